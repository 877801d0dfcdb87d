"""Wall time of whole `opticalstamp` processes: the report, the quick report, --help and the
ghost analysis at its default precision.

Run on demand (not in the test suite)::

    python benchmarks/bench_report.py [--runs 3] [--out results.json]

Each command runs ``--runs`` times in a fresh process, as a user starts it (imports, numba's
cached kernels, process pools and the writing of every file included); the median wall
time is reported, and the CPU time (user + system) of the process and every process it
started (the report's background studies, Tesseract), which other work on a shared
machine changes far less than the wall time. The report's own section times (report.json
``section_elapsed_s``) of its median run are kept too, and each background study's
wall and CPU seconds in its process (``study_elapsed_s``), and the load average before each
run, since other work on the machine slows every wall time here. Prints a table and,
with ``--out``, writes it as JSON with provenance (version, git commit, Python, numba,
cores, date). ``--interleave`` runs the commands in turn, one run of each per round, so
that the commands compared (the report by ray and by wave optics) see the same load.

benchmarks/bench_report.json holds a measurement before and after the report's work was
arranged to compute nothing twice (report: 51.8 s -> 31.6 s on the 2-core machine). A
later change (numba alias tables, Tesseract on one thread, chunks of rays traced once per
tracer, the parameter study in two parts on two background processes, one numba thread
here while they run) took the report from 32.6 s and 62 CPU-s to about 23.3 s and 46 CPU-s
on the same machine, every number of report.json unchanged.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: name -> arguments after `opticalstamp` ({out}: a fresh output folder)
COMMANDS = {
    "report": ["report", "--out", "{out}"],
    "report-ray": ["report", "--optics", "ray", "--out", "{out}"],
    "report-quick": ["report", "--quick", "--out", "{out}"],
    "report-quick-ray": ["report", "--quick", "--optics", "ray", "--out", "{out}"],
    "help": ["--help"],
    "ghosts": ["ghosts"],
}


def _exe() -> str:
    """The `opticalstamp` script of this interpreter's environment."""
    here = Path(sys.executable).with_name("opticalstamp")
    return str(here) if here.exists() else (shutil.which("opticalstamp") or "opticalstamp")


def run_once(args: list[str], tmp: Path) -> dict:
    out = tmp / "out"
    shutil.rmtree(out, ignore_errors=True)
    cmd = [_exe()] + [a.replace("{out}", str(out)) for a in args]
    load = os.getloadavg()[0]
    c0 = _children_cpu_s()
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    run = {"s": time.perf_counter() - t, "cpu_s": _children_cpu_s() - c0, "load_before": load}
    rep = out / "report.json"
    if rep.exists():
        d = json.loads(rep.read_text())
        run["sections_s"] = d.get("section_elapsed_s")
        run["studies_s"] = d.get("study_elapsed_s")  # each background study: wall, CPU
        run["report_elapsed_s"] = d.get("elapsed_s")
    return run


def _children_cpu_s() -> float:
    """User + system CPU seconds of the finished child processes (and their children)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _git(*args: str) -> str | None:
    try:
        res = subprocess.run(["git", *args], capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return None
    return res.stdout.strip()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3, help="runs per command (median)")
    ap.add_argument("--out", type=Path, help="write the results as JSON here")
    ap.add_argument("--only", nargs="*", choices=list(COMMANDS), help="these commands only")
    ap.add_argument(
        "--interleave",
        action="store_true",
        help="run the commands in turn, one run of each per round (so that each sees the "
        "same load on a shared machine), instead of all runs of one command, then the next",
    )
    args = ap.parse_args(argv)
    results = {}
    names = [n for n in COMMANDS if not args.only or n in args.only]
    with tempfile.TemporaryDirectory() as tmp:
        all_runs: dict[str, list[dict]] = {n: [] for n in names}
        if args.interleave:
            for _ in range(args.runs):
                for name in names:
                    all_runs[name].append(run_once(COMMANDS[name], Path(tmp)))
        for name, cmd in COMMANDS.items():
            if name not in names:
                continue
            runs = all_runs[name] or [run_once(cmd, Path(tmp)) for _ in range(args.runs)]
            times = [r["s"] for r in runs]
            cpu = [r["cpu_s"] for r in runs]
            median = sorted(runs, key=lambda r: r["s"])[len(runs) // 2]
            results[name] = {
                "median_s": statistics.median(times),
                "runs_s": times,
                "median_cpu_s": statistics.median(cpu),
                "runs_cpu_s": cpu,
                "load_before": [r["load_before"] for r in runs],
                "sections_s_of_median_run": median.get("sections_s"),
                "studies_s_of_median_run": median.get("studies_s"),
            }
            print(
                f"{name:16s} median {statistics.median(times):6.2f} s"
                f" ({statistics.median(cpu):6.2f} CPU-s)   runs "
                + ", ".join(f"{t:.2f}" for t in times)
            )
    if args.out:
        import numba

        import opticalstamp as osp

        doc = {
            "what": "wall and CPU time of whole opticalstamp processes (median of runs)",
            "provenance": {
                "opticalstamp_version": osp.__version__,
                "git_commit": _git("rev-parse", "HEAD"),
                "git_src_dirty": bool(_git("status", "--porcelain", "--", "src")),
                "python": platform.python_version(),
                "numba": numba.__version__,
                "platform": platform.platform(),
                "cpu_count": os.cpu_count(),
                "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "runs": args.runs,
                "interleaved": args.interleave,
            },
            "commands": {k: " ".join(["opticalstamp", *v]) for k, v in COMMANDS.items()},
            "results": results,
        }
        args.out.write_text(json.dumps(doc, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
