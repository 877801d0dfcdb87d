"""Speed of the rod-lens model (run on demand: python benchmarks/bench_rodlens.py).

1. Per preset: light efficiency to <= 0.3 % standard error plus the contrast-vs-height
   table (9 heights, 4 chart frequencies), target < 5 s on the 2-core machine.
2. Rays per second of the rod tracer (launched rays, integrator for h4/h6 profiles).
3. `opticalstamp compare paper2016 sla-1row-12deg` as a whole process, target < 30 s.
Medians of several runs after a warm-up (kernels compiled and cached first).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from bench_metrics import median_time

from opticalstamp.analysis.rodlens import rod_contrast, rod_efficiency
from opticalstamp.design import load_design
from opticalstamp.raytrace.rodlens import trace_rods


def _both(design):
    e = rod_efficiency(design)
    c = rod_contrast(design)
    return e, c


if __name__ == "__main__":
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    for name in ("sla-1row-12deg", "sla-2row-20deg"):
        d = load_design(name)
        t, (e, c) = median_time(lambda d=d: _both(d), 3)
        print(
            f"{name}: efficiency (SE {e.etendue_se / e.etendue_um2sr:.2%}) + contrast table "
            f"{len(c.heights_mm)} heights x {len(c.dpi)} dpi: {t:.2f} s"
        )
        n = 1 << 22
        pix = np.linspace(0, 2 * d.array.rod_radius_um, 32, endpoint=False)
        t, _ = median_time(lambda d=d, pix=pix, n=n: trace_rods(d, pix, n_rays=n), 3)
        print(f"{name}: rod tracer {n / t / 1e6:.2f} M launched rays/s")
    with tempfile.TemporaryDirectory() as tmp:
        exe = Path(sys.executable).with_name("opticalstamp")
        cmd = [str(exe) if exe.exists() else "opticalstamp", "compare", "paper2016"]
        cmd += ["sla-1row-12deg"]
        cmd += ["-o", f"{tmp}/c"]

        def run():
            subprocess.run(cmd, check=True, capture_output=True)

        t, _ = median_time(run, 3)
    print(f"compare paper2016 sla-1row-12deg (whole process): {t:.1f} s")
