"""Cost of the tolerance study by wave optics (run on demand, not in the test suite)::

    python benchmarks/bench_tolerance_optics.py [--samples 1000] [--errors 6]
        [--studies] [--full-wave-studies] [--skip-cli]

1. ``opticalstamp tolerance --samples N --optics ray`` and ``--optics wave`` on the
   prototype (the default ``auto`` picks wave for it), each in a fresh process as a user
   runs it on every core, timed whole (wall and CPU seconds of the process and its
   workers).
2. The wave estimator (the search's, :func:`~opticalstamp.studies.waveestimate.evaluate_wave`)
   against the exact wave figures on ``--errors`` perturbed samples of the prototype
   (the tolerance study's own draws, seed 0): its error on tolerance samples, beside the
   stated accuracy ``WAVE_ACCURACY``; and each evaluation's time.
3. ``--studies``: the report's background search and tolerance study
   (:func:`~opticalstamp.report.studies.run_search`, ``run_tolerance``) timed one after
   the other in this process on one numba thread (as in the report's background
   processes): by ray optics with the report's budget, by wave optics with the wave
   budget (:func:`~opticalstamp.report.studies.study_budget`); ``--full-wave-studies``
   also by wave optics with the ray budget.

Written as JSON to benchmarks/bench_tolerance_optics.json with the load average before each
run (other work on the 2-core machine slows every wall time here).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def _cpu_children() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _cpu_self() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def cli_run(samples: int, optics: str) -> dict:
    exe = Path(sys.executable).with_name("opticalstamp")
    args = [str(exe), "tolerance", "--samples", str(samples), "--optics", optics, "--json"]
    args += ["--spec", "dof>=2"]
    load = os.getloadavg()[0]
    c0 = _cpu_children()
    t = time.perf_counter()
    res = subprocess.run(args, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if res.returncode != 0:
        raise SystemExit(f"tolerance --optics {optics} failed: {res.stderr[-2000:]}")
    data = json.loads(res.stdout)
    out = {
        "command": "opticalstamp " + " ".join(args[1:]),
        "wall_s": wall,
        "cpu_s": _cpu_children() - c0,
        "load_before": load,
        "optics": data["meta"]["optics"]["engine"],
        "estimator": data["meta"]["estimator"],
        "n_failed": data["n_failed"],
        "dof_mm": data["dof_mm"],
        "efficiency_ratio": data["efficiency_ratio"],
        "ghost_fraction": data["ghost_fraction"],
        "yield": data["yield"],
        "nominal_dof_mm": data["nominal"]["dof_mm"],
        "nominal_exact_dof_mm": (data["meta"].get("nominal_exact") or {}).get("dof_mm"),
        "nominal_disagrees": data["meta"].get("nominal_disagrees"),
    }
    print(
        f"tolerance --samples {samples} --optics {optics}: {wall:.1f} s wall, "
        f"{out['cpu_s']:.1f} CPU-s (load {load:.1f}); DOF median {data['dof_mm']['p50']:.2f} mm",
        flush=True,
    )
    return out


def estimator_errors(n: int) -> dict:
    from opticalstamp.design import load_design
    from opticalstamp.studies.tolerance import DEFAULT_SIGMAS, apply_errors, draw_errors
    from opticalstamp.studies.waveestimate import (
        WAVE_ACCURACY,
        evaluate_wave,
        exact_wave_figures,
        wave_errors,
    )

    d = load_design("paper2016")
    zs = (0.5, 1.0, 2.0, 3.0, 3.5)
    rows, t_est, t_ex = [], [], []
    for i in range(n):
        di = apply_errors(d, draw_errors(d, i, 0, dict(DEFAULT_SIGMAS)))
        t = time.perf_counter()
        est = evaluate_wave(di, dpi=200.0, rmtf_z_mm=zs, ghost_rays=1 << 16, seed=0)
        t_est.append(time.perf_counter() - t)
        t = time.perf_counter()
        ex = exact_wave_figures(di, dpi=200.0, rmtf_z_mm=zs, seed=0)
        t_ex.append(time.perf_counter() - t)
        rows.append(wave_errors(est, ex) | {"ghost_fraction_exact": ex["ghost_fraction"]})
    worst = {k: max(r[k] for r in rows) for k in ("dof_mm", "rmtf", "efficiency_ratio")}
    worst["ghost_fraction"] = max(r["ghost_fraction"] for r in rows)
    print(f"wave estimator on {n} tolerance samples: largest errors {worst}", flush=True)
    return {
        "samples": rows,
        "largest": worst,
        "stated_accuracy": dict(WAVE_ACCURACY),
        "estimate_s": t_est,
        "exact_s": t_ex,
    }


def study_runs(full: bool) -> dict:
    import numba

    from opticalstamp.analysis.responsivity import RAY, resolve_optics
    from opticalstamp.design import load_design
    from opticalstamp.report.studies import run_search, run_tolerance, study_budget
    from opticalstamp.report.work import StudyBudget

    numba.set_num_threads(1)
    d = load_design("paper2016")
    wave = resolve_optics(d, "wave")
    cases = [("ray", RAY, study_budget(StudyBudget(), RAY))]
    cases.append(("wave", wave, study_budget(StudyBudget(), wave)))
    if full:
        cases.append(("wave_ray_budget", wave, StudyBudget()))
    out = {}
    for name, opt, budget in cases:
        row = {"budget": budget.__dict__}
        for job, fn, args in (
            ("search", run_search, (d, 0, 200.0, budget, opt.engine)),
            ("tolerance", run_tolerance, (d, 0, 200.0, None, budget, opt)),
        ):
            load = os.getloadavg()[0]
            c0 = _cpu_self()
            t = time.perf_counter()
            res = fn(*args)
            row[job] = {
                "wall_s": time.perf_counter() - t,
                "cpu_s": _cpu_self() - c0,
                "load_before": load,
            }
            if job == "tolerance":
                row[job]["dof_mm"] = res.to_dict()["dof_mm"]
            else:
                row[job]["front"] = len(res.pareto)
                row[job]["optics_used"] = res.meta["optics_used"]
            print(f"report {job} by {name}: {row[job]['wall_s']:.1f} s", flush=True)
        out[name] = row
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=1000)
    ap.add_argument("--errors", type=int, default=6)
    ap.add_argument("--studies", action="store_true")
    ap.add_argument("--full-wave-studies", action="store_true")
    ap.add_argument("--skip-cli", action="store_true")
    args = ap.parse_args(argv)
    path = Path(__file__).with_suffix(".json")
    doc = json.loads(path.read_text()) if path.exists() else {}
    doc["cores"] = os.cpu_count()
    doc["date_utc"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    if not args.skip_cli:
        doc["cli"] = {o: cli_run(args.samples, o) for o in ("ray", "wave")}
        r, w = doc["cli"]["ray"], doc["cli"]["wave"]
        doc["cli"]["wave_over_ray_wall"] = w["wall_s"] / r["wall_s"]
    if args.errors:
        doc["wave_estimator_on_samples"] = estimator_errors(args.errors)
    if args.studies or args.full_wave_studies:
        doc["report_studies"] = study_runs(args.full_wave_studies)
    path.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
