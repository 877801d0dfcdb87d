"""The wave fit's polish, evaluation by evaluation (issue 24; run on demand).

Runs ``bench_fit.py --wave --only default_3starts`` with the polish's least squares
(:func:`opticalstamp.studies.fitlm.geodesic_lm`, as :mod:`opticalstamp.studies.fit` calls
it) wrapped so that each evaluation of the residuals logs its sum of squares (the wave
chi2) and the seconds since the polish began, and each Jacobian its time: how many wave
runs the polish spends to come within 100, 20, 5, 2, 1 and 0.3 of its end. Writes
``fit_wave_trajectory.json`` (``--out``): the log, and the runs to each mark. The path
along the default free set's valley turns on bits (docs/fit.md, "A wave run of the
marginals alone"): compare codes by their marks, from the same charts, on one machine.
"""

from __future__ import annotations

import argparse
import json
import runpy
import sys
import time
from pathlib import Path

import opticalstamp.studies.fit as fit_module

#: wave runs of one full Jacobian of the default free set (one a physical parameter)
PHYSICAL = 15


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(Path(__file__).with_name("fit_wave_trajectory.json")))
    args = ap.parse_args()
    log: list = []
    plain = fit_module.geodesic_lm

    def logged(fun, x0, jac, *rest, **kw):
        t0 = time.perf_counter()

        def f(x):
            r = fun(x)
            log.append(["f", float(r @ r), time.perf_counter() - t0])
            return r

        def j(x):
            out = jac(x)
            log.append(["J", None, time.perf_counter() - t0])
            return out

        res = plain(f, x0, j, *rest, **kw)
        log.append(["end", res.message, time.perf_counter() - t0])
        return res

    fit_module.geodesic_lm = logged  # this script's run only
    sys.argv = ["bench_fit.py", "--wave", "--only", "default_3starts"]
    runpy.run_path(str(Path(__file__).with_name("bench_fit.py")), run_name="__main__")
    chis = [c for k, c, _ in log if k == "f"]
    end = min(chis) if chis else float("nan")
    marks, evals, jacs, best = {}, 0, 0, float("inf")
    for kind, c, t in log:
        evals += kind == "f"
        jacs += kind == "J"
        if kind == "f":
            best = min(best, c)
        for above in (100, 20, 5, 2, 1, 0.3):
            if best <= end + above and str(above) not in marks:
                runs = evals + PHYSICAL * jacs
                marks[str(above)] = {"evaluations": evals, "jacobians": jacs, "wave_runs": runs}
                marks[str(above)]["seconds"] = t
    out = {"end_chi2": end, "within_of_end": marks, "log": log}
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
