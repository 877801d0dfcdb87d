"""Speed of restoration (run on demand: python benchmarks/bench_restore.py [--repeats N]).

An A4 page at the prototype's 300-dpi output grid (3508 x 2480 pixels, a scan at 3 mm
with noise: the 8-pt text chart tiled over the page) restored with the known blur:
Wiener, Richardson-Lucy (30 iterations) and TV (ADMM, 60 iterations); targets (issue 13,
2-core machine): Wiener <= 3 s, RL <= 20 s, TV <= 60 s. Each time is the median of
``--repeats`` runs after one warm-up, for the restoration alone (the kernels are built
once beforehand, as for a batch of pages) and with the kernels built (a single page).
Writes benchmarks/bench_restore.json.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from opticalstamp import __version__
from opticalstamp.design import load_design
from opticalstamp.imaging.charts import text_chart
from opticalstamp.imaging.outputkernel import output_kernel
from opticalstamp.imaging.restore import METHODS, MODEL_ERROR, noise_sigma, restore, restore_scan
from opticalstamp.imaging.scan import ScanSettings, simulate_scan

A4 = (3508, 2480)  # lines x columns at 300 dpi (297 x 210 mm)
TARGETS_S = {"wiener": 3.0, "rl": 20.0, "tv": 60.0}


def a4_scan(design, z: float) -> np.ndarray:
    """An A4 page of 8-pt text at 300 dpi: one scan of the text chart tiled."""
    doc, _ = text_chart(1200.0, 8.0)
    r = simulate_scan(doc, 1200.0, design, z_mm=z, seed=0)
    reps = (A4[0] // r.image.shape[0] + 1, A4[1] // r.image.shape[1] + 1)
    return np.tile(r.image, reps)[: A4[0], : A4[1]]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    design = load_design("paper2016")
    z = 3.0
    st = ScanSettings()
    page = a4_scan(design, z)
    ok = output_kernel(design, z, settings=st)
    sigma = noise_sigma(st.sensor, ok.white, MODEL_ERROR)
    out = {
        "design": design.name,
        "page_px": list(page.shape),
        "z_mm": z,
        "machine": platform.processor() or platform.machine(),
        "opticalstamp_version": __version__,
        "repeats": args.repeats,
        "methods": {},
    }
    for method in METHODS:
        restore(page, ok, method=method, sigma=sigma, surround=1.0)  # warm-up
        times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            restore(page, ok, method=method, sigma=sigma, surround=1.0)
            times.append(time.perf_counter() - t)
        t = time.perf_counter()
        restore_scan(page, design, z_mm=z, method=method)
        whole = time.perf_counter() - t
        med = statistics.median(times)
        out["methods"][method] = {
            "median_s": med,
            "runs_s": times,
            "with_kernels_s": whole,
            "target_s": TARGETS_S[method],
            "meets_target": med <= TARGETS_S[method],
        }
        print(
            f"{method:7s} A4 {page.shape[1]}x{page.shape[0]}: {med:.2f} s median "
            f"({whole:.2f} s with the kernels built; target {TARGETS_S[method]:g} s)"
        )
    path = Path(__file__).with_suffix(".json")
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
