"""Speed of the wave engine (run on demand: python benchmarks/bench_wave.py [--quick]
[--spectral-only]).

1. The separable path: one pixel's responsivity at 19 heights (0-4.5 mm), for the
   prototype, its half-scale 600-dpi copy (plates 500/200/225 um) and the prototype's
   lattice with holes 24/20/20 um over its plates.
2. The RMTF table from the wave engine: rows A and B at 19 heights folded onto the
   design's charts, RMTF curves and depth of field (:func:`wave_folded_lsf`).
3. The ray-against-wave comparison at Z = 0, 1, 2, 3 mm (``opticalstamp wave``): both
   rows by both engines (2^21 rays a row).
4. The 2-D path (exact angular spectrum): the test's small stamp, and the prototype with
   square and with circular holes at a band of 0.1.
5. White light (issue 23, "light as it is": a white phosphor LED times a silicon QE at 7
   wavelengths, :mod:`opticalstamp.analysis.spectrum`): the RMTF table (responsivity of
   rows A and B at 19 heights, the x-only path, 4 charts, depth of field) and one pixel's
   full responsivity (both marginals, centre-cell shares) at 19 heights, for the
   prototype and the 600-dpi copy.
Medians of several runs after a warm-up, wall-clock and CPU seconds; the machine's load
is printed with them (the 2-core test machine is shared: a loaded run is several times
slower). The separable engine runs BLAS on one thread itself (wave.one_blas_thread); the
FFTs use both cores.
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import time
from pathlib import Path

from opticalstamp.analysis.rmtf import rmtf_from_lsf
from opticalstamp.analysis.wave import wave_response
from opticalstamp.analysis.wave2d import wave_response_2d
from opticalstamp.analysis.wavebase import wave_sampling
from opticalstamp.analysis.wavecompare import compare_wave_ray, wave_folded_lsf
from opticalstamp.analysis.wavespectral import wave_response_spectral
from opticalstamp.design import load_design
from opticalstamp.design.resolution import chart_dpis
from opticalstamp.design.variants import scale_to_dpi, with_hole_shape, with_stack
from opticalstamp.units import period_of_dpi

Z19 = tuple(0.25 * i for i in range(19))


def median_time(fn, repeats: int, cpu: list | None = None) -> tuple[float, object]:
    """Median wall-clock seconds of ``repeats`` runs after a warm-up (and their median
    CPU seconds appended to ``cpu``)."""
    fn()
    times, cpus, out = [], [], None
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        times.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    if cpu is not None:
        cpu.append(statistics.median(cpus))
    return statistics.median(times), out


def spectral(out: dict, reps: int) -> None:
    """White light (7 wavelengths): the RMTF table and one pixel's full responsivity at
    19 heights, against the same at the design's one wavelength."""
    for name, d in list(designs().items())[:2]:
        dpis = list(chart_dpis(d))
        pers = [period_of_dpi(x) for x in dpis]
        rec = {}
        for light in ("mono", "white"):
            cpu: list = []
            t, res = median_time(
                lambda d=d, pers=pers, light=light, dpis=dpis: rmtf_from_lsf(
                    wave_folded_lsf(d, Z19, pers, spectrum=light), d, dpi=dpis
                ),
                reps,
                cpu,
            )
            t2, r = median_time(
                lambda d=d, light=light: wave_response_spectral(d, Z19, spectrum=light), 1, cpu
            )
            print(
                f"{name}, {light}: RMTF table {t:.2f} s (CPU {cpu[0]:.2f} s); one pixel's "
                f"full responsivity at 19 heights {t2:.2f} s (CPU {cpu[1]:.2f} s)",
                flush=True,
            )
            rec[light] = {
                "rmtf_table_s": t,
                "rmtf_table_cpu_s": cpu[0],
                "responsivity_19z_s": t2,
                "responsivity_19z_cpu_s": cpu[1],
                "wave_dof_mm": res.dof_mm,
                "wavelengths_um": list(r.spectrum.wavelengths_um),
                "weights": list(r.spectrum.weights),
                "light_um2sr": float(r.etendue_um2sr[0]),
            }
        out[f"{name} spectral"] = rec


def designs() -> dict:
    d = load_design("paper2016")
    return {
        "paper2016": d,
        "600 dpi copy": with_stack(scale_to_dpi(d, 600), thicknesses_um=(500, 200, 225)),
        "holes 24/20/20": with_stack(d, holes_um=(24, 20, 20)),
    }


def small():
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_wave import _stack

    return _stack((10.0, 10.0, 12.0))


if __name__ == "__main__":
    quick = "--quick" in sys.argv
    reps = 1 if quick else 3
    out = {
        "load_average": os.getloadavg(),
        "cpus": os.cpu_count(),
    }
    spectral(out, reps)
    if "--spectral-only" in sys.argv:  # update the white-light entries of the results
        path = Path(__file__).with_name("bench_wave.json")
        old = json.loads(path.read_text()) if path.exists() else {}
        keys = [k for k in out if k.endswith(" spectral")]
        old.update({k: out[k] for k in keys})
        old["spectral_load_average"] = [out["load_average"], os.getloadavg()]
        path.write_text(json.dumps(old, indent=1, default=str))
        sys.exit(0)
    for name, d in designs().items():
        t, r = median_time(lambda d=d: wave_response(d, Z19), reps)
        print(f"{name}: responsivity at 19 heights, one pixel: {t:.2f} s", flush=True)
        pers = [period_of_dpi(x) for x in chart_dpis(d)]
        t2, res = median_time(
            lambda d=d, pers=pers: rmtf_from_lsf(
                wave_folded_lsf(d, Z19, pers), d, dpi=list(chart_dpis(d))
            ),
            reps,
        )
        print(f"  RMTF table ({len(pers)} charts x 19 Z, rows A and B): {t2:.2f} s", flush=True)
        t3, c = median_time(lambda d=d: compare_wave_ray(d, (0, 1, 2, 3)), 1 if quick else 2)
        print(f"  ray vs wave at 4 heights: {t3:.2f} s", flush=True)
        out[name] = {
            "responsivity_19z_s": t,
            "rmtf_table_s": t2,
            "compare_4z_s": t3,
            "wave_dof_mm": res.dof_mm,
            "sampling": r.sampling.__dict__,
        }
    d = small()
    smp = wave_sampling(d, band=0.2).refined(margin=0.5)
    t, r = median_time(lambda: wave_response_2d(d, (0.05,), sampling=smp), reps)
    print(f"2-D path, small stamp (grid {r.meta['grid']}, {r.meta['modes']} modes): {t:.2f} s")
    out["2d small"] = {"s": t, "meta": {k: str(v) for k, v in r.meta.items()}}
    if not quick:
        p = load_design("paper2016")
        for name, dd in (("square", p), ("circle", with_hole_shape(p, "circle"))):
            smp = wave_sampling(dd, band=0.1).refined(margin=0.5)
            t0 = time.perf_counter()
            r = wave_response_2d(dd, (0.0, 1.0, 2.0), sampling=smp)
            t = time.perf_counter() - t0
            print(
                f"2-D path, prototype {name} holes, band 0.1, 3 heights (grid {r.meta['grid']}, "
                f"{r.meta['modes']} modes): {t:.1f} s; light {r.etendue_um2sr[0]:.4f} um^2 sr"
            )
            out[f"2d prototype {name}"] = {"s": t, "light": float(r.etendue_um2sr[0])}
    out["load_average_after"] = os.getloadavg()
    Path(__file__).with_name("bench_wave.json").write_text(json.dumps(out, indent=1, default=str))
