"""Speed and memory of the scan simulation (run on demand: python benchmarks/bench_scan.py).

An A4 page (210 x 297 mm) read from a 1200-dpi grey PNG, scanned by the prototype to the
300-dpi output (PNG and 16-bit TIFF written), with ghosts and noise: at a constant
Z = 1 mm, with a tilt height map (0.5 -> 3 mm) and with a crumpled page (1.5 mm). Each
case runs in a fresh process (after a warm-up that compiles the kernels) so that its
peak memory (VmHWM, the high-water mark of its resident set since exec) is its
own. Medians of 3 runs.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CASE = r"""
import json, sys, time
from pathlib import Path
from opticalstamp.design import load_design
from opticalstamp.imaging.heightmap import load_height_map
from opticalstamp.io.files import read_document, write_png, write_tiff16
from opticalstamp.imaging.scan import simulate_scan
src, out, spec = sys.argv[1], Path(sys.argv[2]), sys.argv[3]
d = load_design("paper2016")
t = time.perf_counter()
doc, dpi = read_document(src)
hm = None
if spec != "const":
    hm = load_height_map(spec, doc.shape[0] * 25.4 / dpi, doc.shape[1] * 25.4 / dpi, 0)
r = simulate_scan(doc, dpi, d, z_mm=1.0 if hm is None else None, height_map=hm, seed=0)
write_png(out / "scan.png", r.image, r.dpi)
write_tiff16(out / "scan.tif", r.image, r.dpi)
dt = time.perf_counter() - t
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM")][0].split()[1]
print(json.dumps({"s": dt, "rss_gb": int(hwm) / 1e6, "shape": list(r.image.shape)}))
"""


def make_page(path: Path) -> None:
    import numpy as np

    from opticalstamp.imaging.charts import text_chart
    from opticalstamp.io.files import write_png

    text, _ = text_chart(1200.0)
    h, w = 14031, 9921  # A4 at 1200 dpi
    page = np.ones((h, w))
    for y in range(0, h - text.shape[0], text.shape[0]):
        page[y : y + text.shape[0], : min(w, text.shape[1])] = text[:, :w]
    write_png(path, page, 1200.0, srgb=False)


def run(src: Path, out: Path, spec: str) -> dict:
    res = subprocess.run(
        [sys.executable, "-c", CASE, str(src), str(out), spec],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(res.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t = time.perf_counter()
        make_page(tmp / "a4.png")
        print(f"A4 1200-dpi test page written in {time.perf_counter() - t:.1f} s")
        run(tmp / "a4.png", tmp, "const")  # warm-up: compile and cache the kernels
        for spec in ("const", "tilt:0.5:3", "crumple:1.5:15"):
            runs = [run(tmp / "a4.png", tmp, spec) for _ in range(3)]
            s = statistics.median(r["s"] for r in runs)
            gb = max(r["rss_gb"] for r in runs)
            print(f"{spec:16s} {s:6.2f} s   peak memory {gb:.2f} GB   output {runs[0]['shape']}")
