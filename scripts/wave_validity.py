"""When ray optics holds: ray against wave over a range of designs (issue 23).

Runs :func:`~opticalstamp.analysis.wavecompare.compare_wave_ray` on the prototype and its
variants (holes scaled, plates thinner and thicker, the reference gap, 600 and 1200 dpi
by :func:`~opticalstamp.design.variants.scale_to_dpi`, the paper's Fig. 1 presets,
wavelengths 0.45-0.65 um), records per design the layers' Fresnel numbers and the
candidate predictors of :func:`~opticalstamp.analysis.validity.design_predictors`, the
ray figures' errors against the wave figures (light, RMTF on the depth-of-field chart at
0-3 mm, centre-cell share, depth of field), fits the upper envelopes of the errors
against each predictor, and writes

- ``docs/wave-validity.json``: the table, the envelopes and how well each predictor
  orders the errors;
- ``docs/img/wave-validity.png``: the errors against the chosen predictor (log x) with
  the fitted envelopes and the tolerances.

    .venv/bin/python scripts/wave_validity.py [--quick] [--out DIR] [--rays N] [--replot]

``--quick``: 10 designs, fewer rays (a smoke run, about a minute); the full study takes
about 6.5 minutes on the shared 2-core machine. ``--replot``: redraw the figure from the
table already in ``--out``. The constants of :mod:`opticalstamp.analysis.validity` come from
the full run's envelopes.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
import time
from pathlib import Path

import numpy as np

from opticalstamp.analysis.dof import depth_of_field
from opticalstamp.analysis.lsf import FoldedLSF
from opticalstamp.analysis.paraxial import paraxial_etendue
from opticalstamp.analysis.rmtf import rmtf_curves
from opticalstamp.analysis.validity import (
    CHOSEN,
    DEFAULT_LIGHT_TOL,
    DEFAULT_RMTF_TOL,
    ENVELOPE_MARGIN,
    RMTF_Z_MAX_MM,
    Envelope,
    design_predictors,
    fit_envelope,
    ray_errors,
)
from opticalstamp.analysis.wavecompare import compare_wave_ray, ray_in_band
from opticalstamp.design import load_design
from opticalstamp.design.variants import replace, scale_to_dpi, with_stack
from opticalstamp.io.atomic import write_atomic
from opticalstamp.io.files import save_figure, to_json
from opticalstamp.raytrace.stack import lattice_of

ROOT = Path(__file__).resolve().parents[1]
#: heights (mm): the RMTF error is taken over 0-3 mm, the depth of field up to 5 mm
Z_FULL = tuple(0.5 * i for i in range(11))
Z_QUICK = (0.0, 1.0, 2.0, 3.0)
PROTO_PLATES = (1000.0, 400.0, 450.0)  # object side first
PROTO_HOLES = (48.0, 40.0, 40.0)


def _stack(d, holes=None, plates=1.0, gap=None, name=""):
    t = tuple(p * plates for p in PROTO_PLATES)
    g = (1000.0 * plates) if gap is None else gap
    return with_stack(d, holes_um=holes, thicknesses_um=t, reference_gap_um=g, name=name)


def _scaled(h: float) -> tuple[float, ...]:
    return tuple(round(x * h, 1) for x in PROTO_HOLES)


def study_designs(quick: bool = False) -> list[tuple[str, str, object]]:
    """(label, family, Design) of the study, the prototype's variants."""
    d = load_design("paper2016")

    def lam(x, w):
        return replace(x, wavelength_um=w, name=f"{x.name} at {w:g} um")

    d600 = scale_to_dpi(d, 600)
    half = _stack(d600, plates=0.5, gap=1000.0, name="600 dpi half-scale copy")
    q1200 = _stack(scale_to_dpi(d, 1200), plates=0.25, gap=250.0, name="1200 dpi quarter-scale")
    out = [
        ("paper2016", "prototype", d),
        ("paper2016, 0.45 um", "wavelength", lam(d, 0.45)),
        ("paper2016, 0.65 um", "wavelength", lam(d, 0.65)),
        ("holes x0.75", "holes", _stack(d, _scaled(0.75))),
        ("holes x1.25", "holes", _stack(d, _scaled(1.25))),
        ("holes x1.5", "holes", _stack(d, _scaled(1.5))),
        ("holes 80/70/70", "holes", _stack(d, (80.0, 70.0, 70.0))),
        ("holes 60/40/40", "holes", _stack(d, (60.0, 40.0, 40.0))),
        ("holes 36/40/40", "holes", _stack(d, (36.0, 40.0, 40.0))),
        ("plates x0.5", "plates", _stack(d, plates=0.5)),
        ("plates x0.75", "plates", _stack(d, plates=0.75)),
        ("plates x1.5", "plates", _stack(d, plates=1.5)),
        ("plates x2", "plates", _stack(d, plates=2.0)),
        ("gap 0.5 mm", "plates", _stack(d, gap=500.0)),
        ("gap 2 mm", "plates", _stack(d, gap=2000.0)),
        ("plates x0.25", "large F", _stack(d, plates=0.25)),
        ("150 dpi (holes x2)", "large F", scale_to_dpi(d, 150)),
        ("150 dpi, plates x0.5", "large F", _stack(scale_to_dpi(d, 150), plates=0.5)),
        ("100 dpi (holes x3)", "large F", scale_to_dpi(d, 100)),
        ("100 dpi, plates x0.5", "large F", _stack(scale_to_dpi(d, 100), plates=0.5)),
        ("holes x1.5, plates x0.5", "large F", _stack(d, _scaled(1.5), plates=0.5)),
        (
            "holes 80/70/70, plates x0.5, gap 0.25",
            "large F",
            _stack(d, (80.0, 70.0, 70.0), 0.5, 250.0),
        ),
        ("holes x1.25, plates x0.5, 0.45 um", "large F", lam(_stack(d, _scaled(1.25), 0.5), 0.45)),
        ("600 dpi (holes 24/20/20)", "600 dpi", d600),
        ("600 dpi half-scale copy", "600 dpi", half),
        ("600 dpi half-scale copy, 0.45 um", "600 dpi", lam(half, 0.45)),
        ("600 dpi half-scale copy, 0.65 um", "600 dpi", lam(half, 0.65)),
        ("600 dpi, plates x0.25", "600 dpi", _stack(d600, plates=0.25, gap=500.0)),
        ("1200 dpi (holes 12/10/10)", "1200 dpi", scale_to_dpi(d, 1200)),
        ("1200 dpi quarter-scale", "1200 dpi", q1200),
        (
            "1200 dpi, plates x0.125",
            "1200 dpi",
            _stack(scale_to_dpi(d, 1200), plates=0.125, gap=250.0),
        ),
        ("fig1b (1 layer, 1 row)", "presets", load_design("fig1b")),
        ("fig1c (2 layers, 1 row)", "presets", load_design("fig1c")),
        ("fig1d (2 layers, staggered)", "presets", load_design("fig1d")),
        ("three layers, 1 row", "presets", load_design("three-layer-single-row")),
        (
            "paper2016 misregistered 3 um",
            "prototype",
            with_stack(d, offsets_um=((3.0, 0.0), (0.0, 3.0), (-3.0, 0.0))),
        ),
    ]
    if quick:
        keep = {
            "paper2016",
            "holes x1.5",
            "holes 80/70/70, plates x0.5, gap 0.25",
            "plates x2",
            "100 dpi (holes x3)",
            "600 dpi (holes 24/20/20)",
            "600 dpi half-scale copy",
            "1200 dpi quarter-scale",
            "fig1c (2 layers, 1 row)",
            "paper2016, 0.45 um",
            "holes x0.75",
        }
        out = [o for o in out if o[0] in keep]
    return out


def _dof(z, r) -> float:
    """Depth of field of a sampled curve, None where it never falls below (past the
    last Z)."""
    r = np.asarray(r)
    if not (r < 0.3).any():
        return None
    return depth_of_field(np.asarray(z), r)


def _ray_rmtf(design, zs, period_um: float, folded_rows) -> np.ndarray:
    """RMTF on the chart of period ``period_um`` from the rows' folded ray LSFs (as
    :func:`~opticalstamp.analysis.wavecompare.compare_wave_ray` computes it)."""
    lat = lattice_of(design)
    rows = [(float(lat.row_x[r]), float(lat.row_y[r])) for r in range(design.sensor.rows)]
    h = np.stack(folded_rows)[:, None]  # (rows, 1, nz, n_bins)
    lsf = FoldedLSF(
        np.asarray(zs, float), np.array([period_um]), rows, [h], "trace", 0, False, False
    )
    return np.asarray(rmtf_curves(lsf, design)["max"][0])


def measure(label: str, family: str, design, zs, n_rays: int, seeds: int) -> dict:
    """One design's row of the table: the wave side once (:func:`compare_wave_ray`), the
    ray side again with ``seeds`` fresh seeds of ``n_rays`` rays a row
    (:func:`ray_in_band`); the errors (:func:`ray_errors`' definitions) are those of the
    seeds' pooled ray figures, with standard errors from the spread between seeds."""
    t = time.perf_counter()
    c = compare_wave_ray(design, zs, n_rays=n_rays, seed=0)
    z = np.asarray(c.z_mm)
    near = z <= RMTF_Z_MAX_MM + 1e-9
    wr = np.asarray(c.wave["rmtf"])
    band, per = c.sampling["band"], c.period_um
    folds, nears = [], []
    for seed in range(1, seeds + 1):  # compare_wave_ray's ray side used seed 0
        rays = [
            ray_in_band(design, zs, band, pixel=(r, 0), period_um=per, n_rays=n_rays, seed=seed)
            for r in range(design.sensor.rows)
        ]
        folds.append([x.folded for x in rays])
        nears.append(rays[0].near_um2sr)
    own = paraxial_etendue(design)  # the separable wave path's geometric limit
    light_w = c.wave["light_um2sr"]
    seed0 = ray_errors(c, design)  # compare_wave_ray's own ray side (seed 0), for the record
    per_seed = {
        "light": [light_w / (own + n) - 1 for n in nears],
        "rmtf": [float(np.abs(wr - _ray_rmtf(design, zs, per, f))[near].max()) for f in folds],
    }
    pooled = [np.mean([f[r] for f in folds], axis=0) for r in range(design.sensor.rows)]
    rr = _ray_rmtf(design, zs, per, pooled)
    err = {
        "light": light_w / (own + float(np.mean(nears))) - 1,
        "rmtf": float(np.abs(wr - rr)[near].max()),
    }
    se = {k: float(np.std(v, ddof=1) / np.sqrt(seeds)) for k, v in per_seed.items()}
    dw, dr = _dof(z, wr), _dof(z, rr)
    cell = np.asarray(c.difference["center_cell_fraction"])
    row = {
        "label": label,
        "family": family,
        "design": c.design,
        "fingerprint": c.fingerprint,
        "wavelength_um": design.wavelength_um,
        "holes_um": [m.hole_width_um for m in design.masks][::-1],
        "rows": design.sensor.rows,
        "fresnel": [{k: f[k] for k in ("layer", "towards", "fresnel_number")} for f in c.fresnel],
        "predictors": design_predictors(design),
        "band": c.sampling["band"],
        "light_wave_um2sr": c.wave["light_um2sr"],
        "own_paraxial_um2sr": own,
        "own_exact_um2sr": c.own_exact_um2sr,
        "light_error_vs_exact": light_w / (c.own_exact_um2sr + float(np.mean(nears))) - 1,
        "near_ray_um2sr": float(np.mean(nears)),
        "light_error": err["light"],
        "light_error_se": se["light"],
        "rmtf_error": err["rmtf"],
        "rmtf_error_se": se["rmtf"],
        "per_seed": per_seed,
        "errors_seed0": seed0,
        "rmtf_error_z0": float(abs(wr[0] - rr[0])),
        "cell_error_seed0": float(np.abs(cell[near]).max()),
        "dof_chart_dpi": c.dof_dpi,
        "dof_wave_mm": dw,
        "dof_ray_mm": dr,
        "dof_difference_mm": None if dw is None or dr is None else dw - dr,
        "z_mm": c.z_mm,
        "rmtf_wave": wr.tolist(),
        "rmtf_ray": rr.tolist(),
        "seconds": time.perf_counter() - t,
    }
    return row


def rank_agreement(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rank correlation of x and y (ties: mean ranks)."""
    from scipy.stats import spearmanr

    return float(spearmanr(x, y).statistic)


def summarise(rows: list[dict]) -> dict:
    """Each predictor's envelopes (:func:`fit_envelope` with the module's margin), its
    rank correlation with the errors, and what the rule built on it would do to the
    study's designs: ``needless_wave``, designs sent to wave whose ray figures were in
    fact within both tolerances (the price of a loose predictor; none is ever sent to
    ray outside them: the envelope lies above every error plus two standard errors)."""
    names = list(rows[0]["predictors"])
    light = np.array([abs(r["light_error"]) for r in rows])
    rm = np.array([r["rmtf_error"] for r in rows])
    # the envelope lies above each error plus two standard errors of its estimate
    light_hi = light + 2 * np.array([r["light_error_se"] for r in rows])
    rm_hi = rm + 2 * np.array([r["rmtf_error_se"] for r in rows])
    fine = (light <= DEFAULT_LIGHT_TOL) & (rm <= DEFAULT_RMTF_TOL)
    out = {}
    for n in names:
        p = np.array([r["predictors"][n] for r in rows])
        le = fit_envelope(p, light_hi, margin=ENVELOPE_MARGIN)
        re_ = fit_envelope(p, rm_hi, margin=ENVELOPE_MARGIN)
        wave = (le.bound(p) > DEFAULT_LIGHT_TOL) | (re_.bound(p) > DEFAULT_RMTF_TOL)
        out[n] = {
            "spearman_light": rank_agreement(p, light),
            "spearman_rmtf": rank_agreement(p, rm),
            "light_envelope": le,
            "rmtf_envelope": re_,
            "threshold_light": le.predictor_for(DEFAULT_LIGHT_TOL),
            "threshold_rmtf": re_.predictor_for(DEFAULT_RMTF_TOL),
            "designs_within_tolerances": int(fine.sum()),
            "needless_wave": int((wave & fine).sum()),
        }
    return out


LABELS = {
    "fresnel_own": "own-path Fresnel number P = G$_1$ / (4 λ)",
    "fresnel_min": "least layer Fresnel number a² / (λ d)",
}


def plot(rows: list[dict], envelopes: dict, predictor: str):
    """Errors against the predictor (log x), with the envelopes (``light``, ``rmtf``:
    :class:`Envelope`) and the default tolerances."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2))
    axs = fig.subplots(1, 3)
    p = np.array([r["predictors"][predictor] for r in rows])
    grid = np.geomspace(p.min() * 0.8, p.max() * 1.25, 200)
    fams = sorted({r["family"] for r in rows})
    marks = dict(zip(fams, "osD^v<>ph*", strict=False))
    for fam in fams:
        sel = [i for i, r in enumerate(rows) if r["family"] == fam]
        le = [rows[i]["light_error"] for i in sel]
        axs[0].scatter(
            p[sel],
            np.abs(le),
            marker=marks[fam],
            label=fam,
            facecolors=["C0" if v > 0 else "none" for v in le],
            edgecolors="C0",
        )
        axs[1].scatter(p[sel], [rows[i]["rmtf_error"] for i in sel], marker=marks[fam], c="C1")
        dd = [(p[i], rows[i]["dof_difference_mm"]) for i in sel]
        dd = [x for x in dd if x[1] is not None]
        if dd:
            axs[2].scatter(*zip(*dd, strict=True), marker=marks[fam], c="C2")
    for ax, key, tol, what in (
        (axs[0], "light_envelope", DEFAULT_LIGHT_TOL, "|light wave/ray - 1|"),
        (axs[1], "rmtf_envelope", DEFAULT_RMTF_TOL, "max |RMTF wave - ray|, Z 0-3 mm"),
    ):
        env = envelopes[key.split("_")[0]]
        ax.plot(grid, env.bound(grid), "k-", lw=1, label="envelope (the rule)")
        ax.axhline(tol, color="r", ls="--", lw=1, label=f"tolerance {tol:g}")
        ax.axvline(env.predictor_for(tol), color="r", ls=":", lw=1)
        ax.set_yscale("log")
        ax.set_ylabel(what)
    axs[2].axhline(0, color="k", lw=0.5)
    axs[2].set_ylabel("DOF wave - ray (mm)")
    for ax in axs:
        ax.set_xscale("log")
        ax.set_xlabel(LABELS.get(predictor, predictor.replace("_", " ")))
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    axs[0].legend(fontsize=6, loc="lower left")
    axs[1].legend(fontsize=6, loc="lower left")
    axs[0].set_title("light (filled: wave > ray)", fontsize=9)
    axs[1].set_title("RMTF on the depth-of-field chart", fontsize=9)
    axs[2].set_title("own-light depth of field", fontsize=9)
    fig.tight_layout()
    return fig


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 designs, fewer rays")
    ap.add_argument("--out", type=Path, default=ROOT / "docs", help="folder (docs)")
    ap.add_argument(
        "--rays", type=int, default=None, help="rays per row and seed (2^18; quick 2^16)"
    )
    ap.add_argument("--seeds", type=int, default=None, help="ray seeds pooled (4; quick 2)")
    ap.add_argument(
        "--replot", action="store_true", help="redraw the figure from the table in --out"
    )
    a = ap.parse_args(argv)
    if a.replot:
        data = json.loads((a.out / "wave-validity.json").read_text())
        fit = data["predictors"][data["chosen_predictor"]]
        env = {k: Envelope(**fit[f"{k}_envelope"]) for k in ("light", "rmtf")}
        fig = plot(data["designs"], env, data["chosen_predictor"])
        save_figure(fig, a.out / "img" / "wave-validity.png")
        return 0
    zs = Z_QUICK if a.quick else Z_FULL
    n_rays = a.rays or (1 << 16 if a.quick else 1 << 18)
    seeds = a.seeds or (2 if a.quick else 4)
    if seeds < 2:
        ap.error("--seeds: at least 2 (the standard errors come from their spread)")
    rows = []
    t0 = time.perf_counter()
    for label, fam, design in study_designs(a.quick):
        r = measure(label, fam, design, zs, n_rays, seeds)
        rows.append(r)
        pr = r["predictors"]
        print(
            f"{label:48s} Fmin {pr['fresnel_min']:6.2f} Fown {pr['fresnel_own']:6.2f} "
            f"light {r['light_error']:+7.1%} ±{r['light_error_se']:.1%} "
            f"rmtf {r['rmtf_error']:.3f} ±{r['rmtf_error_se']:.3f} "
            f"dof {r['dof_wave_mm']} / {r['dof_ray_mm']} ({r['seconds']:.1f} s)",
            flush=True,
        )
    summary = summarise(rows)
    for n, s in summary.items():
        print(
            f"{n:18s} rho light {s['spearman_light']:+.2f} rmtf {s['spearman_rmtf']:+.2f}  "
            f"light {s['light_envelope']}  rmtf {s['rmtf_envelope']}  thresholds "
            f"{s['threshold_light']:.2f} / {s['threshold_rmtf']:.2f}  needless wave "
            f"{s['needless_wave']} of {s['designs_within_tolerances']}"
        )
    data = {
        "study": "scripts/wave_validity.py" + (" --quick" if a.quick else ""),
        "date": datetime.date.today().isoformat(),
        "n_rays_per_row": n_rays,
        "ray_seeds": seeds,
        "z_mm": list(zs),
        "rmtf_error_z_max_mm": RMTF_Z_MAX_MM,
        "tolerances": {"light": DEFAULT_LIGHT_TOL, "rmtf": DEFAULT_RMTF_TOL},
        "chosen_predictor": CHOSEN,
        "envelope_margin": ENVELOPE_MARGIN,
        "predictors": {
            n: {k: (v.to_dict() if hasattr(v, "to_dict") else v) for k, v in s.items()}
            for n, s in summary.items()
        },
        "designs": rows,
        "seconds": time.perf_counter() - t0,
    }
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "img").mkdir(exist_ok=True)
    write_atomic(a.out / "wave-validity.json", to_json(data))
    env = {"light": summary[CHOSEN]["light_envelope"], "rmtf": summary[CHOSEN]["rmtf_envelope"]}
    save_figure(plot(rows, env, CHOSEN), a.out / "img" / "wave-validity.png")
    print(
        f"wrote {a.out / 'wave-validity.json'} and img/wave-validity.png "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
