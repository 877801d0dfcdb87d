"""Speed of `opticalstamp fit` (issue 24; run on demand: python benchmarks/bench_fit.py).

Five bar-chart and three slanted-edge scans (sensor noise, no ghost light; bars drawn at
4800 dpi with 32 samples a pixel, the edge at 2400 dpi) of the prototype assembled with
layer 2 shifted 4 um, slab 2 420 um thick and the light guide 200 um thicker, fitted with
the default free set (every physical parameter) and 3 starts, and with the three
perturbed parameters alone. Wall-clock seconds of the fit (the scans not counted), the
machine's load beside them; the fit runs BLAS on one thread itself (threadpoolctl). Also
the depth of field (paraxial, design's DOF chart) of the truth, the nominal and each fitted
design, and the parameters held at nominal. Writes bench_fit.json.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from opticalstamp.analysis.rmtf import rmtf
from opticalstamp.design import load_design
from opticalstamp.design.variants import replace
from opticalstamp.imaging.charts import bar_chart, edge_chart
from opticalstamp.imaging.scan import prepare_kernels, simulate_scan
from opticalstamp.studies.fit import fit
from opticalstamp.studies.fitdata import observation

ZS = np.round(np.arange(0.0, 5.01, 0.25), 3)


def _dof(design) -> float:
    r = rmtf(design, z_mm=ZS, method="paraxial", ghosts=False)
    return float(r.dof_mm[r.dof_key])


def main() -> None:
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
    kc = prepare_kernels(true, z_mm=sorted(set(zb + ze)), ghosts=False, seed=1)
    obs = []
    charts = (
        ("bars", zb, bar_chart(4800, supersample=32), 4800),
        ("edge", ze, edge_chart(2400), 2400),
    )
    for kind, zs, doc, cdpi in charts:
        for z in zs:
            r = simulate_scan(doc, cdpi, true, z_mm=z, seed=1, kernels=kc, ghosts=False)
            obs.append(observation(r.image, r.dpi, z, name=f"{kind}{z}"))
    out = {"load_average": list(os.getloadavg()), "cpus": os.cpu_count(), "images": 8}
    out["dof_mm"] = {"truth": _dof(true), "nominal": _dof(d)}
    for key, free, starts in (
        ("default_3starts", None, 3),
        ("three_params", list(("layer2.x", "slab2", "ref")), 1),
    ):
        t = time.perf_counter()
        res = fit(d, obs, free=free, starts=starts)
        out[key] = {
            "seconds": time.perf_counter() - t,
            "chi2_per_dof": res.chi2 / res.dof,
            "estimates": dict(zip(res.names, res.values, strict=True)),
            "errors": dict(zip(res.names, res.errors, strict=True)),
            "degeneracies": res.degeneracies,
            "held": res.held,
            "chi2_starts": [r["chi2"] for r in res.starts],
            "dof_mm": _dof(res.fitted),
        }
        print(key, round(out[key]["seconds"], 1), "s")
    out["load_average_after"] = list(os.getloadavg())
    Path(__file__).with_name("bench_fit.json").write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
