"""The study journal: JSON lines of finished evaluations, read back to resume a study.

Lines that are not records (a truncated last line, garbage) are skipped with one
:class:`JournalWarning` naming the file and the lines; every append starts on a fresh line
and is flushed and synced; a run holds an exclusive lock on the journal
(``<journal>.lock``), so that a second run on the same output stops at once with
:class:`JournalLocked`.
"""

from __future__ import annotations

import json
import os
import socket
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..validate import InputError
from .files import to_json

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: journals are not locked
    fcntl = None


class JournalWarning(UserWarning):
    """Lines of a journal that are not records were skipped (their evaluations are redone)."""


class JournalLocked(InputError):
    """Another run holds the journal: two runs on one output would do all the work twice."""


def _is_record(rec) -> bool:
    """Whether a parsed journal line has the shape that :func:`run_tasks` writes."""
    return (
        isinstance(rec, dict)
        and isinstance(rec.get("key"), str)
        and isinstance(rec.get("payload"), dict)
        and type(rec.get("attempts")) is int
        and (
            isinstance(rec.get("result"), dict)
            if rec.get("ok") is True
            else rec.get("ok") is False and isinstance(rec.get("error"), str)
        )
    )


def read_journal(path: Path | None) -> dict[str, dict]:
    """Finished records of a journal, by key.

    Parameters
    ----------
    path : Path or None
        The JSON-lines journal; None or a missing file: no records.

    Returns
    -------
    dict
        Records by key (a later line with the same key wins).

    Warns
    -----
    JournalWarning
        Once, naming the file and the line numbers, when lines are skipped because they
        are not records: a truncated last line (a kill during a write), bytes that are not
        UTF-8 or not JSON, or JSON of another shape. Their evaluations are run again.
    """
    done: dict[str, dict] = {}
    if path is None or not path.exists():
        return done
    bad = []
    for n, line in enumerate(path.read_bytes().split(b"\n"), start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line.decode("utf-8"))
        except (ValueError, RecursionError):  # UnicodeDecodeError and JSONDecodeError included
            rec = None
        if _is_record(rec):
            done[rec["key"]] = rec
        else:
            bad.append(n)
    if bad:
        shown = ", ".join(map(str, bad[:20])) + (
            f" and {len(bad) - 20} more" if len(bad) > 20 else ""
        )
        warnings.warn(
            f"journal {path}: skipped {len(bad)} line(s) that are not records (line {shown}); "
            "their evaluations are run again",
            JournalWarning,
            stacklevel=2,
        )
    return done


def append_record(path: Path | None, rec: dict) -> None:
    """Append one record as one line, on a line of its own, flushed and synced to disk."""
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    line = to_json(rec).replace("\n", " ").encode() + b"\n"
    with open(path, "a+b") as fh:
        end = fh.seek(0, os.SEEK_END)
        if end:
            fh.seek(end - 1)
            if fh.read(1) != b"\n":  # a truncated last line: end it, or this record joins it
                line = b"\n" + line
        fh.write(line)
        fh.flush()
        os.fsync(fh.fileno())


@contextmanager
def journal_lock(journal: Path | None) -> Iterator[None]:
    """Hold the journal's lock, ``<journal>.lock``, for one run (not re-entrant).

    The holder writes its PID and host into the lock file. The lock (``flock``) is released
    when the block exits, normally or by an exception, and by the OS when the process dies.

    Parameters
    ----------
    journal : Path or None
        The journal; None: nothing to lock.

    Raises
    ------
    JournalLocked
        At once, when another process holds the lock; the message names the journal and
        the holder.
    """
    if journal is None or fcntl is None:
        yield
        return
    journal = Path(journal)
    lock = journal.with_name(journal.name + ".lock")
    lock.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "PID unknown"
            raise JournalLocked(
                f"journal {journal} is in use by another run ({holder}); wait for it to "
                f"finish or write to another output (lock file: {lock})"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"PID {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
        yield
    finally:
        os.close(fd)  # releases the lock
