"""The device figures of issue 14 on whatever device traces the rays (run on demand:
python benchmarks/bench_gpu.py [--device cpu|cuda|auto] [--search-designs N] [--no-report]).

1. Plain reverse trace of the prototype's pixel: launched rays per second (2^26 samples
   on the CPU, 2^30 on a GPU), after a warm-up (compilation); on a GPU also each plain
   kernel alone (queued per block, per warp, one thread per ray), median of 5 chunks of
   2^26.
2. The ghost analysis to 0.01 % standard error on the own path and 0.1 % on the ghost
   light (the precision-driven run, capped at 2^31 rays).
3. ``search --estimator trace``: every candidate traced exactly (480 designs by default).
4. ``opticalstamp report``, the whole process, on the device.
5. Start-up: a whole process tracing a few rays, with an empty and with a filled
   compiled-code cache (the kernels are declared ``cache=True``).
Targets on an H100-class GPU: >= 1e11 rays/s (float64); ghosts < 1 s; search < 60 s;
report < 10 s. On the 2-core CPU: the exact search within 15 minutes.
Writes benchmarks/bench_gpu_DEVICE.json (cpu or cuda) with the device's name.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def device_name(device: str) -> str:
    if device == "cuda":
        from numba import cuda

        name = cuda.get_current_device().name
        return name.decode() if isinstance(name, bytes) else str(name)
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"


STARTUP = """
from opticalstamp.design import load_design
from opticalstamp.raytrace.launch import launch
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.stack import reverse_path
d = load_design("paper2016")
for importance in (False, True):
    src = pixel_source(d, 0, 0)
    list(launch(reverse_path(d), src, 1 << 16, 1, importance=importance, device=DEVICE))
"""


def startup(device: str) -> dict:
    """Seconds for a whole process that traces a few rays (both kernels): with an empty
    compiled-code cache (numba compiles and stores the kernels), then with that cache (the
    kernels loaded from it): what compile-once saves."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = os.environ | {"NUMBA_CACHE_DIR": cache}
        code = f"DEVICE = {device!r}\n{STARTUP}"
        for name in ("cold_cache_s", "warm_cache_s"):
            t = time.perf_counter()
            subprocess.run([sys.executable, "-c", code], check=True, env=env)
            out[name] = round(time.perf_counter() - t, 2)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--device", default="auto", choices=("auto", "cpu", "cuda"), help="where to trace"
    )
    ap.add_argument("--search-designs", type=int, default=480, help="designs of the exact search")
    ap.add_argument("--no-report", action="store_true", help="skip the report's timing")
    args = ap.parse_args()
    from opticalstamp.analysis.ghosts import analyse_ghosts
    from opticalstamp.design import load_design
    from opticalstamp.device import resolve_device
    from opticalstamp.raytrace.launch import launch
    from opticalstamp.raytrace.pixel import PixelTracer, pixel_source
    from opticalstamp.raytrace.stack import reverse_path
    from opticalstamp.studies.search import search

    device = resolve_device(args.device)
    out = {"device": device, "device_name": device_name(device), "python": sys.version.split()[0]}
    out["startup"] = startup(args.device)
    print(f"start-up, whole process: {out['startup']}")
    d = load_design("paper2016")
    path, src = reverse_path(d), pixel_source(d, 0, 0)
    n = 1 << (30 if device == "cuda" else 26)
    t = time.perf_counter()
    list(launch(path, src, 1 << 20, 1, importance=False, device=device))
    out["first_call_s"] = time.perf_counter() - t  # compilation (or its cache) included
    t = time.perf_counter()
    chunk = 1 << (24 if device == "cuda" else 21)  # the CPU's default: its caches
    batches = launch(path, src, n, 2, importance=False, chunk=chunk, device=device)
    launched = sum(b.n_launched for b in batches)
    dt = time.perf_counter() - t
    out["plain_trace"] = {"samples": n, "launched": launched, "s": dt, "rays_per_s": launched / dt}
    print(f"{out['device_name']}: plain trace {launched / dt:.3g} launched rays/s")
    if device == "cuda":  # the plain kernels: queued per block (default), per warp, not
        from opticalstamp.raytrace import cuda
        from opticalstamp.raytrace.kernel import seed_key

        n0 = float(path.slabs[0, 1])
        srcv = np.array([src.x, src.y, src.width, src.height, 4 * n0 * n0 * src.area, n0, n0, 0])
        kargs = (
            np.ascontiguousarray(path.slabs), float(path.index_out),
            np.ascontiguousarray(path.masks), path.lattice.as_array(), path.limits,
        )  # fmt: skip
        n_pre, step = path.first_mask_slab + 1, 1 << 26
        for queue in cuda.QUEUES:
            cuda.run(0, step, seed_key(2), srcv, kargs, False, n_pre, None, queue)  # warm-up
            times = []
            for rep in range(5):
                t = time.perf_counter()
                r = cuda.run(rep * step, step, seed_key(2), srcv, kargs, False, n_pre, None, queue)
                cuda.cuda.synchronize()
                times.append(time.perf_counter() - t)
            rate = r.n_launched / float(np.median(times))
            out[f"plain_kernel_queue_{queue}_rays_per_s"] = rate
            print(f"  plain kernel, queue {queue}: {rate:.3g} launched rays/s")
    t = time.perf_counter()
    tracer = PixelTracer(d, device=device)
    g = analyse_ghosts(d, rse_own=1e-4, rse_ghost=1e-3, max_rays=1 << 31, tracer=tracer)
    dt = time.perf_counter() - t
    out["ghosts_precise"] = {"s": dt, "rays": g.n_rays, "ghost_fraction": g.ghost_fraction}
    print(f"ghost analysis to 0.01 % / 0.1 %: {dt:.2f} s ({g.n_rays:,} rays)")
    pop = 32
    gens = max(1, args.search_designs // pop)
    t = time.perf_counter()
    r = search(d, population=pop, generations=gens, estimator="trace", device=device)
    dt = time.perf_counter() - t
    out["exact_search"] = {"designs": len(r.records), "s": dt, "front": len(r.pareto)}
    print(f"search --estimator trace, {len(r.records)} designs: {dt:.1f} s")
    if not args.no_report:
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            subprocess.run(
                [sys.executable, "-c", "from opticalstamp.cli import main; main()",
                 "--device", args.device, "report", "--out", tmp],
                check=True, capture_output=True,
            )  # fmt: skip
            out["report_s"] = time.perf_counter() - t
        print(f"report: {out['report_s']:.1f} s")
    path_out = Path(__file__).with_name(f"bench_gpu_{device}.json")  # one file per device
    path_out.write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {path_out}")


if __name__ == "__main__":
    main()
