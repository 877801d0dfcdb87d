"""Speed of the design search and the tolerancing on both cores (run on demand:
python benchmarks/bench_search.py).

1. The 300-dpi search of the paper's stack: NSGA-II, 32 designs x 15 generations (480
   evaluations plus the base design), local process pool on every core.
2. Tolerancing: 1,000 Monte Carlo samples (plus the one-at-a-time sensitivity table).
No journal, so every run evaluates from scratch. Medians of 3 runs.
"""

from __future__ import annotations

import os
import statistics
import time

from opticalstamp.design import load_design
from opticalstamp.studies.search import search
from opticalstamp.studies.tolerance import tolerance


def timed(fn, repeats: int = 3):
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


if __name__ == "__main__":
    d = load_design("paper2016")
    print(f"cores: {os.cpu_count()}")
    t, r = timed(lambda: search(d, dpi=300.0, population=32, generations=15))
    print(
        f"300-dpi search, {len(r.records)} designs: {t:.1f} s; base design dominated by "
        f"{r.reference.get('dominated_by')} designs; front of {len(r.pareto)}"
    )
    t, r = timed(lambda: tolerance(d, samples=1000, spec="dof>=2.2,ghost<=0.2"))
    print(f"tolerancing, 1000 samples: {t:.1f} s; yield {r.yield_fraction:.1%}")
