"""Test options: ``--runslow`` runs the tests marked ``slow`` (skipped by default).

The CLI's click command built once per state of the Typer app, not at every
``CliRunner().invoke``: typer rebuilds it from the ~30 commands' signatures each time
(0.23 of 0.29 s per invocation of a refused command, measured), and the suite invokes
the CLI over a thousand times (the fuzz tests 600)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import typer.testing

sys.path.insert(0, str(Path(__file__).parent))  # the shared helpers (helpers.py, edges.py)


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


def pytest_collection_modifyitems(config, items):
    if config.getoption("--runslow"):
        return
    skip = pytest.mark.skip(reason="slow: run with --runslow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
