"""Speed benchmarks (run on demand: python benchmarks/bench_trace.py).

1. Rays launched per second, plain Lambertian reverse trace of the prototype's pixel.
2. Wall time of the ghost analysis to 0.1 % RSE (own) and 1 % RSE (ghost).
Medians of several runs after a warm-up (kernels are compiled and cached first).
"""

from __future__ import annotations

import statistics
import time

import numba

from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.design import load_design
from opticalstamp.raytrace.launch import launch
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.stack import reverse_path


def rays_per_second(n_rays: int = 1 << 27, repeats: int = 5) -> float:
    design = load_design("paper2016")
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    for _ in launch(path, src, 1 << 20, 0, importance=False):
        pass
    rates = []
    for r in range(repeats):
        t = time.perf_counter()
        launched = sum(b.n_launched for b in launch(path, src, n_rays, r, importance=False))
        rates.append(launched / (time.perf_counter() - t))
    return statistics.median(rates)


def ghost_time(repeats: int = 5) -> tuple[float, int]:
    design = load_design("paper2016")
    analyse_ghosts(design, n_rays=1 << 20)
    times, rays = [], 0
    for r in range(repeats):
        t = time.perf_counter()
        res = analyse_ghosts(design, seed=r, rse_own=1e-3, rse_ghost=1e-2)
        times.append(time.perf_counter() - t)
        rays = res.n_rays
    return statistics.median(times), rays


if __name__ == "__main__":
    print(f"threads: {numba.get_num_threads()}")
    print(f"reverse trace, plain Lambertian: {rays_per_second() / 1e6:.0f} million rays/s launched")
    t, n = ghost_time()
    print(f"ghost analysis to 0.1 % / 1 % RSE: {t:.2f} s ({n:,} rays)")
