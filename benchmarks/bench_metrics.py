"""Speed of the metrics (run on demand: python benchmarks/bench_metrics.py).

1. The full RMTF table of the prototype: 4 chart periods x 19 distances (0-4.5 mm),
   maximised over chart shifts (1 um steps), standard error <= 0.005, exact tracer with
   ghost light.
2. The Fresnel diffraction profile of the paper's Fig. 6 slit at two wavelengths.
Medians of several runs after a warm-up (kernels compiled and cached first).
"""

from __future__ import annotations

import statistics
import time

from opticalstamp.analysis.diffraction import slit_case
from opticalstamp.analysis.rmtf import rmtf
from opticalstamp.design import load_design


def median_time(fn, repeats: int) -> tuple[float, object]:
    fn()
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


if __name__ == "__main__":
    design = load_design("paper2016")
    t, res = median_time(lambda: rmtf(design), 5)
    se = max(max(v) for v in res.rmtf_max_se.values())
    print(f"RMTF table 4 periods x {len(res.z_mm)} Z: {t:.2f} s (max SE {se:.4f})")
    t, _ = median_time(lambda: rmtf(design, method="paraxial"), 5)
    print(f"RMTF table, paraxial closed form (own path): {t:.3f} s")
    t, _ = median_time(lambda: slit_case(wavelengths_um=(0.4, 0.7)), 5)
    print(f"diffraction profile at two wavelengths: {t:.3f} s")
