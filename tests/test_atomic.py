"""Output sets are atomic as sets: a run killed at any point leaves the old complete set
or the new complete set (after the next run's recovery), and no temporary files."""

from __future__ import annotations

import hashlib
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from opticalstamp.io.atomic import recover, replace_folder, verify_set, write_atomic, write_set
from opticalstamp.io.files import write_png


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_write_set_verifies_and_detects_a_mixed_set(tmp_path):
    m = write_set({tmp_path / "a.png": b"A1", tmp_path / "a.tif": b"T1"}, tmp_path / "a.json", {})
    assert verify_set(m)
    (tmp_path / "a.tif").write_bytes(b"T2")  # a member that is not the manifest's
    assert not verify_set(m)
    assert not verify_set(tmp_path / "missing.json")
    assert _leftovers(tmp_path) == []


def test_write_atomic_keeps_mode_and_leaves_nothing(tmp_path):
    p = write_atomic(tmp_path / "sub" / "x.txt", "hello")
    assert p.read_text() == "hello"
    assert p.stat().st_mode & 0o777 == 0o666 & ~_umask()
    assert _leftovers(p.parent) == []


def _umask() -> int:
    u = os.umask(0)
    os.umask(u)
    return u


# -- deterministic crash points: a child process dies (os._exit) at the k-th step -------
_CHILD = textwrap.dedent(
    """
    import os, sys
    from pathlib import Path
    import opticalstamp.io.atomic as at
    mode, k, folder, content = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3]), sys.argv[4]
    steps = {"n": 0}
    def step(real):
        def wrapped(*a, **kw):
            if steps["n"] == k:
                os._exit(9)
            steps["n"] += 1
            return real(*a, **kw)
        return wrapped
    at.os.replace = step(os.replace)
    at._write_synced = step(at._write_synced)
    if mode == "set":
        members = {folder / "s.png": content + "P", folder / "s.tif": content + "T"}
        at.write_set(members, folder / "s.json", {"content": content})
    else:
        with at.replace_folder(folder / "rep") as tmp:
            for name in ("a.png", "b.png", "report.json"):
                (tmp / name).write_text(content + name)
    """
)


def _crash(mode: str, k: int, folder: Path, content: str) -> int:
    return subprocess.run(
        [sys.executable, "-c", _CHILD, mode, str(k), str(folder), content], check=False
    ).returncode


@pytest.mark.parametrize("k", range(7))
def test_file_set_killed_at_every_step_is_old_or_new(tmp_path, k):
    assert _crash("set", 99, tmp_path, "old") == 0
    old = {n: _digest(tmp_path / n) for n in ("s.png", "s.tif", "s.json")}
    rc = _crash("set", k, tmp_path, "new")
    recover(tmp_path)  # what the next run over this output does first
    assert _leftovers(tmp_path) == []
    now = {n: _digest(tmp_path / n) for n in ("s.png", "s.tif", "s.json")}
    assert verify_set(tmp_path / "s.json")
    if rc == 0:
        assert now != old and (tmp_path / "s.png").read_text() == "newP"
    else:
        assert now == old or (tmp_path / "s.png").read_text() == "newP"
    if now != old:
        assert (tmp_path / "s.tif").read_text() == "newT"


@pytest.mark.parametrize("k", range(4))
def test_folder_killed_at_every_step_is_old_or_new(tmp_path, k):
    assert _crash("folder", 99, tmp_path, "old") == 0
    _crash("folder", k, tmp_path, "new")
    recover(tmp_path)
    assert _leftovers(tmp_path) == []
    texts = {p.read_text() for p in (tmp_path / "rep").iterdir()}
    assert texts in (
        {"olda.png", "oldb.png", "oldreport.json"},
        {"newa.png", "newb.png", "newreport.json"},
    )


def test_failed_folder_write_keeps_the_old_one(tmp_path):
    with replace_folder(tmp_path / "rep") as tmp:
        (tmp / "report.json").write_text("old")
    with pytest.raises(RuntimeError), replace_folder(tmp_path / "rep") as tmp:
        (tmp / "report.json").write_text("new")
        raise RuntimeError("analysis failed")
    assert (tmp_path / "rep" / "report.json").read_text() == "old"
    assert _leftovers(tmp_path) == []


def test_recover_leaves_live_writers_alone(tmp_path):
    live = tmp_path / f".x.png.{os.getpid()}-0123abcd.tmp"
    live.write_text("in progress")
    dead = tmp_path / ".x.png.999999999-0123abcd.tmp"  # no such PID
    dead.write_text("stale")
    recover(tmp_path)
    assert live.exists() and not dead.exists()


# -- a real kill: `opticalstamp scan` killed with SIGKILL at random moments --------------
def test_scan_killed_at_random_points(tmp_path):
    doc = np.ones((300, 600))
    doc[100:200, ::20] = 0.0
    write_png(tmp_path / "doc.png", doc, 1200.0)
    out = tmp_path / "out"
    out.mkdir()
    cmd = [str(Path(sys.executable).parent / "opticalstamp"), "scan", str(tmp_path / "doc.png")]
    cmd += ["-o", str(out / "s.png"), "--z", "1"]
    env = dict(os.environ, PYTHONWARNINGS="ignore")

    def scan(seed: int) -> float:
        t0 = time.perf_counter()
        subprocess.run([*cmd, "--seed", str(seed)], check=True, env=env, capture_output=True)
        return time.perf_counter() - t0

    scan(1)
    new = _digest(out / "s.png")
    span = scan(0)
    old = _digest(out / "s.png")
    assert old != new
    rng = random.Random(0)
    seen = set()
    for i in range(6):
        p = subprocess.Popen(
            [*cmd, "--seed", "1"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        time.sleep(rng.uniform(0.3, 1.1) * span)
        p.send_signal(signal.SIGKILL)
        p.wait()
        recover(out)
        assert _leftovers(out) == []
        assert verify_set(out / "s.json"), f"kill {i}: the set on disk is not one set"
        got = _digest(out / "s.png")
        assert got in (old, new)
        seen.add(got)
        if got == new:  # back to the old set for the next kill
            subprocess.run([*cmd, "--seed", "0"], check=True, env=env, capture_output=True)
