"""The study journal: JSON lines of finished evaluations, read back to resume a study.

Lines that are not records (a truncated last line, garbage) and records whose values
break the study's rules (a ``check``: NaN, negative or missing figures) are skipped with
one :class:`JournalWarning` naming the file and the lines, and their evaluations are run
again; every append starts on a fresh line and is flushed and synced; a run holds an
exclusive lock on the journal (``<journal>.lock``, removed when the run ends, normally or
not), so that a second run on the same output stops at once with :class:`JournalLocked`.
A journal path that is not a regular file (a folder, a device) is refused with
:class:`~opticalstamp.validate.InputError` before anything is created.
"""

from __future__ import annotations

import json
import os
import socket
import warnings
from collections.abc import Callable, Iterator
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


#: A record's check: None where its values keep the study's rules, else the rule broken.
RecordCheck = Callable[[dict], str | None]


def check_journal_path(path: Path | None) -> None:
    """InputError unless ``path`` is None, missing, or a regular file (a folder or a device
    in its place is named, before anything is read, created or locked)."""
    if path is None:
        return
    path = Path(path)
    if (path.exists() or path.is_symlink()) and not path.is_file():
        kind = "a folder" if path.is_dir() else "not a regular file"
        raise InputError(
            f"journal {path}: {kind}; a study's journal is a file of JSON lines beside its "
            "results (RESULTS.journal.jsonl): move it away or write the results elsewhere"
        )


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


def read_journal(path: Path | None, check: RecordCheck | None = None) -> dict[str, dict]:
    """Finished records of a journal, by key.

    Parameters
    ----------
    path : Path or None
        The JSON-lines journal; None or a missing file: no records.
    check : callable, optional
        ``check(record) -> None | str``: None where a finished record's values keep the
        study's rules, else the rule it breaks (a record with NaN, negative or missing
        figures); such records are skipped like lines that are not records. Failed
        records (``ok`` false) are not checked.

    Returns
    -------
    dict
        Records by key (a later line with the same key wins; a skipped line never does).

    Raises
    ------
    InputError
        When ``path`` is a folder or another file that is not a regular one.

    Warns
    -----
    JournalWarning
        Once, naming the file and the line numbers, when lines are skipped: not records (a
        truncated last line after a kill during a write, bytes that are not UTF-8 or not
        JSON, JSON of another shape) or records that break ``check`` (with the first
        rule broken). Their evaluations are run again.
    """
    done: dict[str, dict] = {}
    check_journal_path(path)
    if path is None or not path.exists():
        return done
    bad, broken = [], []
    for n, line in enumerate(path.read_bytes().split(b"\n"), start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line.decode("utf-8"))
        except (ValueError, RecursionError):  # UnicodeDecodeError and JSONDecodeError included
            rec = None
        if not _is_record(rec):
            bad.append(n)
            continue
        why = check(rec) if check is not None and rec["ok"] else None
        if why:
            broken.append((n, why))
        else:
            done[rec["key"]] = rec
    if bad or broken:
        parts = []
        if bad:
            parts.append(f"{len(bad)} line(s) that are not records (line {_lines(bad)})")
        if broken:
            n, why = broken[0]
            parts.append(
                f"{len(broken)} record(s) whose values break the study's rules (line "
                f"{_lines([b[0] for b in broken])}; line {n}: {why})"
            )
        warnings.warn(
            f"journal {path}: skipped {' and '.join(parts)}; their evaluations are run again",
            JournalWarning,
            stacklevel=2,
        )
    return done


def _lines(numbers: list[int]) -> str:
    """Line numbers as a short list: the first 20 and how many more."""
    shown = ", ".join(map(str, numbers[:20]))
    return shown + (f" and {len(numbers) - 20} more" if len(numbers) > 20 else "")


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

    The holder writes its PID and host into the lock file and removes the file when the
    block exits, normally or by an exception (it is unlinked while still locked, and a
    taker checks after locking that the file it locked is still the one at the path, so
    two runs never both hold it). A process that dies leaves the file behind, but its
    lock (``flock``) is released by the OS: the next run takes it.

    Parameters
    ----------
    journal : Path or None
        The journal; None: nothing to lock.

    Raises
    ------
    JournalLocked
        At once, when another process holds the lock; the message names the journal and
        the holder.
    InputError
        Before anything is created, when the journal is a folder or not a regular file.
    """
    check_journal_path(journal)
    if journal is None or fcntl is None:
        yield
        return
    journal = Path(journal)
    lock = journal.with_name(journal.name + ".lock")
    lock.parent.mkdir(parents=True, exist_ok=True)
    fd = _take_lock(journal, lock)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"PID {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
        yield
    finally:
        try:
            if _same_file(fd, lock):
                os.unlink(lock)  # while locked: a waiting taker sees it gone and retries
        finally:
            os.close(fd)  # releases the lock


def _same_file(fd: int, path: Path) -> bool:
    """Whether the open file ``fd`` is the file at ``path`` now."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return False
    own = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)


def _take_lock(journal: Path, lock: Path) -> int:
    """An open descriptor of ``lock``, exclusively locked (see :func:`journal_lock`)."""
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode("utf-8", "replace").strip() or "PID unknown"
            os.close(fd)
            raise JournalLocked(
                f"journal {journal} is in use by another run ({holder}); wait for it to "
                f"finish or write to another output (lock file: {lock})"
            ) from None
        except BaseException:
            os.close(fd)
            raise
        if _same_file(fd, lock):
            return fd
        os.close(fd)  # the holder removed it between our open and our lock: open anew
