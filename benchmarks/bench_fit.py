"""Speed of `opticalstamp fit` (issue 24; run on demand: python benchmarks/bench_fit.py).

Five bar-chart and three slanted-edge scans (2400-dpi charts, sensor noise, no ghost
light) of the prototype assembled with layer 2 shifted 4 um, slab 2 420 um thick and the
light guide 200 um thicker, fitted with the default free set (every physical parameter)
and 3 starts, and with the three perturbed parameters alone. Wall-clock seconds of the
fit (the scans not counted), the machine's load beside them. OpenBLAS single-threaded
(OPENBLAS_NUM_THREADS=1 unless set), as bench_wave.py: its spinning threads made every
BLAS call several times slower on the shared 2-core machine. Writes bench_fit.json.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from opticalstamp.design import load_design  # noqa: E402
from opticalstamp.design.variants import replace  # noqa: E402
from opticalstamp.imaging.charts import bar_chart, edge_chart  # noqa: E402
from opticalstamp.imaging.scan import prepare_kernels, simulate_scan  # noqa: E402
from opticalstamp.studies.fit import fit  # noqa: E402
from opticalstamp.studies.fitdata import observation  # noqa: E402


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
    for kind, zs, doc in (("bars", zb, bar_chart(2400)), ("edge", ze, edge_chart(2400))):
        for z in zs:
            r = simulate_scan(doc, 2400, true, z_mm=z, seed=1, kernels=kc, ghosts=False)
            obs.append(observation(r.image, r.dpi, z, name=f"{kind}{z}"))
    out = {"load_average": list(os.getloadavg()), "cpus": os.cpu_count(), "images": 8}
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
            "degeneracies": len(res.degeneracies),
        }
        print(key, round(out[key]["seconds"], 1), "s")
    out["load_average_after"] = list(os.getloadavg())
    Path(__file__).with_name("bench_fit.json").write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
