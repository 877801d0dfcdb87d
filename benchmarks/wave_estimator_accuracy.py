"""How far the search's wave estimator is from the exact wave figures (run on demand:
python benchmarks/wave_estimator_accuracy.py [N600] [N1200] [SEED]).

Random designs of the 600-dpi and 1200-dpi search spaces (the paper's design scaled by
``scale_to_dpi``; ``default_space``: square holes in 1 um steps, slabs in 50 um steps
within the 2.5 mm budget) are drawn until N600 (default 10) and N1200 (default 4) are
feasible as a wave-optics search judges them (no traced light beyond the band within
1 mm, within the budget), and the 600-dpi half-scale prototype (every length halved:
holes 24/20/20 um, slabs 500/200/225 um) is added. Each is evaluated by the wave
estimator (studies/waveestimate.py ``evaluate_wave``, the search's 2^17 rays) and by the
exact wave figures (``exact_wave_figures``: efficiency and rmtf with optics wave,
2^20 and 2^19 rays), both on the design's depth-of-field chart. Printed: the error of
every figure (mean, RMS, largest) and the time of each; written as JSON to
benchmarks/wave_estimator_accuracy.json. ``WAVE_ACCURACY`` in studies/waveestimate.py
is the largest error measured here, times 1.2.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from opticalstamp.design import load_design, scale_to_dpi, stack_params, with_stack
from opticalstamp.design.resolution import dof_chart_dpi
from opticalstamp.studies.search import default_space
from opticalstamp.studies.waveestimate import (
    FAST_ORDERS,
    evaluate_wave,
    exact_wave_figures,
    wave_errors,
)

BUDGET_UM = 2500.0
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


def compare(d, label: str) -> dict:
    dpi = dof_chart_dpi(d)
    t0 = time.perf_counter()
    est = evaluate_wave(d, dpi=dpi)
    t1 = time.perf_counter()
    ex = exact_wave_figures(d, dpi=dpi)
    t2 = time.perf_counter()
    err = wave_errors(est, ex)
    print(
        f"{label}: est {est['efficiency_ratio']:.4f} {est['dof_mm']:.3f} mm "
        f"{est['ghost_fraction']:.3f} ({t1 - t0:.1f} s) exact {ex['efficiency_ratio']:.4f} "
        f"{ex['dof_mm']:.3f} mm {ex['ghost_fraction']:.3f} ({t2 - t1:.1f} s) "
        + " ".join(f"{k} {v:.3g}" for k, v in err.items()),
        flush=True,
    )
    keep = ("efficiency_ratio", "dof_mm", "ghost_fraction", "rmtf_at", "nearest_ghost_mm")
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
        "exact_s": t2 - t1,
    }


def main(n600: int = 10, n1200: int = 4, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    paper = load_design("paper2016")
    rows = []
    half = with_stack(scale_to_dpi(paper, 600), thicknesses_um=(500, 200, 225), name="half")
    rows.append(compare(half, "half-scale prototype") | {"dpi": 600})
    for dpi, n in ((600, n600), (1200, n1200)):
        base = scale_to_dpi(paper, dpi)
        space = default_space(base, BUDGET_UM)
        found = drawn = 0
        while found < n:
            holes, ts = draw(rng, space, len(base.masks), BUDGET_UM)
            drawn += 1
            d = with_stack(base, holes_um=holes, thicknesses_um=ts)
            est = evaluate_wave(d, dpi=dof_chart_dpi(d), ghost_rays=1 << 15)
            if est["near_ghost"] or est["efficiency_ratio"] <= 0:
                continue
            found += 1
            rows.append(compare(d, f"{dpi} dpi #{found} (drawn {drawn})") | {"dpi": dpi})
    summary = {}
    for k in FIGURES:
        e = np.array([r["error"][k] for r in rows])
        summary[k] = {"mean": float(e.mean()), "rms": float(np.sqrt((e**2).mean())),
                      "max": float(e.max())}  # fmt: skip
    signed = np.array(
        [r["estimate"]["efficiency_ratio"] / r["exact"]["efficiency_ratio"] - 1 for r in rows]
    )
    summary["efficiency_ratio"]["signed_mean"] = float(signed.mean())
    out = {
        "what": "wave estimator (search) against the exact wave figures",
        "fast_orders": FAST_ORDERS,
        "seed": seed,
        "designs": len(rows),
        "summary": summary,
        "estimate_s_median": float(np.median([r["estimate_s"] for r in rows])),
        "exact_s_median": float(np.median([r["exact_s"] for r in rows])),
        "machine": f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}",
        "rows": rows,
    }
    for k, v in summary.items():
        print(f"{k}: mean {v['mean']:.4g}, rms {v['rms']:.4g}, largest {v['max']:.4g}")
    path = Path(__file__).with_suffix(".json")
    path.write_text(json.dumps(out, indent=1, default=float) + "\n")
    return out


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
