"""Three estimators of RMTF and depth of field, measured on a set of designs.

Run on demand (not in the test suite)::

    python benchmarks/estimators.py [--out results.json] [--seed 0]

A design's depth of field (largest Z with RMTF >= 0.3 for the 200-dpi chart, paper Eq. 1,
Fig. 11) and its RMTF are computed in three ways in opticalstamp (docs/estimators.md):

1. ``trace``: the exact tracer, own and ghost light (``rmtf(design, method="trace")``),
   the estimator of record;
2. ``paraxial``: the closed form of the own path (``rmtf(design, method="paraxial")``),
   rectangular holes, no ghost light;
3. ``surrogate``: what the search and the tolerancing use
   (``studies.evaluate.evaluate_design``): the paraxial own path plus the ghost light as
   a uniform background from a sampled ghost etendue.

For about a dozen designs derived from the paper's prototype with the variant functions
of ``opticalstamp.design`` this script measures DOF(200 dpi) and RMTF(200 dpi) at Z = 1,
2 and 3 mm by all three, on one Z grid (0 to 5 mm in 0.05 mm steps), with the trace's
ray count doubled until its largest standard error on the grid is <= 0.005. It also
records what explains the differences:

- the ghost fraction, the nearest ghost landing distance and the ghost paths that carry
  most of the ghost light (``analyse_ghosts``);
- the *ghost coherence* c(Z): the traced ghost light folded onto the chart period, its
  first Fourier coefficient over its total (0: a uniform background, the surrogate's
  assumption; 1: all ghost light at one phase);
- the trace with its own ghost light made uniform (own path traced, ghost light of the
  same rays spread evenly over the period): the trace minus this is the error of the
  uniform-background assumption alone; this minus the surrogate is the rest (paraxial
  own path, ghost etendue from 2^17 rays, 2 um chart shift steps);
- the trace's DOF on a 0.01 mm grid (the same rays), which shows where the 0.05 mm grid
  misses a dip of an oscillating RMTF curve;
- the spread of the surrogate's DOF over five seeds (its ghost etendue is sampled).

Prints the tables of docs/estimators.md and, with ``--out``, writes them as JSON with
provenance (seed, version, git commit, design fingerprints, run time). About 2-3 minutes
on the 2-core machine.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np

import opticalstamp as osp
from opticalstamp.analysis.lsf import FoldedLSF, traced_folded_lsf
from opticalstamp.analysis.rmtf import depth_of_field, rmtf_from_lsf
from opticalstamp.io.files import provenance, to_json, write_atomic
from opticalstamp.studies.evaluate import SURROGATE, evaluate_design

DPI = 200.0
THRESHOLD = 0.3
Z_AT_MM = (1.0, 2.0, 3.0)
Z_MAX_MM = 5.0
Z_STEP_MM = 0.05  # the grid of the comparison (all three estimators)
Z_FINE_STEP_MM = 0.01  # the trace is folded on this grid too (a check of the DOF)
GHOST_Z_MM = (0.0, 1.0, 2.0, 3.0, 4.0, 5.0)
SE_TARGET = 0.005
FIRST_RAYS = 1 << 21
MAX_RAYS = 1 << 24
SURROGATE_SEEDS = 5
NEAR_MM = 1.0  # the search's default near-ghost constraint (--near-mm)
CHART_WINDOW_MM = 5.0  # the default chart window (--window-um 5000)


# -- the designs ---------------------------------------------------------------------------
def four_layers(design: osp.Design) -> osp.Design:
    """The design with its object-side plate split in two equal plates and a fourth mask
    between them, its hole the mean of the masks above and below (48/40 -> 44 um)."""
    slabs = [sl.model_dump(mode="json", exclude_none=True) for sl in design.slabs]
    top = slabs[-1]
    below = next(s for s in reversed(slabs[:-1]) if "mask_top" in s)
    size = (top["mask_top"]["size_um"] + below["mask_top"]["size_um"]) / 2
    half = top["thickness_um"] / 2
    mid = {
        "medium": top["medium"],
        "thickness_um": half,
        "mask_top": {"name": "layer 1b", "shape": "square", "size_um": size},
    }
    top = dict(top, thickness_um=half)
    return osp.replace(design, {"slabs": [*slabs[:-1], mid, top], "name": "4 layers"})


def designs() -> dict[str, tuple[osp.Design, str]]:
    """{label: (design, what it is)}, all derived from the prototype by opticalstamp.design."""
    d = osp.load_design("paper2016")
    two = next(iter(osp.structural_variants(d, layers=(2,)).values()))
    return {
        "prototype": (d, "paper2016: holes 48/40/40 um, slabs 450/400/1000 um, air gap"),
        "holes 52/40/40": (
            osp.with_stack(d, holes_um=(52, 40, 40), name="holes 52/40/40"),
            "larger object-side hole",
        ),
        "holes 40/32/32": (
            osp.with_stack(d, holes_um=(40, 32, 32), name="holes 40/32/32"),
            "smaller holes",
        ),
        "L1 plate 1.5 mm": (
            osp.with_stack(d, thicknesses_um=(450, 400, 1500), name="L1 plate 1.5 mm"),
            "object-side plate (t2) 1.0 -> 1.5 mm",
        ),
        "L2 plate 0.5 mm": (
            osp.with_stack(d, thicknesses_um=(450, 500, 1000), name="L2 plate 0.5 mm"),
            "layer-2 plate (t1) 0.4 -> 0.5 mm",
        ),
        "newcomer": (
            osp.with_stack(
                d,
                holes_um=(52, 40, 40),
                thicknesses_um=(450, 500, 1000),
                offsets_um=((0, 0), (5, 0), (0, 0)),
                name="newcomer",
            ),
            "hole 52/40/40, layer-2 plate 0.5 mm, layer 2 offset_x 5 um (review 4bf8144)",
        ),
        "2 layers": (two, "middle mask dropped (paper Fig. 1d), structural_variants"),
        "4 layers": (four_layers(d), "object-side plate split 500/500 um, 44 um mask between"),
        "600 dpi": (osp.scale_to_dpi(d, 600), "scale_to_dpi: holes 24/20/20 um, same plates"),
        "200 dpi": (osp.scale_to_dpi(d, 200), "scale_to_dpi: holes 72/60/60 um, same plates"),
        "light-guide gap": (
            osp.replace(d, {"reference_gap.medium": 1.49, "name": "light-guide gap"}),
            "reference gap of n = 1.49 (a light-guide plate)",
        ),
    }


# -- one design ----------------------------------------------------------------------------
def _grids() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    fine = np.round(np.arange(0.0, Z_MAX_MM + 1e-9, Z_FINE_STEP_MM), 4)
    step = round(Z_STEP_MM / Z_FINE_STEP_MM)
    coarse_idx = np.arange(0, fine.size, step)
    return fine, fine[coarse_idx], coarse_idx


def _at(z: np.ndarray, values, zs=Z_AT_MM) -> dict[str, float]:
    v = np.asarray(values, dtype=np.float64)
    return {f"{q:g}": float(v[int(np.argmin(np.abs(z - q)))]) for q in zs}


def _uniform_ghosts(all_light: FoldedLSF, own: FoldedLSF) -> FoldedLSF:
    """The traced own path plus the same rays' ghost light spread evenly over the period."""
    h_g = all_light.h[0] - own.h[0]
    h = own.h[0] + h_g.sum(axis=-1, keepdims=True) / h_g.shape[-1]
    return FoldedLSF(
        own.z_mm, own.periods_um, own.rows, [h], "trace", own.n_rays, True, own.fresnel
    )


def _coherence(all_light: FoldedLSF, own: FoldedLSF) -> np.ndarray:
    """c(Z) = |first Fourier coefficient| / total of the folded ghost light (both rows)."""
    h_g = (all_light.h[0] - own.h[0]).sum(axis=(0, 1))  # (nz, bins)
    n = h_g.shape[-1]
    phase = np.exp(-2j * np.pi * (np.arange(n) + 0.5) / n)
    tot = h_g.sum(axis=-1)
    return np.where(tot > 0, np.abs(h_g @ phase) / np.where(tot > 0, tot, 1.0), np.nan)


def trace_estimates(design: osp.Design, seed: int) -> dict:
    """The exact tracer (rays doubled until the largest SE <= SE_TARGET) and its diagnostics."""
    fine, coarse, idx = _grids()
    period = osp.period_of_dpi(DPI)
    n = FIRST_RAYS
    while True:
        lsf = traced_folded_lsf(
            design, z_mm=fine, periods_um=[period], n_rays=n, seed=seed, ghosts=True
        )
        res = rmtf_from_lsf(lsf, design, dpi=[DPI], seed=seed, dof_threshold=THRESHOLD)
        se = float(np.max(res.rmtf_max_se[f"{DPI:g}"]))
        if se <= SE_TARGET or n >= MAX_RAYS:
            break
        n *= 2
    own = traced_folded_lsf(
        design, z_mm=fine, periods_um=[period], n_rays=n, seed=seed, ghosts=False
    )
    res_own = rmtf_from_lsf(own, design, dpi=[DPI], seed=seed, dof_threshold=THRESHOLD)
    res_uni = rmtf_from_lsf(
        _uniform_ghosts(lsf, own), design, dpi=[DPI], seed=seed, dof_threshold=THRESHOLD
    )
    key = f"{DPI:g}"
    curve = np.asarray(res.rmtf_max[key])
    curve_own = np.asarray(res_own.rmtf_max[key])
    curve_uni = np.asarray(res_uni.rmtf_max[key])
    coh = _coherence(lsf, own)
    in03 = fine <= 3.0 + 1e-9
    return {
        "n_rays_per_row": int(lsf.n_rays),
        "max_se": se,
        "dof_mm": depth_of_field(coarse, curve[idx], THRESHOLD),
        "dof_mm_fine_grid": depth_of_field(fine, curve, THRESHOLD),
        "rmtf_at": _at(fine, curve),
        "rmtf_se_at": _at(fine, res.rmtf_max_se[key]),
        "rmtf_curve": curve[idx].tolist(),
        "own_dof_mm": depth_of_field(coarse, curve_own[idx], THRESHOLD),
        "own_rmtf_at": _at(fine, curve_own),
        "uniform_ghost_dof_mm": depth_of_field(coarse, curve_uni[idx], THRESHOLD),
        "uniform_ghost_rmtf_at": _at(fine, curve_uni),
        "uniform_ghost_rmtf_curve": curve_uni[idx].tolist(),
        "max_abs_ghost_model_error_0_3mm": float(np.max(np.abs(curve - curve_uni)[in03])),
        "ghost_coherence_at": _at(fine, coh, (0.0, *Z_AT_MM)),
        "ghost_coherence_curve": coh[idx].tolist(),
        "ghost_coherence_max_0_3mm": (
            float(np.nanmax(coh[in03])) if np.isfinite(coh[in03]).any() else math.nan
        ),
        "_result": res,
    }


def ghost_summary(design: osp.Design, seed: int) -> dict:
    """Ghost fraction, nearest landing and the path pair that carries most ghost light."""
    g = osp.analyse_ghosts(design, z_mm=GHOST_Z_MM, seed=seed)
    near = {
        k: (v["nearest_um"] / 1000.0 if v["nearest_um"] is not None else None)
        for k, v in g.landing.items()
    }
    finite = [v for v in near.values() if v is not None]
    top = g.paths[:2]
    return {
        "ghost_fraction": g.ghost_fraction,
        "ghost_fraction_se": g.ghost_fraction_se,
        "n_rays": g.n_rays,
        "etendue_own_um2sr": g.etendue_own_um2sr,
        "etendue_ghost_um2sr": g.etendue_ghost_um2sr,
        "etendue_ghost_se": g.etendue_ghost_se,
        "nearest_landing_mm": near,
        "nearest_landing_min_mm": min(finite) if finite else None,
        "n_paths": len(g.paths),
        "top_pair_share": float(sum(p.share for p in top)),
        "top_pair_angle_deg": (
            [min(p.emission_angle_deg[0] for p in top), max(p.emission_angle_deg[1] for p in top)]
            if top
            else None
        ),
        "top_pair_holes": [[(h["row"], h["dk"]) for h in p.holes] for p in top],
        "top_pair_nearest_mm_z0": (
            min(p.nearest_landing_um["0"] for p in top) / 1000.0
            if top and all(p.nearest_landing_um["0"] is not None for p in top)
            else None
        ),
    }


def measure(label: str, design: osp.Design, note: str, seed: int) -> dict:
    t0 = time.perf_counter()
    _, coarse, _ = _grids()
    tr = trace_estimates(design, seed)
    res = tr.pop("_result")
    try:
        par = osp.rmtf(design, dpi=(DPI,), z_mm=coarse, method="paraxial")
        p_curve = par.rmtf_max[f"{DPI:g}"]
        paraxial = {"dof_mm": par.dof_mm[f"{DPI:g}"], "rmtf_at": _at(coarse, p_curve)}
    except ValueError as err:  # circular holes: no closed form
        paraxial = {"dof_mm": None, "rmtf_at": None, "error": str(err)}
    # rmtf_z_mm on the grid itself: the surrogate's whole curve (interpolation at nodes)
    sur = evaluate_design(design, dpi=DPI, z_mm=coarse, rmtf_z_mm=tuple(coarse), seed=seed)
    s_curve = np.array([sur["rmtf_at"][f"{z:g}"] for z in coarse])
    t_curve = np.asarray(tr["rmtf_curve"])
    in03 = coarse <= 3.0 + 1e-9
    worst = int(np.argmax(np.abs(s_curve - t_curve)[in03]))
    sur_dofs = [
        evaluate_design(design, dpi=DPI, z_mm=coarse, rmtf_z_mm=Z_AT_MM, seed=s)["dof_mm"]
        for s in range(seed, seed + SURROGATE_SEEDS)
    ]
    surrogate = {
        "dof_mm": sur["dof_mm"],
        "rmtf_at": _at(coarse, s_curve),
        "rmtf_curve": s_curve.tolist(),
        "max_abs_error_0_3mm": float(abs(s_curve[worst] - t_curve[worst])),
        "max_abs_error_z_mm": float(coarse[worst]),
        "etendue_ghost_um2sr": sur["etendue_ghost_um2sr"],
        "ghost_fraction": sur["ghost_fraction"],
        "nearest_ghost_mm": sur["nearest_ghost_mm"],
        "near_ghost": sur["near_ghost"],
        "dof_mm_over_seeds": sur_dofs,
    }
    out = {
        "label": label,
        "note": note,
        **provenance(design, seed),
        "stack": osp.stack_params(design),
        "output_pitch_um": osp.output_pitch(design),
        "trace": tr,
        "paraxial": paraxial,
        "surrogate": surrogate,
        "ghosts": ghost_summary(design, seed),
        "seconds": 0.0,
    }
    out["trace"]["fingerprint_checked"] = res.fingerprint == design.fingerprint()
    out["seconds"] = time.perf_counter() - t0
    return out


def check_against_api(design: osp.Design, seed: int, n_rays: int, expect: dict) -> bool:
    """The trace here is ``osp.rmtf(method="trace")``: the same DOF on the fine grid."""
    fine, _, _ = _grids()
    r = osp.rmtf(design, dpi=(DPI,), z_mm=fine, method="trace", n_rays=n_rays, seed=seed)
    return abs(r.dof_mm[f"{DPI:g}"] - expect["dof_mm_fine_grid"]) < 1e-12


# -- summaries -----------------------------------------------------------------------------
def flipped_pairs(rows: list[dict], key, min_gap: float) -> list[list[str]]:
    """Pairs of designs that the trace and the surrogate order differently, where one of
    them separates the pair by more than ``min_gap``."""
    out = []
    for i, a in enumerate(rows):
        for b in rows[i + 1 :]:
            ta, tb = key(a, "trace"), key(b, "trace")
            sa, sb = key(a, "surrogate"), key(b, "surrogate")
            if (ta - tb) * (sa - sb) < 0 and max(abs(ta - tb), abs(sa - sb)) > min_gap:
                out.append([a["label"], b["label"]])
    return out


def kendall_tau(x: list[float], y: list[float]) -> float:
    n, s = len(x), 0.0
    for i in range(n):
        for j in range(i + 1, n):
            s += np.sign(x[i] - x[j]) * np.sign(y[i] - y[j])
    return float(2 * s / (n * (n - 1))) if n > 1 else math.nan


def summarise(rows: list[dict]) -> dict:
    def dof(r, est):
        return r[est]["dof_mm"]

    def r1(r, est):
        return r[est]["rmtf_at"]["1"]

    accepted = [r for r in rows if not r["surrogate"]["near_ghost"]]
    out = {}
    for name, sel in (("all", rows), ("no_near_ghost", accepted)):
        out[name] = {
            "designs": [r["label"] for r in sel],
            "kendall_tau_dof": kendall_tau(
                [dof(r, "trace") for r in sel], [dof(r, "surrogate") for r in sel]
            ),
            "flipped_dof_pairs": flipped_pairs(sel, dof, 0.05),
            "kendall_tau_rmtf1": kendall_tau(
                [r1(r, "trace") for r in sel], [r1(r, "surrogate") for r in sel]
            ),
            "flipped_rmtf1_pairs": flipped_pairs(sel, r1, 0.02),
        }
    return out


def _f(v, fmt=".3f") -> str:
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def print_tables(rows: list[dict], summary: dict) -> None:
    print("\nDOF at 200 dpi (mm, 0.05 mm grid; trace on a 0.01 mm grid in brackets)")
    print(
        f"{'design':17s} {'trace':>15s} {'paraxial':>8s} {'surr.':>6s} {'sur-tr':>7s} "
        f"{'sur seeds':>11s} {'unif.':>6s} {'gf':>6s} {'near':>5s} {'pair':>5s} "
        f"{'angle':>9s} {'c max':>5s}"
    )
    for r in rows:
        t, p, s, g = r["trace"], r["paraxial"], r["surrogate"], r["ghosts"]
        seeds = s["dof_mm_over_seeds"]
        ang = g["top_pair_angle_deg"]
        print(
            f"{r['label']:17s} {_f(t['dof_mm']):>6s} ({_f(t['dof_mm_fine_grid'])}) "
            f"{_f(p['dof_mm']):>8s} {_f(s['dof_mm']):>6s} {s['dof_mm'] - t['dof_mm']:+7.3f} "
            f"{min(seeds):5.2f}-{max(seeds):4.2f} {_f(t['uniform_ghost_dof_mm']):>6s} "
            f"{g['ghost_fraction']:6.3f} {_f(g['nearest_landing_min_mm'], '.2f'):>5s} "
            f"{g['top_pair_share']:5.2f} "
            f"{(f'{ang[0]:.0f}-{ang[1]:.0f}' if ang else '—'):>9s} "
            f"{_f(t['ghost_coherence_max_0_3mm'], '.2f'):>5s}"
        )
    print("\nRMTF(200 dpi) at Z = 1 / 2 / 3 mm; differences to the trace")
    print(
        f"{'design':17s} {'trace':>17s} {'max SE':>6s} {'paraxial':>17s} {'surrogate':>17s} "
        f"{'surrogate - trace':>20s} {'unif. - trace':>20s} {'max |s-t| (Z)':>14s}"
    )
    for r in rows:
        t, p, s = r["trace"], r["paraxial"], r["surrogate"]
        zs = [f"{z:g}" for z in Z_AT_MM]

        def three(d, zs=zs):
            return " ".join(_f(d[z], ".3f") for z in zs) if d else "—"

        ds = {z: s["rmtf_at"][z] - t["rmtf_at"][z] for z in zs}
        du = {z: t["uniform_ghost_rmtf_at"][z] - t["rmtf_at"][z] for z in zs}
        print(
            f"{r['label']:17s} {three(t['rmtf_at']):>17s} {t['max_se']:6.4f} "
            f"{three(p['rmtf_at']):>17s} {three(s['rmtf_at']):>17s} "
            f"{' '.join(f'{ds[z]:+.3f}' for z in zs):>20s} "
            f"{' '.join(f'{du[z]:+.3f}' for z in zs):>20s} "
            f"{s['max_abs_error_0_3mm']:6.3f} ({s['max_abs_error_z_mm']:.2f})"
        )
    for name, s in summary.items():
        print(
            f"\n{name}: Kendall tau (trace vs surrogate) DOF {s['kendall_tau_dof']:.2f}, "
            f"RMTF(1 mm) {s['kendall_tau_rmtf1']:.2f}\n  DOF pairs ordered differently "
            f"(> 0.05 mm apart): {s['flipped_dof_pairs']}\n  RMTF(1 mm) pairs ordered "
            f"differently (> 0.02 apart): {s['flipped_rmtf1_pairs']}"
        )


def _git(*args: str) -> str | None:
    try:
        root = Path(__file__).resolve().parents[1]
        return subprocess.run(
            ["git", *args], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="write the results as JSON here")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    for label, (design, note) in designs().items():
        row = measure(label, design, note, args.seed)
        rows.append(row)
        print(
            f"{label}: {row['seconds']:.1f} s ({row['trace']['n_rays_per_row']} rays per row)",
            file=sys.stderr,
        )
    d0 = osp.load_design("paper2016")
    same = check_against_api(d0, args.seed, rows[0]["trace"]["n_rays_per_row"], rows[0]["trace"])
    summary = summarise(rows)
    print_tables(rows, summary)
    seconds = time.perf_counter() - t0
    print(f"\ntrace == rmtf(method='trace') on the prototype: {same}; total {seconds:.0f} s")
    if args.out:
        fine, coarse, _ = _grids()
        doc = {
            "what": "RMTF(200 dpi) and DOF by three estimators: trace, paraxial, surrogate",
            "provenance": {
                "seed": args.seed,
                "opticalstamp_version": osp.__version__,
                "git_commit": _git("rev-parse", "HEAD"),
                "git_src_dirty": bool(_git("status", "--porcelain", "--", "src")),
                "python": platform.python_version(),
                "numpy": np.__version__,
                "numba": numba.__version__,
                "platform": platform.platform(),
                "cpu_count": os.cpu_count(),
                "numba_threads": numba.get_num_threads(),
                "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "seconds": seconds,
            },
            "settings": {
                "dpi": DPI,
                "dof_threshold": THRESHOLD,
                "z_grid_mm": coarse.tolist(),
                "z_fine_step_mm": Z_FINE_STEP_MM,
                "rmtf_z_mm": list(Z_AT_MM),
                "trace_se_target": SE_TARGET,
                "trace_rays": [FIRST_RAYS, MAX_RAYS],
                "window_um": 5000.0,
                "surrogate": SURROGATE,
                "surrogate_seeds": list(range(args.seed, args.seed + SURROGATE_SEEDS)),
                "near_mm": NEAR_MM,
            },
            "trace_equals_rmtf_api": same,
            "designs": rows,
            "summary": summary,
        }
        write_atomic(args.out, to_json(doc))
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
