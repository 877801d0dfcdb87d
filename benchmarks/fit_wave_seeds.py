"""The wave fit with the default free set over noise seeds (issue 24; run on demand:
python benchmarks/fit_wave_seeds.py [SEEDS] [--edge-dpi]).

bench_fit.py --wave's case (the prototype with layer 2 shifted 4 um, slab 2 420 um thick
and the light guide 200 um thicker; 5 bar charts at 4800 dpi and 3 slanted edges at 2400
dpi scanned through wave kernels, sensor noise, no ghost light; the default free set, 3
starts, wave optics) with the scans' noise drawn from each seed in turn (bench_fit.py's
is seed 1). Per seed: the seconds and wave runs of the fit, the wave chi2 at the polish's
start and end, what was held, and each estimate's distance from the truth in its stated
errors (None: no error stated). ``--edge-dpi``: the edges' chart resolution given to the
fit (IMAGE:Z_MM:CHART_DPI, its pixels' blur modelled). Writes fit_wave_seeds.json (or
fit_wave_seeds_edge_dpi.json) beside this file.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from opticalstamp.imaging.charts import bar_chart, edge_chart
from opticalstamp.imaging.scan import ScanSettings, prepare_kernels, simulate_scan
from opticalstamp.studies.fit import fit
from opticalstamp.studies.fitdata import observation

# the benchmark's assembly: the same as the scatter's (run from benchmarks/)
from fit_wave_scatter import NOMINAL, TRUE  # noqa: E402  isort: skip

TRUTH = {"layer2.x": 4.0, "slab2": 420.0, "ref": 200.0}
Z_BARS, Z_EDGES = (0.5, 1.5, 2.5, 3.5, 4.5), (0.5, 2.0, 3.5)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("seeds", nargs="?", default="1,2,3,4", help="comma-separated")
    ap.add_argument("--edge-dpi", action="store_true", help="model the edges' chart pixels")
    args = ap.parse_args()
    nominal, true = NOMINAL, TRUE
    st = ScanSettings(kernel="wave")
    charts = (("bars", Z_BARS, bar_chart(4800, supersample=32), 4800.0),
              ("edge", Z_EDGES, edge_chart(2400), 2400.0))  # fmt: skip
    runs = []
    for seed in (int(s) for s in args.seeds.split(",")):
        kc = prepare_kernels(true, z_mm=sorted(set(Z_BARS + Z_EDGES)), ghosts=False,
                             seed=seed, settings=st)  # fmt: skip
        obs = []
        for kind, zs, doc, cdpi in charts:
            for z in zs:
                r = simulate_scan(doc, cdpi, true, z_mm=z, seed=seed, kernels=kc, ghosts=False,
                                  settings=st)  # fmt: skip
                chart = cdpi if (args.edge_dpi and kind == "edge") else None
                obs.append(observation(r.image, r.dpi, z, name=f"{kind}{z}", chart_dpi=chart))
        load = os.getloadavg()[0]
        t = time.perf_counter()
        res = fit(nominal, obs, optics="wave")
        sec = time.perf_counter() - t
        sc = res.optics["scheme"]
        nom = dict(zip(res.names, res.nominal, strict=True))
        z_err = {
            n: None if e is None else round((v - TRUTH.get(n, nom[n])) / e, 2)
            for n, v, e in zip(res.names, res.values, res.errors, strict=True)
        }
        rec = {
            "seed": seed,
            "seconds": round(sec, 1),
            "load": round(load, 2),
            "wave_runs": sc["wave_runs"],
            "wave_chi2": [round(c, 2) for c in sc["wave_chi2"]],
            "held": res.held,
            "held_combinations": res.held_combinations,
            "errors_from_truth": z_err,
            "starts": res.starts,
        }
        print(json.dumps({k: rec[k] for k in ("seed", "seconds", "wave_runs", "wave_chi2")}))
        runs.append(rec)
    name = "fit_wave_seeds_edge_dpi.json" if args.edge_dpi else "fit_wave_seeds.json"
    out = {"truth": TRUTH, "edge_chart_dpi_modelled": args.edge_dpi, "runs": runs}
    Path(__file__).with_name(name).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
