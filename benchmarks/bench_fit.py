"""Speed of `opticalstamp fit` (issue 24; run on demand: python benchmarks/bench_fit.py).

Five bar-chart and three slanted-edge scans (sensor noise, no ghost light; bars drawn at
4800 dpi with 32 samples a pixel, the edge at 2400 dpi) of the prototype assembled with
layer 2 shifted 4 um, slab 2 420 um thick and the light guide 200 um thicker, fitted with
the default free set (every physical parameter) and 3 starts, and with the three
perturbed parameters alone. Wall-clock seconds of the fit (the scans not counted), the
machine's load beside them; the fit runs BLAS on one thread itself (threadpoolctl). Also
the depth of field (paraxial, design's DOF chart) of the truth, the nominal and each fitted
design, and the parameters held at nominal. Writes bench_fit.json.

``--wave``: the same charts scanned through wave kernels (``scan --kernel wave``) and
fitted under wave optics (the prototype's ``--optics auto``; the starts on the
corrected fast model, then the wave model's own geodesic least squares, docs/fit.md),
default free set and three parameters; ``--runs N`` repeats each fit N times (the
median is reported).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np

from opticalstamp.analysis.rmtf import rmtf
from opticalstamp.design import load_design
from opticalstamp.design.variants import replace
from opticalstamp.imaging.charts import bar_chart, edge_chart
from opticalstamp.imaging.scan import ScanSettings, prepare_kernels, simulate_scan
from opticalstamp.studies.fit import fit
from opticalstamp.studies.fitdata import observation

ZS = np.round(np.arange(0.0, 5.01, 0.25), 3)


def _dof(design, optics: str = "ray") -> float:
    """Depth of field on the design's chart, own path: paraxial (ray) or the wave
    engine's light in its band (wave), no ghost light."""
    how = {"method": "paraxial"} if optics == "ray" else {"optics": optics}
    r = rmtf(design, z_mm=ZS, ghosts=False, **how)
    return float(r.dof_mm[r.dof_key])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--wave", action="store_true", help="wave-kernel scans, wave fit")
    ap.add_argument("--runs", type=int, default=1, help="fits of each case (median)")
    ap.add_argument("--only", choices=("default_3starts", "three_params"), default=None)
    args = ap.parse_args()
    optics = "wave" if args.wave else "ray"
    st = ScanSettings(kernel="wave" if args.wave else "auto")
    d = load_design("paper2016")
    true = replace(
        d,
        {
            "slabs.1.mask_top.offset_x_um": 4.0,
            "slabs.1.thickness_um": 420.0,
            "reference_gap.thickness_um": 1200.0,
        },
    )
    zb, ze = (0.5, 1.5, 2.5, 3.5, 4.5), (0.5, 2.0, 3.5)
    kc = prepare_kernels(true, z_mm=sorted(set(zb + ze)), ghosts=False, seed=1, settings=st)
    obs = []
    charts = (
        ("bars", zb, bar_chart(4800, supersample=32), 4800),
        ("edge", ze, edge_chart(2400), 2400),
    )
    for kind, zs, doc, cdpi in charts:
        for z in zs:
            r = simulate_scan(
                doc, cdpi, true, z_mm=z, seed=1, kernels=kc, ghosts=False, settings=st
            )
            obs.append(observation(r.image, r.dpi, z, name=f"{kind}{z}"))
    out = {"load_average": list(os.getloadavg()), "cpus": os.cpu_count(), "images": 8}
    out["optics"] = optics
    out["dof_mm"] = {"truth": _dof(true, optics), "nominal": _dof(d, optics)}
    for key, free, starts in (
        ("default_3starts", None, 3),
        ("three_params", list(("layer2.x", "slab2", "ref")), 1),
    ):
        if args.only and key != args.only:
            continue
        times = []
        for _ in range(max(1, args.runs)):
            t = time.perf_counter()
            res = fit(d, obs, free=free, starts=starts, optics=optics)
            times.append(time.perf_counter() - t)
        scheme = res.optics.get("scheme", {})
        out[key] = {
            "seconds": statistics.median(times),
            "all_seconds": times,
            # the wave fit's path moves with rounding (docs/fit.md): its runs beside its
            # time, and the time over the runs (the starts' fast model included)
            "wave_runs": scheme.get("wave_runs"),
            "seconds_per_wave_run": (
                statistics.median(times) / scheme["wave_runs"] if scheme.get("wave_runs") else None
            ),
            "optics": res.optics,
            "chi2_per_dof": res.chi2 / res.dof,
            "estimates": dict(zip(res.names, res.values, strict=True)),
            "errors": dict(zip(res.names, res.errors, strict=True)),
            "degeneracies": res.degeneracies,
            "held": res.held,
            "chi2_starts": [r["chi2"] for r in res.starts],
            "dof_mm": _dof(res.fitted, optics),
        }
        print(key, round(out[key]["seconds"], 1), "s", out[key]["wave_runs"] or "", "wave runs")
    out["load_average_after"] = list(os.getloadavg())
    path = Path(__file__).with_name("bench_fit_wave.json" if args.wave else "bench_fit.json")
    if args.only and path.exists():  # the other case's figures stay, with their own load
        kept = json.loads(path.read_text())
        other = next(k for k in ("default_3starts", "three_params") if k != args.only)
        if other in kept:
            out[other] = kept[other] | {"load_average": kept.get("load_average")}
    path.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
