"""The study journal: unreadable lines, appends after a truncated line, the run lock."""

import subprocess
import sys
import warnings

import pytest

from opticalstamp.io.journal import JournalLocked, JournalWarning, journal_lock, read_journal
from opticalstamp.studies.runner import run_tasks, task_key
from opticalstamp.validate import InputError

TASKS = [(task_key({"v": v}), {"v": v}) for v in range(4)]


def _square(p: dict) -> dict:
    return {"y": p["v"] ** 2}


def _run(journal, fn=_square, tasks=TASKS, lock=True):
    """One run in this process; returns (records, payloads evaluated)."""
    calls = []
    out = run_tasks(
        lambda p: calls.append(p) or fn(p), tasks, workers=1, journal=journal, lock=lock
    )
    return out, calls


def _quiet_run(journal, **kw):
    """A run that must not warn (a JournalWarning here is an error)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", JournalWarning)
        return _run(journal, **kw)


def test_lines_that_are_json_but_not_records_are_skipped_with_one_warning(tmp_path):
    j = tmp_path / "j.jsonl"
    _run(j, tasks=TASKS[:2])
    good = j.read_text()
    no_result = '{"key": "k1", "payload": {}, "ok": true, "attempts": 1}'
    bad_key = '{"key": 7, "payload": {}, "ok": true, "result": {}, "attempts": 1}'
    bad_ok = '{"key": "k2", "payload": {}, "ok": "yes", "result": {}, "attempts": 1}'
    bad_err = '{"key": "k3", "payload": {}, "ok": false, "error": 3, "attempts": 1}'
    junk = ["{}", "null", "[1, 2]", '"text"', "42", no_result, bad_key, bad_ok, bad_err]
    j.write_text(good + "\n".join(junk) + "\n")
    with pytest.warns(JournalWarning) as got:
        out, calls = _run(j)
    assert len(got) == 1
    msg = str(got[0].message)
    assert str(j) in msg and "skipped 9 line(s)" in msg and "line 3, 4, 5, 6, 7, 8" in msg
    assert [p["v"] for p in calls] == [2, 3]  # the two good records are kept
    assert [r["result"]["y"] for r in out.values()] == [0, 1, 4, 9]


def test_binary_garbage_is_skipped_and_named(tmp_path):
    j = tmp_path / "j.jsonl"
    _run(j, tasks=TASKS[:2])
    lines = j.read_bytes().splitlines(keepends=True)
    garbage = b"\xff\xfe\x00\x9c bad utf-8 \xc3\x28\n\x00\x01\x02\n"
    j.write_bytes(lines[0] + garbage + lines[1] + b"\x89PNG\r\n\x1a\n")
    with pytest.warns(JournalWarning, match="line 2, 3, 5, 6") as got:
        out, calls = _run(j)
    assert str(j) in str(got[0].message)
    assert [p["v"] for p in calls] == [2, 3]
    assert len(out) == 4 and all(r["ok"] for r in out.values())


def test_a_truncated_last_line_is_ended_so_the_next_record_survives(tmp_path):
    j = tmp_path / "j.jsonl"
    _run(j, tasks=TASKS[:2])
    j.write_bytes(j.read_bytes() + b'{"key": "abc", "payl')  # killed during a write
    with pytest.warns(JournalWarning, match="line 3"):
        out, calls = _run(j)  # resume: the remaining two are run and appended
    assert [p["v"] for p in calls] == [2, 3] and len(out) == 4
    with pytest.warns(JournalWarning, match=r"skipped 1 line\(s\).*line 3\)"):
        again, calls = _run(j)  # the second resume finds every record
    assert calls == [] and again == out
    with pytest.warns(JournalWarning):
        assert read_journal(j) == out
    assert len(j.read_bytes().splitlines()) == 5  # 4 records and the fragment, each alone


def test_a_clean_journal_does_not_warn(tmp_path):
    j = tmp_path / "j.jsonl"
    out, _ = _quiet_run(j)
    again, calls = _quiet_run(j)
    assert calls == [] and again == out
    assert j.read_bytes().endswith(b"\n") and len(j.read_bytes().splitlines()) == 4


HOLDER = """
import sys
from pathlib import Path
from opticalstamp.io.journal import journal_lock
with journal_lock(Path(sys.argv[1])):
    print("locked", flush=True)
    sys.stdin.read()
"""


def _holder(journal):
    """Another process that holds the journal's lock until its stdin closes (or it is killed)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(journal)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout.readline().strip() == "locked"
    return proc


@pytest.mark.parametrize("release", ["exit", "kill"])
def test_a_second_run_on_a_locked_journal_fails_at_once(tmp_path, release):
    j = tmp_path / "out.nc.journal.jsonl"
    proc = _holder(j)
    try:
        with pytest.raises(JournalLocked) as err:
            _run(j)
        msg = str(err.value)
        assert isinstance(err.value, InputError)
        assert f"PID {proc.pid}" in msg and str(j) in msg
        assert not j.exists()  # no work was done, nothing was written
    finally:
        if release == "exit":
            proc.communicate("")  # the holder leaves its block normally
        else:
            proc.kill()  # the OS releases the lock of a killed process
            proc.communicate()
    out, calls = _run(j)
    assert len(calls) == 4 and len(out) == 4


def test_the_lock_is_released_on_an_exception_and_a_caller_may_hold_it(tmp_path):
    j = tmp_path / "j.jsonl"
    with pytest.raises(RuntimeError), journal_lock(j):
        raise RuntimeError("boom")
    assert not (tmp_path / "j.jsonl.lock").exists()  # removed on the way out
    with journal_lock(j):  # taken again: the first was released
        assert (tmp_path / "j.jsonl.lock").read_text().startswith("PID ")
        out, _ = _run(j, lock=False)  # the caller holds it (search: across generations)
        with pytest.raises(JournalLocked):  # not re-entrant: a second taker is refused
            _run(j)
        assert (tmp_path / "j.jsonl.lock").exists()  # a refused taker leaves the holder's
    assert len(out) == 4
    assert not (tmp_path / "j.jsonl.lock").exists()
