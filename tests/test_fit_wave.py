"""opticalstamp fit under wave optics (issue 24): scans made through the wave engine's
kernels (``scan --kernel wave``) of a perturbed prototype are fitted back by the wave
model (defect correction, studies/fitwave.py), and a ray-optics fit of the same scans is
biased.

The scans: the prototype with layer 2 shifted 4 um, slab 2 420 um and the light guide
200 um thicker (as tests/test_fit.py), bars at 0.5, 2.5 and 4.5 mm and an edge at 2 mm,
sensor noise, no ghost light.
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from opticalstamp.analysis.responsivity import resolve_optics
from opticalstamp.cli import app
from opticalstamp.design import load_design
from opticalstamp.design.variants import replace
from opticalstamp.imaging.charts import bar_chart, edge_chart
from opticalstamp.imaging.scan import ScanSettings, prepare_kernels, simulate_scan
from opticalstamp.io.atomic import write_atomic
from opticalstamp.io.files import encode_tiff16
from opticalstamp.report.fitsection import fit_section, load_fit
from opticalstamp.studies.fit import Problem, fit, layout_for
from opticalstamp.studies.fitmodel import design_params, smear_of
from opticalstamp.studies.fitwave import WaveModel, held_sampling

NOMINAL = load_design("paper2016")
TRUTH = {"layer2.x": 4.0, "slab2": 420.0, "ref": 200.0}
TRUE = replace(
    NOMINAL,
    {
        "slabs.1.mask_top.offset_x_um": 4.0,
        "slabs.1.thickness_um": 420.0,
        "reference_gap.thickness_um": 1200.0,
    },
)
Z_BARS = (0.5, 2.5, 4.5)
Z_EDGE = 2.0
SETTINGS = ScanSettings(kernel="wave")
SEED = 1


@functools.cache
def _scans() -> dict[str, tuple[np.ndarray, float]]:
    """{name: (image, Z)} through wave kernels (one wave run a row for every height)."""
    kc = prepare_kernels(
        TRUE, z_mm=sorted(Z_BARS + (Z_EDGE,)), ghosts=False, seed=SEED, settings=SETTINGS
    )
    out = {}
    charts = (
        ("b", Z_BARS, bar_chart(4800, supersample=32), 4800),
        ("e", (Z_EDGE,), edge_chart(2400), 2400),
    )
    for kind, zs, doc, dpi in charts:
        for z in zs:
            r = simulate_scan(
                doc, dpi, TRUE, z_mm=z, seed=SEED, kernels=kc, ghosts=False, settings=SETTINGS
            )
            out[f"{kind}{z}"] = (r.image, z)
    return out


@functools.cache
def _observations():
    from opticalstamp.studies.fitdata import observation

    return [observation(img, 300.0, z, name=n) for n, (img, z) in _scans().items()]


@functools.cache
def _fits():
    obs = _observations()
    free = list(TRUTH)
    return {o: fit(NOMINAL, obs, free=free, starts=1, optics=o) for o in ("wave", "ray")}


def test_corrected_model_is_the_wave_model_at_its_point():
    """The defect correction's model at the parameters it was made at is the wave model
    (its spreads), and its derivative there the wave model's (forward differences)."""
    params = design_params(NOMINAL)
    names = [p.name for p in params]
    wave = WaveModel(resolve_optics(NOMINAL, "wave").sampling)
    smear, zs = smear_of(NOMINAL), [0.5, 2.5]
    at = np.array([0.0 if p.offset else p.nominal for p in params])
    at[names.index("ref")] = 150.0
    j = names.index("layer2.x")
    corr = wave.correction(NOMINAL, params, at, (j,), zs, smear)
    from opticalstamp.studies.fitmodel import with_params

    exact = wave(with_params(NOMINAL, params, at), zs, smear)
    model = corr(with_params(NOMINAL, params, at), zs, smear, at)
    for z in zs:  # the model's table reaches as far as the step's (0 and 1 beyond)
        m, e = model[z], exact[z]
        assert np.max(np.abs(m.cx - np.interp(m.u, e.u, e.cx))) < 1e-12
        assert np.max(np.abs(m.cy - np.interp(m.u, e.u, e.cy))) < 1e-12
    # one step of 0.2 um along layer2.x: the model's change is the wave model's to
    # first order (the fast part exact, the difference linear)
    moved = at.copy()
    moved[j] += 0.2
    d = with_params(NOMINAL, params, moved)
    w1, m1 = wave(d, zs, smear), corr(d, zs, smear, moved)
    for z in zs:
        dw = np.interp(m1[z].u, w1[z].u, w1[z].cx) - np.interp(m1[z].u, exact[z].u, exact[z].cx)
        dm = m1[z].cx - model[z].cx
        assert np.max(np.abs(dw)) > 1e-4  # the step moves the spread
        assert np.max(np.abs(dm - dw)) < 0.02 * np.max(np.abs(dw)), z


def test_wave_fit_recovers_wave_scans_and_ray_fit_is_biased():
    res = _fits()
    w, r = res["wave"], res["ray"]
    assert w.optics["engine"] == "wave" and w.optics["scheme"]["converged"]
    assert r.optics["engine"] == "ray"
    for n, v, e in zip(w.names, w.values, w.errors, strict=True):
        assert e is not None and abs(v - TRUTH[n]) < 3 * e, (n, v, e)
    assert w.chi2 / w.dof < 1.3  # the wave model describes the wave scans
    # the start judged by the model fitted: its wave chi2 (its nuisance fitted again) at
    # the fast model's minimum, which the polish lowers, nothing being held
    (s0,) = w.starts
    assert s0["best"] and s0["chi2"] > 0 and not w.held and not w.held_combinations
    assert w.chi2 < s0["wave_chi2"]
    assert w.optics["scheme"]["wave_chi2"][0] <= s0["wave_chi2"] * (1 + 1e-9)
    # the ray model does not: a misfit, and the misregistration far off in its errors
    assert r.chi2 / r.dof > 5
    bias = {n: (v - TRUTH[n]) / e for n, v, e in zip(r.names, r.values, r.errors, strict=True)}
    assert max(abs(b) for b in bias.values()) > 10, bias


def test_wave_fit_is_the_wave_models_optimum():
    """Independently of the correction: the wave model itself (no fast part), moved by
    one error along each free parameter either way (the rest held), puts the minimum of
    its chi2 parabola within 0.1 error of the fit."""
    w = _fits()["wave"]
    obs = _observations()
    lay = layout_for(NOMINAL, obs, w.names, w.pinned)
    zs = sorted({o.z_mm for o in obs})
    wave = WaveModel(held_sampling(NOMINAL, resolve_optics(NOMINAL, "wave").sampling, max(zs)))
    prob = Problem(NOMINAL, obs, lay, model=wave.held(NOMINAL, zs, smear_of(NOMINAL)))
    theta = np.asarray(w.theta)
    chi0 = float(np.sum(prob.residuals(theta) ** 2))
    assert chi0 == pytest.approx(w.chi2, rel=1e-3)
    for k, e in enumerate(w.errors):
        chi = []
        for sign in (-1, 1):
            t = theta.copy()
            t[k] += sign * e
            chi.append(float(np.sum(prob.residuals(t) ** 2)))
        curv = chi[0] + chi[1] - 2 * chi0
        assert curv > 0.5  # a minimum along it, seen at the scale of the error
        offset = (chi[1] - chi[0]) / (2 * curv)  # the parabola's minimum, in errors
        assert abs(offset) < 0.1, (w.names[k], offset, chi0, chi)


def _write(tmp_path, name):
    img, z = _scans()[name]
    p = tmp_path / f"{name}.tif"
    write_atomic(p, encode_tiff16(np.clip(img, 0, 1), 300.0))
    return f"{p}:{z}"


def test_cli_fit_takes_the_designs_optics(tmp_path):
    """--optics auto (the default) takes wave optics for the prototype, as the other
    commands; fit.json and the report section say so; a bad --optics exits 2."""
    args = [_write(tmp_path, n) for n in ("b0.5", "b4.5")]
    # one parameter free (the reference plane), the others pinned at the truth: the wave
    # fit through the command line, converged and recovering the truth (2.0 errors off;
    # 2.3 with layer2.x free too), at 26 wave runs (37 with layer2.x free, measured; the
    # three-parameter wave fit is tested above)
    out, rep = tmp_path / "fitted.toml", tmp_path / "rep"
    r = CliRunner().invoke(
        app,
        ["fit", *args, "-o", str(out), "--free", "ref", "--pin", "layer2.x=4,slab2=420"]
        + ["--starts", "1", "--json", "--report", str(rep)],
    )
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    o = data["optics"]
    assert o["asked"] == "auto" and o["engine"] == "wave" and o["warning"] is None
    assert o["scheme"]["converged"] and o["scheme"]["wave_runs"] >= 4
    p = data["parameters"]["ref"]
    assert abs(p["value"] - TRUTH["ref"]) < 3 * p["error"], p
    sec = fit_section(load_fit(rep), NOMINAL)
    assert "optics: wave" in sec["optics_text"] and sec["curves"].startswith("the wave")
    assert json.loads((rep / "fit.json").read_text())["rmtf"]["optics"] == "wave"
    r = CliRunner().invoke(app, ["fit", *args, "-o", str(out), "--optics", "bogus"])
    assert r.exit_code == 2 and "--optics" in r.output, r.output


def test_secant_refits_on_the_pool_are_the_fits_own():
    """The secant probes' nuisance refits, run side by side on the wave fit's pool
    (:meth:`~opticalstamp.studies.fitpool.WaveRuns.refits`: wave run, refit and sum in a
    worker), are the bits the fit's own process gives (the run, ``fit_nuisance(search=
    False)``, the sum of squares); new runs are kept, a kept one is not run again, a point
    whose design breaks a rule is NaN, a batch below ``min_runs`` is left to the caller;
    and the secant check itself (:func:`~opticalstamp.studies.fitident.secant_estimate`)
    gives the same covariance and record with the pool as without."""
    from opticalstamp.studies.fit import UNDETERMINED, _estimate, _exact, _wave_chi2
    from opticalstamp.studies.fitident import secant_estimate
    from opticalstamp.studies.fitpool import WaveRuns, wave_pool
    from opticalstamp.studies.fitproblem import nuisance_start

    obs = _observations()[-2:]  # bars at 4.5 mm and the edge
    lay = layout_for(NOMINAL, obs, free=["layer2.x", "slab2", "ref"])
    zs = sorted({o.z_mm for o in obs})
    opt = resolve_optics(NOMINAL, "wave")
    wave = WaveModel(held_sampling(NOMINAL, opt.sampling, max(zs))).held(
        NOMINAL, zs, smear_of(NOMINAL)
    )
    theta = np.concatenate([lay.fixed[list(lay.free)]] + [nuisance_start(o) for o in obs])

    def runs_on(pool):
        return WaveRuns(wave, NOMINAL, list(lay.params), zs, smear_of(NOMINAL), pool)

    serial = _exact(Problem(NOMINAL, obs, lay), runs_on(None))
    theta = serial.fit_nuisance(theta)
    points = [theta.copy() for _ in range(3)]
    for p, d in zip(points, (0.0, 2.0, -3.0), strict=True):
        p[:3] = theta[:3] + d * np.array([1.0, 5.0, 10.0])
    broken = theta.copy()
    broken[1] = -50.0  # plate 2 -50 um thick: no design
    est = _estimate(serial, theta)
    alone = secant_estimate(serial, theta, est, UNDETERMINED, None)
    with wave_pool(2) as pool:
        runs = runs_on(pool)
        runs(serial.lay.physical(points[0]))  # kept: not run again
        assert runs.refits(serial, points, min_runs=4) is None
        got = runs.refits(serial, points + [broken], min_runs=4)
        assert runs.runs == len(points)
        pooled = secant_estimate(_exact(serial, runs), theta, est, UNDETERMINED, runs)
    for p, (q, value) in zip(points, got[:-1], strict=True):
        want_q = serial.fit_nuisance(p, search=False)
        assert np.array_equal(q, want_q)
        assert value == float(np.sum(serial.residuals(want_q) ** 2))
    assert np.isnan(got[-1][1])
    # the starts' judge (_wave_chi2): the same points and sums here as on the pool
    here = _wave_chi2(Problem(NOMINAL, obs, lay), runs_on(None), points + [broken])
    for (q, v), (gq, gv) in zip(here[:-1], got[:-1], strict=True):
        assert np.array_equal(q, gq) and v == gv
    assert np.isnan(here[-1][1])
    assert np.array_equal(pooled[0][3], alone[0][3])  # the covariance
    assert json.dumps(pooled[1], default=str) == json.dumps(alone[1], default=str)
