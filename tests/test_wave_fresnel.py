"""Fresnel losses and the pixel's acceptance cone in the wave engine (issue 23,
analysis/wavefilter.py): filters on the angular spectrum, as separable terms, against
closed forms (normal incidence, the band-averaged transmittance by the tracer's own
Fresnel formula, the etendue of the cone's disk in s-space), against the exact own-path
etendue in the geometric limit (lambda / 20), and through the analyses."""

from __future__ import annotations

import math
from dataclasses import replace as dc_replace

import numpy as np
import pytest

from opticalstamp.analysis import wave, wavebase, wavefilter
from opticalstamp.analysis.lsf import fold_bins, traced_folded_lsf
from opticalstamp.analysis.own_etendue import own_etendue
from opticalstamp.analysis.responsivity import (
    RAY,
    folded_lsf,
    join,
    resolve_optics,
    wave_folds,
)
from opticalstamp.analysis.wavecompare import fold
from opticalstamp.design import load_design
from opticalstamp.design.files import design_from_dict
from opticalstamp.design.variants import replace
from opticalstamp.raytrace.kernel import fresnel_sp as kernel_fresnel_sp

A = 30.0 * 20.0  # the open stamp's sensitive area (um^2)


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def _open(cone=90.0, media=("air", 1.52, 1.46), gap=1.49, scale=1.0, area=(30.0, 20.0)):
    """Holes wider than the domain (no mask clips the light): air 300, glass 400, glass
    500 um under the reference gap (700 um), object medium air (thicknesses times
    ``scale``), sensitive ``area`` (um)."""
    m = {"shape": "square", "size_um": 12000.0}
    return design_from_dict(
        {
            "name": "open",
            "sensor": {
                "sensitive_width_um": area[0],
                "sensitive_height_um": area[1],
                "rows": 1,
                "row_pitch_um": 20000.0,
                "pixels_per_row": 3,
                "acceptance_half_angle_deg": cone,
            },
            "slabs": [
                {"medium": media[0], "thickness_um": 300.0 * scale, "mask_top": m},
                {"medium": media[1], "thickness_um": 400.0 * scale},
                {"medium": media[2], "thickness_um": 500.0 * scale, "mask_top": m},
            ],
            "reference_gap": {"medium": gap, "thickness_um": 700.0 * scale},
        }
    )


def _light(d, band, fresnel=False, margin=64.0):
    smp = wavebase.wave_sampling(d, band=band).refined(margin=margin)
    r = wave.wave_response(d, (0.0,), sampling=smp, fresnel=fresnel)
    return float(r.etendue_um2sr[0]), r


def _tracer_t(pairs_by_group, s):
    """The band's transmittance by the tracer's kernel formula: in each group (no mask
    between) the s and p transmittances multiply; the groups' unpolarised ones multiply."""
    out = 1.0
    for pairs in pairs_by_group:
        ps = pp = 1.0
        for n1, n2 in pairs:
            c1 = math.sqrt(1 - (s / n1) ** 2)
            c2 = math.sqrt(1 - (s / n2) ** 2)
            ts, tp = kernel_fresnel_sp(n1, n2, c1, c2)
            ps, pp = ps * ts, pp * tp
        out *= 0.5 * (ps + pp)
    return out


def test_fresnel_formula_is_the_tracers():
    s = np.array([0.0, 0.2, 0.5, 0.9, 0.999])
    for n1, n2 in ((1.0, 1.52), (1.52, 1.0), (1.46, 1.49)):
        ts, tp = wavefilter.fresnel_sp(n1, n2, s)
        for i, si in enumerate(s):
            c1, c2 = math.sqrt(1 - (si / n1) ** 2), math.sqrt(1 - (si / n2) ** 2)
            assert (ts[i], tp[i]) == pytest.approx(kernel_fresnel_sp(n1, n2, c1, c2), abs=1e-15)
    assert wavefilter.fresnel_sp(1.52, 1.0, np.array([1.0]))[0][0] == 0.0  # TIR
    d = _open()
    expect = [(1, 1.0, 1.52), (1, 1.52, 1.46), (2, 1.46, 1.49), (2, 1.49, 1.0)]
    assert wavefilter.interfaces(d) == expect
    assert wavefilter.interfaces(_open(media=("air", "air", "air"), gap="air")) == []


def test_normal_incidence_drops_the_light_by_the_product_of_t():
    """A narrow band (B = 0.02) through four interfaces: the light falls by prod 4 n1 n2
    / (n1 + n2)^2 (0.9198), to the O(B^2) angular change (below 1e-5 here)."""
    d = _open()
    t0 = np.prod([4 * a * b / (a + b) ** 2 for _, a, b in wavefilter.interfaces(d)])
    e0, _ = _light(d, 0.02)
    e1, r = _light(d, 0.02, fresnel=True)
    assert e1 / e0 == pytest.approx(t0, rel=1e-5)
    assert e0 == pytest.approx(A * 0.04**2, rel=1e-3)
    for f in r.meta["filters"]:  # the separable filter: within its tolerance
        assert f["max_error"] <= wavefilter.FILTER_TOL


def test_band_average_of_the_transmittance():
    """Bands of 0.2 and 0.6 (|s| up to 0.85: grazing in air): the light falls by the
    mean over the square band of the groups' transmittance computed with the tracer's
    formula (two groups: the mask on the first glass slab's face separates them), to
    3e-5; at 0.6 that mean lies 0.6 % below the normal-incidence product, so the angular
    dependence is what is checked (a stack a quarter as thick and a pixel of 6 x 4 um: a
    smaller grid, fewer source points)."""
    d = _open(scale=0.25, area=(6.0, 4.0))
    groups = [[(1.0, 1.52), (1.52, 1.46)], [(1.46, 1.49), (1.49, 1.0)]]
    t0 = _tracer_t(groups, 0.0)
    for band in (0.2, 0.6):
        e0, _ = _light(d, band, margin=32.0)
        e1, r = _light(d, band, fresnel=True, margin=32.0)
        x, w = np.polynomial.legendre.leggauss(48)
        x, w = x * band, w * band
        t = np.array([[_tracer_t(groups, math.hypot(a, b)) for b in x] for a in x])
        mean = float(w @ t @ w) / (2 * band) ** 2
        assert e1 / e0 == pytest.approx(mean, rel=3e-5)
        for f in r.meta["filters"]:  # 2 terms at 0.2, 3 at 0.6
            assert f["max_error"] <= wavefilter.FILTER_TOL and f["terms"] <= 3
    assert mean < t0 - 0.005


def test_a_cone_wider_than_the_band_changes_nothing_and_a_narrow_one_is_its_disk():
    """The light of a maskless stack is A times the area of the cone's disk in s-space
    that lies in the band: A pi s_cut^2 for a cone inside it, the disk's share of the
    square where it cuts the corners (the staircase keeps each strip's area); a cone
    beyond the corners changes nothing. A thin stack, a 6 x 4 um pixel, margin 32: the
    source's tails beyond the domain take 3.9e-4 of the light without a cone, 2.7e-4
    with the corners cut, hence 5e-4; the corners cut against no cone: 1.1e-4."""
    band, area = 0.1, 24.0
    kw = {"scale": 0.25, "area": (6.0, 4.0)}
    e_all, _ = _light(_open(**kw), band, margin=32.0)
    assert e_all == pytest.approx(area * (2 * band) ** 2, rel=5e-4)
    wide = _open(cone=math.degrees(math.asin(band * math.sqrt(2) * 1.01)), **kw)
    assert _light(wide, band, margin=32.0)[0] == e_all
    # corners cut: s_cut between B and B sqrt 2
    r_ = math.sin(math.radians(7.0))
    a = math.sqrt(r_ * r_ - band * band)
    quarter = a * band + r_ * r_ * (math.asin(band / r_) - math.asin(a / r_)) / 2
    e, r = _light(_open(cone=7.0, **kw), band, margin=32.0)
    assert e == pytest.approx(area * 4 * quarter, rel=5e-4)
    assert e / e_all == pytest.approx(4 * quarter / (2 * band) ** 2, rel=2e-4)
    assert e < e_all * 0.99
    # inside the band: the disk
    e, r = _light(_open(cone=4.0, **kw), band, margin=32.0)
    assert e == pytest.approx(area * math.pi * math.sin(math.radians(4.0)) ** 2, rel=5e-4)
    f = r.meta["filters"][0]
    assert f["cone"] == pytest.approx(math.sin(math.radians(4.0)))
    assert f["terms"] == f["cone_strips"] == wavefilter.CONE_STEPS


# -- the geometric limit: the exact own-path etendue with Fresnel losses or a cone -----------
def _limit(paper, k: int):
    """The wave engine's sampling at lambda / k (half the source points: the light moves
    by 1e-5 of itself)."""
    return wavebase.wave_sampling(paper, wavelength_um=paper.wavelength_um / k).refined(points=0.5)


def test_geometric_limit_with_fresnel_losses(paper):
    """At lambda / 20 the wave light over the exact own-path etendue (quadrature, the
    tracer's model: exact refraction, Fresnel losses) has the same diffraction excess
    with and without Fresnel losses (0.34 %; the two agree to 1e-8): the losses are the
    tracer's, direction by direction."""
    smp = _limit(paper, 20)
    ex = {}
    for fr in (False, True):
        w = wave.wave_response(paper, (0.0,), sampling=smp, fresnel=fr).etendue_um2sr[0]
        ex[fr] = w / own_etendue(paper, fresnel=fr) - 1
    assert 0 < ex[False] < 5e-3
    assert ex[True] == pytest.approx(ex[False], abs=1e-6)
    t0 = 4 * 1.52 / 2.52**2  # two air-glass interfaces, near normal incidence
    assert own_etendue(paper, fresnel=True) / own_etendue(paper) == pytest.approx(t0**2, rel=1e-3)


def test_geometric_limit_with_an_acceptance_cone(paper):
    """A 1.5 degree cone (|s| <= 0.026, inside the own path's slopes up to 0.033 per
    axis) takes a sixth of the own path's light: the wave light tends to the exact
    own-path etendue with the cone as lambda shrinks (excess 0.27 % at lambda / 10,
    0.06 % at lambda / 20 with 16 strips; the staircase's rim moves it by 0.03-0.04 %
    per doubling of the strips, docs/wave.md), and the cone's share of the light is the
    tracer's to 0.4 % (the diffraction excess without the cone is 0.34 %)."""
    d = replace(paper, {"sensor.acceptance_half_angle_deg": 1.5})
    own, own0 = own_etendue(d), own_etendue(paper)
    assert own < 0.9 * own0
    ex = {}
    for k in (10, 20):
        smp = _limit(paper, k)
        ex[k] = wave.wave_response(d, (0.0,), sampling=smp).etendue_um2sr[0] / own - 1
    assert 0 < ex[10] < 5e-3 and abs(ex[20]) < 0.6 * ex[10]
    w0 = wave.wave_response(paper, (0.0,), sampling=smp).etendue_um2sr[0]
    assert (1 + ex[20]) * own / w0 == pytest.approx(own / own0, abs=4e-3)


# -- through the analyses ---------------------------------------------------------------------
ZS = np.array([0.0, 1.0, 2.0, 3.0])
PER = [254.0]


def test_resolve_optics_takes_fresnel_and_the_cone_for_wave(paper):
    o = resolve_optics(paper, "wave", fresnel=True)
    assert o.engine == "wave" and o.fresnel and o.to_dict()["fresnel"] is True
    auto = resolve_optics(paper, "auto", fresnel=True)
    assert auto.engine == resolve_optics(paper, "auto").engine  # the validity rule decides
    assert auto.reason == resolve_optics(paper, "auto").reason and auto.fresnel
    assert resolve_optics(paper, o, fresnel=False).fresnel is False  # the call's setting
    coned = replace(paper, {"sensor.acceptance_half_angle_deg": 3.0})
    assert resolve_optics(coned, "wave").engine == "wave"
    # wave folds made without Fresnel losses are not joined with a trace that has them
    wf = wave_folds(paper, resolve_optics(paper, "wave"), 1.0)
    with pytest.raises(ValueError, match="fresnel"):
        folded_lsf(paper, z_mm=[0.0], periods_um=PER, optics=o, fresnel=True, wave=wf)


def test_geometric_limit_of_the_joined_light_with_fresnel_losses(paper):
    """At lambda / 20 the wave engine's in-band light with Fresnel losses (row A and B,
    one wavelength, as tests/test_optics_engines.py) joined with the traced light beyond
    the band (traced with them too) gives the tracer's light with Fresnel losses to 1 %,
    8 % below the light without them."""
    smp = wavebase.wave_sampling(paper, wavelength_um=paper.wavelength_um / 20)
    rows = [wave.wave_response(paper, ZS, pixel=(r, 0), sampling=smp, fresnel=True) for r in (0, 1)]
    nb = int(fold_bins(np.array(PER))[0])
    h = np.stack([[fold(x.x_um, p, PER[0], nb) for p in x.lsf_x] for x in rows])[:, None]
    n = 1 << 17
    kw = {"z_mm": ZS, "periods_um": PER, "n_rays": n}
    far = traced_folded_lsf(paper, outside_band=smp.band, fresnel=True, **kw)
    w = join(dc_replace(far, h=[h], method="wave"), far, smp.band, 1.0)
    r = folded_lsf(paper, optics=RAY, fresnel=True, **kw)
    r0 = folded_lsf(paper, optics=RAY, **kw)

    def light(x):
        return x.h[0].sum(axis=(0, 1, 3)) / len(x.rows)

    np.testing.assert_allclose(light(w), light(r), rtol=0.01)
    assert np.all(light(r) < 0.93 * light(r0))


def test_cli_rmtf_by_wave_optics_with_fresnel_losses():
    import json

    from typer.testing import CliRunner

    from opticalstamp.cli import app

    args = ["rmtf", "--optics", "wave", "--z", "0,1", "--dpi", "200", "--rays", "65536", "--json"]
    r = CliRunner().invoke(app, [*args, "--fresnel"])
    assert r.exit_code == 0, r.output
    data = json.loads(r.output)
    assert data["meta"]["optics"]["engine"] == "wave" and data["meta"]["optics"]["fresnel"]


def test_wave_scan_kernels_with_fresnel_losses(paper):
    """Scan kernels by wave optics with Fresnel losses: the near-field part is the wave
    engine's in-band light with the losses (within 0.2 % of wave_response's, as without
    them in tests/test_optics_engines.py), the ghost part the traced light beyond the
    band with the losses (grazing: it falls to less than half)."""
    from opticalstamp.imaging.kernels import scan_kernels

    k0, k1 = (
        scan_kernels(paper, [0.0], source="wave", n_rays=1 << 16, fresnel=f) for f in (False, True)
    )
    light = wave.wave_response(paper, (0.0,), fresnel=True).etendue_um2sr[0]
    assert k1[0][0].own_etendue == pytest.approx(light, rel=2e-3)
    assert k1[0][0].ghost_etendue < 0.5 * k0[0][0].ghost_etendue


def test_cone_staircase_against_the_2d_exact_disk(monkeypatch):
    """The small two-row stamp of tests/test_wave.py with a 6 degree cone (|s| <= 0.105
    in a band of 0.2, over many rows of bins): the 2-D path applies the disk exactly
    (wave2d.angular_filters), the separable path its 16-strip staircase: light within
    0.2 % (measured -0.105 %), LSFs within 0.3 % of their peak (0.16 %), and closer with
    32 strips."""
    from opticalstamp.analysis.wave2dlsf import lsf_source_2d
    from test_wave import _stack

    d = _stack((10.0, 10.0, 12.0), offsets=[(1.5, -1.0), (0.0, 0.0), (-2.0, 0.7)])
    d = replace(d, {"sensor.acceptance_half_angle_deg": 6.0})
    smp = wavebase.wave_sampling(d, band=0.2).refined(margin=0.5)
    zs = (0.0, 0.4)
    _, exact, e_light, _ = lsf_source_2d(d, 0.4, sampling=smp, propagator="paraxial").lsf_x(zs)
    err = []
    for steps in (16, 32):
        monkeypatch.setattr(wavefilter, "CONE_STEPS", steps)
        _, lsf, light, _ = wave.lsf_source(d, 0.4, sampling=smp).lsf_x(zs)
        err.append((abs(light / e_light - 1), np.abs(lsf - exact).max() / exact.max()))
    assert err[0][0] < 2e-3 and err[0][1] < 3e-3
    assert err[1][0] < err[0][0] and err[1][1] < err[0][1]
