"""Speed of the wave engine's 2-D path on circular holes (issue 23: "a circular-hole
design: <= 2 min, and on the GPU <= 2 s"); run on demand:

    python benchmarks/bench_wave_circle.py [--device cpu|cuda] [--band B] [--reps N]
        [--white-reps N] [--lights mono,white] [--warmup 1|0]

The prototype with circular holes (:func:`~opticalstamp.design.variants.with_hole_shape`):
the RMTF table (rows A and B at 19 heights, 0-4.5 mm, folded onto the design's charts,
RMTF curves and depth of field; row B is row A's mirror twin), with the design's one
wavelength and with white light (7 wavelengths), through the 2-D path
(:func:`~opticalstamp.analysis.wave2dlsf.lsf_source_2d`) on the device named. Medians of
``--reps`` runs after a warm-up; the machine's load and the stack's figures (grid,
range, modes) are printed with them. Results: bench_wave_circle.json (per device).
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import time
from pathlib import Path

from opticalstamp.analysis.arrays import backend
from opticalstamp.analysis.rmtf import rmtf_from_lsf
from opticalstamp.analysis.wave import lsf_source
from opticalstamp.analysis.wavebase import wave_sampling
from opticalstamp.analysis.wavecompare import wave_folded_lsf
from opticalstamp.design import load_design
from opticalstamp.design.resolution import chart_dpis
from opticalstamp.design.variants import with_hole_shape
from opticalstamp.device import using_device
from opticalstamp.units import period_of_dpi

Z19 = tuple(0.25 * i for i in range(19))


def _arg(name: str, default: str) -> str:
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def timed(fn, reps: int, bk, warmup: bool = True) -> tuple[float, list[float], object, list[float]]:
    """Median wall-clock seconds of ``reps`` runs after a warm-up (``warmup``), all the
    times, the last result and each run's CPU seconds (this process, every thread)."""
    out = fn() if warmup else None
    times, cpu = [], []
    for _ in range(reps):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        bk.sync()
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    return statistics.median(times), times, out, cpu


def main() -> None:
    device = _arg("--device", "cpu")
    reps = int(_arg("--reps", "3"))
    white_reps = int(_arg("--white-reps", str(reps)))
    band = _arg("--band", "")
    lights = _arg("--lights", "mono,white").split(",")
    warmup = _arg("--warmup", "1") == "1"
    bk = backend(device)
    d = with_hole_shape(load_design("paper2016"), "circle")
    smp = wave_sampling(d, band=float(band) if band else None)
    dpis = list(chart_dpis(d))
    pers = [period_of_dpi(x) for x in dpis]
    out: dict = {"device": device, "load_average": os.getloadavg(), "cpus": os.cpu_count()}
    out["sampling"] = smp.__dict__
    with using_device(device):
        src = lsf_source(d, max(Z19), sampling=smp)
        out["stack"] = {k: v for k, v in src.meta.items() if k != "note"}
        print(f"circles, {device}: stack {out['stack']}", flush=True)
        for light in lights:
            t, times, res, cpu = timed(
                lambda light=light: rmtf_from_lsf(
                    wave_folded_lsf(d, Z19, pers, sampling=smp, spectrum=light), d, dpi=dpis
                ),
                white_reps if light == "white" else reps,
                bk,
                warmup,
            )
            print(
                f"circles, {device}, {light}: RMTF table (19 Z, rows A and B, {len(pers)} "
                f"charts) {t:.2f} s (runs {', '.join(f'{x:.2f}' for x in times)}; CPU "
                f"{', '.join(f'{x:.1f}' for x in cpu)} s); "
                f"DOF {res.dof_mm} mm",
                flush=True,
            )
            out[light] = {"rmtf_table_s": t, "runs_s": times, "cpu_s": cpu, "dof_mm": res.dof_mm}
    out["load_average_after"] = os.getloadavg()
    path = Path(__file__).with_name("bench_wave_circle.json")
    old = json.loads(path.read_text()) if path.exists() else {}
    old[device + (f" band {band}" if band else "")] = out
    path.write_text(json.dumps(old, indent=1, default=str))


if __name__ == "__main__":
    main()
