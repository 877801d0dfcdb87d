"""docs/api.md's examples run as written (in order, in one namespace), and the top-level
API exposes what it lists, lazily."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import opticalstamp as osp

DOC = Path(__file__).resolve().parents[1] / "docs" / "api.md"


def test_api_examples_run():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    assert len(blocks) >= 4
    namespace: dict = {}
    for i, code in enumerate(blocks):
        exec(compile(code, f"docs/api.md block {i + 1}", "exec"), namespace)  # noqa: S102


def test_every_listed_name_resolves():
    for name in osp.__all__:
        assert getattr(osp, name) is not None, name
    assert "rmtf" in dir(osp)


def test_import_is_cheap():
    """`import opticalstamp` loads no numba, matplotlib or analysis module."""
    code = (
        "import sys, opticalstamp;"
        "bad = [m for m in ('numba', 'matplotlib', 'opticalstamp.analysis.rmtf') "
        "if m in sys.modules]; print(bad)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
