"""How far the search's wave estimator is from the exact wave figures (run on demand:
python benchmarks/wave_estimator_accuracy.py [N600] [N1200] [SEED] [NARROW] [REUSE]).

Random designs of the 600-dpi and 1200-dpi search spaces (the paper's design scaled by
``search_base``, every length; ``default_space``: the paper's 300-dpi space scaled to
the resolution, square holes in 1 um steps) are drawn until N600 (default 12) and N1200
(default 4) are feasible as a wave-optics search judges them (no traced light beyond the
band within 1 mm, within the budget) and have some contrast and light by the ray
surrogate (a depth of field > 0, an efficiency >= MIN_LIGHT: a design that passes no
light, 5-um holes, compares trivially), and the
600-dpi half-scale prototype (every length halved but the 1-mm reference gap: holes
24/20/20 um, slabs 500/200/225 um) is added. Each is evaluated by the wave
estimator (studies/waveestimate.py ``evaluate_wave``, the search's 2^17 rays) and by the
exact wave figures (``exact_wave_figures``: efficiency and rmtf with optics wave,
2^20 and 2^19 rays), both on the design's depth-of-field chart; with ``NARROW`` 1 also
by the estimator as it was before 2026-11-26 (a band of 4 orders, crossings refined in
4 steps), for comparison. Printed: the error of every figure (mean, RMS, largest, and
the depth of field's share within 0.05 mm) and the time of each; written as JSON to
benchmarks/wave_estimator_accuracy.json. ``WAVE_ACCURACY`` in studies/waveestimate.py
is set from the errors measured here (docs/search.md). ``REUSE``: a JSON of an earlier
run whose exact figures are taken for the same designs (the draws depend on the seed
alone; the exact figures' code unchanged), its estimates recorded as ``earlier``: to
measure a change of the estimator alone.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from opticalstamp.analysis.wavebase import wave_sampling
from opticalstamp.design import load_design, scale_to_dpi, stack_params, with_stack
from opticalstamp.design.resolution import dof_chart_dpi
from opticalstamp.studies.evaluate import evaluate_design
from opticalstamp.studies.search import default_space, search_base
from opticalstamp.studies.waveestimate import (
    ESTIMATE_ORDERS,
    evaluate_wave,
    exact_wave_figures,
    far_light,
    wave_errors,
)

BUDGET_UM = 2500.0
#: the least light (ratio to the reference lens, ray surrogate) of a design compared: the
#: fronts of the 600-dpi searches reach down to about 0.003
MIN_LIGHT = 0.002
FIGURES = ("dof_mm", "rmtf", "efficiency_ratio", "ghost_fraction")


def draw(rng, space, n_holes, budget_um):
    lo, hi = space.hole_bounds_um
    while True:
        holes = [float(rng.integers(lo, hi + 1)) for _ in range(n_holes)]
        ts = []
        for a, b in space.thickness_bounds_um:
            n = int(round((b - a) / space.thickness_step_um))
            ts.append(a + space.thickness_step_um * float(rng.integers(0, n + 1)))
        if sum(ts) <= budget_um:
            return holes, ts


def compare(d, label: str, narrow: bool = False, earlier: dict | None = None) -> dict:
    dpi = dof_chart_dpi(d)
    t0, c0 = time.perf_counter(), time.process_time()
    est = evaluate_wave(d, dpi=dpi)
    t1, c1 = time.perf_counter(), time.process_time()
    key = (tuple(stack_params(d)["holes_um"]), tuple(stack_params(d)["thicknesses_um"]), dpi)
    before = (earlier or {}).get(key)
    ex = before["exact"] if before else exact_wave_figures(d, dpi=dpi)
    t2 = before["exact_s"] + t1 if before else time.perf_counter()
    err = wave_errors(est, ex)
    old = {}
    if narrow:
        n = evaluate_wave(d, dpi=dpi, orders=4.0, refine=4)
        old = {"narrow_estimate": {k: n[k] for k in ("efficiency_ratio", "dof_mm")},
               "narrow_error": {k: float(v) for k, v in wave_errors(n, ex).items()}}  # fmt: skip
    print(
        f"{label}: est {est['efficiency_ratio']:.4f} {est['dof_mm']:.3f} mm "
        f"{est['ghost_fraction']:.3f} ({t1 - t0:.1f} s, {c1 - c0:.2f} CPU-s) exact "
        f"{ex['efficiency_ratio']:.4f} {ex['dof_mm']:.3f} mm "
        f"{ex['ghost_fraction']:.3f} ({t2 - t1:.1f} s) "
        + " ".join(f"{k} {v:.3g}" for k, v in err.items()),
        flush=True,
    )
    keep = ("efficiency_ratio", "dof_mm", "ghost_fraction", "rmtf_at", "nearest_ghost_mm")
    if before:
        old |= {"earlier_estimate": before["estimate"], "earlier_error": before["error"],
                "exact_reused": True}  # fmt: skip
        if not narrow:  # the earlier run's narrow-band figures against the same exact
            old |= {k: before[k] for k in ("narrow_estimate", "narrow_error") if k in before}
    return {
        "label": label,
        "dof_dpi": dpi,
        "holes_um": stack_params(d)["holes_um"],
        "thicknesses_um": stack_params(d)["thicknesses_um"],
        "estimate": {k: est[k] for k in keep} | {"band": est["band"]},
        "exact": {k: float(ex[k]) if k != "rmtf_at" else ex[k] for k in keep}
        | {"band": ex["band"]},
        "error": {k: float(v) for k, v in err.items()},
        "estimate_s": t1 - t0,
        "estimate_cpu_s": c1 - c0,  # this process's CPU (every thread): the shared machine's
        # load stretches the wall time, not this
        "exact_s": t2 - t1,
        "load": os.getloadavg()[0],
    } | old


def main(n600: int = 12, n1200: int = 4, seed: int = 0, narrow: int = 0, reuse: str = ""):
    rng = np.random.default_rng(seed)
    earlier = {}
    if reuse:
        for r in json.loads(Path(reuse).read_text())["rows"]:
            key = (tuple(r["holes_um"]), tuple(r["thicknesses_um"]), r["dof_dpi"])
            earlier[key] = r
    paper = load_design("paper2016")
    rows = []
    half = with_stack(scale_to_dpi(paper, 600), thicknesses_um=(500, 200, 225), name="half")
    evaluate_wave(half, dpi=dof_chart_dpi(half))  # warm: no row's time holds the JIT caches
    rows.append(compare(half, "half-scale prototype", bool(narrow), earlier) | {"dpi": 600})
    for dpi, n in ((600, n600), (1200, n1200)):
        base = search_base(paper, dpi)
        space = default_space(base, BUDGET_UM)
        found = drawn = 0
        while found < n:
            holes, ts = draw(rng, space, len(base.masks), BUDGET_UM)
            drawn += 1
            d = with_stack(base, holes_um=holes, thicknesses_um=ts)
            far = far_light(d, wave_sampling(d).band, n_rays=1 << 15)
            if far["nearest_far_mm"] < 1.0:  # the search's near-ghost constraint
                continue
            ray = evaluate_design(d, dpi=dof_chart_dpi(d), ghost_rays=1 << 15)
            if ray["dof_mm"] <= 0 or ray["efficiency_ratio"] < MIN_LIGHT:
                continue  # no contrast or no light even by ray optics: nothing to compare
            found += 1
            label = f"{dpi} dpi #{found} (drawn {drawn})"
            rows.append(compare(d, label, bool(narrow), earlier) | {"dpi": dpi})
    summary = {}
    for k in FIGURES:
        e = np.array([r["error"][k] for r in rows])
        summary[k] = {"mean": float(e.mean()), "rms": float(np.sqrt((e**2).mean())),
                      "max": float(e.max()), "p90": float(np.quantile(e, 0.9))}  # fmt: skip
    dof_err = np.array([r["error"]["dof_mm"] for r in rows])
    summary["dof_mm"]["within_0.05"] = float(np.mean(dof_err <= 0.05))
    if all("narrow_error" in r for r in rows):
        e = np.array([r["narrow_error"]["dof_mm"] for r in rows])
        summary["narrow_dof_mm"] = {"mean": float(e.mean()), "max": float(e.max()),
                                    "within_0.05": float(np.mean(e <= 0.05))}  # fmt: skip
    signed = np.array(
        [r["estimate"]["efficiency_ratio"] / r["exact"]["efficiency_ratio"] - 1 for r in rows]
    )
    summary["efficiency_ratio"]["signed_mean"] = float(signed.mean())
    if all("earlier_error" in r for r in rows):
        e = np.array([r["earlier_error"]["dof_mm"] for r in rows])
        summary["earlier_dof_mm"] = {"mean": float(e.mean()), "max": float(e.max()),
                                     "within_0.05": float(np.mean(e <= 0.05))}  # fmt: skip
    out = {
        "what": "wave estimator (search) against the exact wave figures",
        "orders": ESTIMATE_ORDERS,
        "seed": seed,
        "designs": len(rows),
        "summary": summary,
        "estimate_s_median": float(np.median([r["estimate_s"] for r in rows])),
        "estimate_cpu_s_median": float(np.median([r["estimate_cpu_s"] for r in rows])),
        "estimate_cpu_s_total": float(sum(r["estimate_cpu_s"] for r in rows)),
        "exact_s_median": float(np.median([r["exact_s"] for r in rows])),
        "machine": f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}",
        "rows": rows,
    }
    for k, v in summary.items():
        print(f"{k}: " + ", ".join(f"{a} {b:.4g}" for a, b in v.items()))
    path = Path(__file__).with_suffix(".json")
    path.write_text(json.dumps(out, indent=1, default=float) + "\n")
    return out


if __name__ == "__main__":
    args = sys.argv[1:]
    main(*(int(a) for a in args[:4]), *args[4:5])
