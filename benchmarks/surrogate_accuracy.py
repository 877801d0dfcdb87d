"""How far the search's surrogate is from the exact tracer (run on demand:
python benchmarks/surrogate_accuracy.py [N] [SEED]).

Random designs of the prototype's 300-dpi search space (studies/search.py
``default_space``: square holes in 1 um steps, slabs in 50 um steps within the 2.5 mm
budget) are drawn until N (default 40) are feasible as the search defines it (no ghost
light within 1 mm at Z = 0 ... 4 mm, spill <= 0.25, within the budget). Each is
evaluated by the surrogate (studies/evaluate.py) and by the exact tracer
(studies/verify.py). Printed: the error of every figure (mean, RMS, 95th percentile,
largest) and the rank correlation of the depth of field; written as JSON to
benchmarks/surrogate_accuracy.json. ``SURROGATE_ACCURACY`` in studies/verify.py is the
95th percentile measured here.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from opticalstamp.design import load_design, with_stack
from opticalstamp.studies.evaluate import evaluate_design
from opticalstamp.studies.search import default_space
from opticalstamp.studies.verify import exact_figures


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


def stats(err: np.ndarray) -> dict:
    a = np.abs(err)
    return {
        "mean": float(err.mean()),
        "rms": float(np.sqrt((err**2).mean())),
        "p95_abs": float(np.percentile(a, 95)),
        "max_abs": float(a.max()),
    }


def _regime(rows, lo, hi):
    """Errors of the designs whose exact ghost fraction is in [lo, hi)."""
    sel = [r for r in rows if lo <= r["exact"]["ghost_fraction"] < hi]
    if not sel:
        return {"designs": 0}
    dof = np.array([r["surrogate"]["dof_mm"] - r["exact"]["dof_mm"] for r in sel])
    rm = np.array([v - r["exact"]["rmtf_at"][z] for r in sel
                   for z, v in r["surrogate"]["rmtf_at"].items()])  # fmt: skip
    return {"designs": len(sel), "dof_mm": stats(dof), "rmtf_at_1_2_3_mm": stats(rm)}


if __name__ == "__main__":
    n_want = int(sys.argv[1]) if len(sys.argv) > 1 else 40
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    base = load_design("paper2016")
    budget = 2500.0
    space = default_space(base, budget)
    rng = np.random.default_rng(seed)
    rows, tried = [], 0
    t0 = time.perf_counter()
    while len(rows) < n_want:
        holes, ts = draw(rng, space, len(base.masks), budget)
        tried += 1
        d = with_stack(base, holes_um=holes, thicknesses_um=ts, name=f"random-{tried}")
        s = evaluate_design(d, seed=seed)
        if s["near_ghost"] or s["diffraction_spill"] > 0.25:
            continue
        e = exact_figures(d, seed=seed)
        rows.append({"holes_um": holes, "thicknesses_um": ts, "surrogate": s, "exact": e})
        print(
            f"{len(rows):3d}/{n_want} holes {holes} slabs {ts}: DOF {s['dof_mm']:.2f} / "
            f"{e['dof_mm']:.2f} mm, light {s['efficiency_ratio']:.4f} / "
            f"{e['efficiency_ratio']:.4f}, ghosts {s['ghost_fraction']:.3f} / "
            f"{e['ghost_fraction']:.3f}",
            flush=True,
        )
    sv = {k: np.array([r["surrogate"][k] for r in rows]) for k in ("dof_mm", "ghost_fraction")}
    ex = {k: np.array([r["exact"][k] for r in rows]) for k in ("dof_mm", "ghost_fraction")}
    eff = np.array([r["surrogate"]["efficiency_ratio"] / r["exact"]["efficiency_ratio"] - 1
                    for r in rows])  # fmt: skip
    rm = np.array([v - r["exact"]["rmtf_at"][z] for r in rows
                   for z, v in r["surrogate"]["rmtf_at"].items()])  # fmt: skip
    out = {
        "designs": len(rows),
        "drawn": tried,
        "seed": seed,
        "cores": os.cpu_count(),
        "elapsed_s": time.perf_counter() - t0,
        "dof_mm": stats(sv["dof_mm"] - ex["dof_mm"]),
        "dof_rank_correlation": float(spearmanr(sv["dof_mm"], ex["dof_mm"]).statistic),
        "efficiency_ratio_relative": stats(eff),
        "ghost_fraction": stats(sv["ghost_fraction"] - ex["ghost_fraction"]),
        "rmtf_at_1_2_3_mm": stats(rm),
        "near_ghost_missed": sum(r["exact"]["near_ghost"] for r in rows),
        "by_ghost_fraction": {
            f"{lo:g}-{hi:g}": _regime(rows, lo, hi) for lo, hi in ((0, 0.2), (0.2, 1.0))
        },
        "exact_rmtf_se_max": float(max(r["exact"]["rmtf_se_max"] for r in rows)),
        "rows": rows,
    }
    for k in ("dof_mm", "efficiency_ratio_relative", "ghost_fraction", "rmtf_at_1_2_3_mm"):
        print(k, {a: round(b, 4) for a, b in out[k].items()})
    print("DOF rank correlation (Spearman):", round(out["dof_rank_correlation"], 3))
    print("near ghost missed by the surrogate:", out["near_ghost_missed"])
    for k, v in out["by_ghost_fraction"].items():
        print(f"ghost fraction {k}:", json.dumps(v, default=lambda x: round(x, 4)))
    path = Path(__file__).with_name("surrogate_accuracy.json")
    path.write_text(json.dumps(out, indent=1, default=float))
    print(f"wrote {path} ({out['elapsed_s']:.0f} s)")
