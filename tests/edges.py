"""Shared by the edge tests: run the CLI on bad input and check that it ended cleanly."""

from __future__ import annotations

import math
from pathlib import Path

from typer.testing import CliRunner

from opticalstamp.cli.common import app

runner = CliRunner()


def run(args: list[str]):
    return runner.invoke(app, [str(a) for a in args])


def assert_clean_refusal(res, names: str | tuple[str, ...], folder: Path | None = None, before=()):
    """Exit code 2, a message naming one of ``names``, no traceback, no new file in folder."""
    out = res.output
    assert res.exit_code == 2, f"exit {res.exit_code}: {out}"
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in out
    names = (names,) if isinstance(names, str) else names
    assert any(n in out for n in names), f"none of {names} in: {out}"
    if folder is not None:
        assert sorted(p.name for p in folder.iterdir()) == sorted(before), "a file was written"


def toml_value(v) -> str:
    """A value as TOML (enough for designs: numbers incl. nan/inf, bools, strings, lists,
    inline tables)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def to_toml(d: dict) -> str:
    """A design dict (top-level keys, [sensor], [[slabs]] with [slabs.mask_top],
    [reference_gap]) as TOML text."""
    lines = []
    tables = {k: v for k, v in d.items() if isinstance(v, dict)}
    arrays = {k: v for k, v in d.items() if isinstance(v, list) and v and isinstance(v[0], dict)}
    for k, v in d.items():
        if k not in tables and k not in arrays:
            lines.append(f"{k} = {toml_value(v)}")
    for k, v in tables.items():
        lines.append(f"[{k}]")
        lines += [f"{kk} = {toml_value(vv)}" for kk, vv in v.items()]
    for k, items in arrays.items():
        for item in items:
            lines.append(f"[[{k}]]")
            lines += [f"{kk} = {toml_value(vv)}" for kk, vv in item.items()]
    return "\n".join(lines) + "\n"
