"""Test options: ``--runslow`` runs the tests marked ``slow`` (skipped by default).

The CLI's click command built once per state of the Typer app, not at every
``CliRunner().invoke``: typer rebuilds it from the ~30 commands' signatures each time
(0.23 of 0.29 s per invocation of a refused command, measured), and the suite invokes
the CLI over a thousand times (the fuzz tests 600)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
import typer.testing

sys.path.insert(0, str(Path(__file__).parent))  # the shared helpers (helpers.py, edges.py)

#: one thread per pytest-xdist worker (numba's parallel loops, OpenMP, OpenBLAS), set
#: before numpy and numba load in the worker and inherited by its subprocesses: two
#: workers on two cores, each with two threads, lost a tenth of the run to threads that
#: spin while they wait (libgomp's and OpenBLAS's; measured: 471 s and 905 CPU-s, 423 s
#: and 804 CPU-s with one). Tests that need more threads ask for them in a process of
#: their own (tests/test_sampling.py)
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ.setdefault(_var, "1")


def _registered(app) -> tuple:
    """What typer builds the command from: the app's callback, commands and groups (each
    group's own, recursively), by identity."""
    groups = tuple((id(g), _registered(g.typer_instance)) for g in app.registered_groups)
    commands = tuple(id(c) for c in app.registered_commands)
    return (id(app.registered_callback), id(app.info.callback), commands, groups)


def _built_once(build):
    built: dict = {}

    def get_command(app):
        key = (id(app), _registered(app))
        if key not in built:
            built[key] = (app, build(app))  # the app kept alive: its id stays its own
        return built[key][1]

    return get_command


typer.testing._get_command = _built_once(typer.testing._get_command)


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", help="also run tests marked slow")


#: the test files that take longest (about the seconds of their tests on 2 cores: the
#: sum of their tests' durations), longest first: under ``-n 2 --dist loadfile`` (scripts/test.sh)
#: they go to the workers first and the many short files fill in behind them. xdist's
#: own order (files by their number of tests, most first) sent these files of a few long
#: tests last, one of them alone on a worker at the end while the other had finished
HEAVY_FILES = (
    "test_report_presets.py",  # 92 s (2026-11-26, one thread a worker)
    "test_report.py",  # 50
    "test_fit_wave.py",  # 48
    "test_cuda.py",  # 45
    "test_search.py",  # 40
    "test_wave_circle_maps.py",  # 26
    "test_fit.py",  # 26
    "test_rgb_report.py",  # 24
    "test_tolerance_optics.py",  # 23
    "test_reciprocity.py",  # 23
    "test_compare.py",  # 20
    "test_report_speed_paths.py",  # 20
    "test_atomic.py",  # 19
    "test_wave_circle.py",  # 18
    "test_restore.py",  # 16
    "test_wave_fresnel.py",  # 14
    "test_compare_optics.py",  # 14
    "test_search_wave.py",  # 13
    "test_rodlens.py",  # 12
    "test_wave_checks.py",  # 11
    "test_report_sections.py",  # 11
)


def pytest_sessionstart(session):
    """With workers (pytest-xdist's controller, before it starts them): numba's CPU
    kernels compiled into their caches once, in two processes side by side
    (tests/warm_numba.py), where in a fresh clone each worker and each background
    process that reaches a kernel first would compile it again (a fresh clone's suite: 438
    -> 401 s; about 23 s here, 2.5 s where the caches are warm). A failure here is only
    reported: the tests that use the kernel show it."""
    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    import subprocess

    script = str(Path(__file__).with_name("warm_numba.py"))
    runs = {
        part: subprocess.Popen([sys.executable, script, part], stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True)
        for part in ("rays", "rest")
    }  # fmt: skip
    for part, p in runs.items():
        _, err = p.communicate()
        if p.returncode:
            print(f"warm_numba.py {part} failed: {err.strip().splitlines()[-1:]}")


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config):
    # under --dist loadfile the controller hands out the files in the order the workers
    # collected them (pytest_collection_modifyitems below), not re-sorted by their
    # number of tests
    if getattr(config.option, "dist", "no") == "loadfile":
        config.option.loadscopereorder = False


def _heavy_first(items) -> None:
    rank = {name: i for i, name in enumerate(HEAVY_FILES)}
    order = {}  # the files in collection order, each at its first test
    for item in items:
        order.setdefault(item.path, len(order))
    key = {p: (rank.get(p.name, len(rank)), i) for p, i in order.items()}
    items.sort(key=lambda item: key[item.path])  # stable: a file's tests keep their order


def pytest_collection_modifyitems(config, items):
    if hasattr(config, "workerinput"):  # a pytest-xdist worker (its dist reads "no")
        _heavy_first(items)
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
