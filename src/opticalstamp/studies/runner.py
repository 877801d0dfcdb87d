"""Independent evaluations on a local process pool or a Dask cluster, journalled.

A *task* is (key, payload): the key names the evaluation (a hash of what it evaluates
and its seed), the payload is what the worker function needs (plain data). Results are
appended to a JSON-lines journal as they arrive (flushed and synced), so a study that is
interrupted resumes where it stopped: tasks whose key is already in the journal are not
run again. Journal lines that are not records (a truncated last line, garbage) are
skipped with one :class:`JournalWarning`, and a run holds a lock on its journal
(``<journal>.lock``), so that a second run on the same output stops at once with
:class:`JournalLocked`. An evaluation that raises is retried ``retries`` times and then
journalled as failed with its error and payload; when a worker process dies, the tasks
that were in flight with it are rerun one at a time in pools of their own, so that only
the task that kills its worker is marked ("worker process died"). Seeds belong to tasks,
not workers, so results are identical for any number of workers.
"""

from __future__ import annotations

import hashlib
import json
import os
import socket
import warnings
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ..io.files import to_json
from ..validate import InputError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: journals are not locked
    fcntl = None


class JournalWarning(UserWarning):
    """Lines of a journal that are not records were skipped (their evaluations are redone)."""


class JournalLocked(InputError):
    """Another run holds the journal: two runs on one output would do all the work twice."""


def task_key(payload: dict) -> str:
    """Stable key of a payload (sorted JSON, SHA-256, 16 hex digits)."""
    blob = json.dumps(payload, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


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


def _append(path: Path | None, rec: dict) -> None:
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


_HELD: set[str] = set()  # lock files this process holds


@contextmanager
def journal_lock(journal: Path | None) -> Iterator[None]:
    """Hold the journal's lock, ``<journal>.lock``, for one run; nested use is free.

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
    name = str(lock.resolve())
    if name in _HELD:  # search: one run_tasks per generation, inside the study's lock
        yield
        return
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
        _HELD.add(name)
        try:
            yield
        finally:
            _HELD.discard(name)
    finally:
        os.close(fd)  # releases the lock


def _single_thread() -> None:  # pragma: no cover - runs in worker processes
    import numba

    numba.set_num_threads(1)


def run_tasks(
    fn: Callable[[dict], dict],
    tasks: Iterable[tuple[str, dict]],
    *,
    workers: int | None = None,
    dask_address: str | None = None,
    journal: Path | None = None,
    retries: int = 1,
    progress: bool = False,
    desc: str = "evaluations",
) -> dict[str, dict]:
    """Run ``fn(payload)`` for every task not yet journalled; return records by key.

    Parameters
    ----------
    fn : callable
        The evaluation, ``fn(payload) -> dict``.
    tasks : iterable of (str, dict)
        (key, payload) pairs.
    workers : int, optional
        Local processes (default: every core); 1 runs in this process.
    dask_address : str, optional
        Run on that Dask scheduler instead (``tcp://host:port``).
    journal : Path, optional
        JSON-lines journal to resume from and append to; it is locked for the run.
    retries : int
        Further attempts of an evaluation that raises.
    progress : bool
        Show a progress bar.
    desc : str
        Label of the progress bar.

    Returns
    -------
    dict
        Records by key: {"key", "payload", "ok", "result" or "error", "attempts"}.

    Raises
    ------
    JournalLocked
        Before any work, when another process runs on the same journal.
    """
    tasks = list(tasks)
    with journal_lock(journal):  # before any work: one run at a time
        done = read_journal(journal)
        todo = [(k, p) for k, p in tasks if k not in done]
        bar = None
        if progress and todo:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), desc=desc, unit="eval")

        def record(key, payload, ok, value, attempts):
            rec = {"key": key, "payload": payload, "ok": ok, "attempts": attempts}
            rec["result" if ok else "error"] = value
            done[key] = rec
            _append(journal, rec)
            if bar is not None:
                bar.update(1)

        if not todo:
            pass  # everything is journalled already: nothing to connect to or start
        elif dask_address:
            _run_dask(fn, todo, dask_address, retries, record)
        elif (workers or os.cpu_count() or 1) <= 1 or len(todo) <= 1:
            for key, payload in todo:
                for attempt in range(1, retries + 2):
                    try:
                        record(key, payload, True, fn(payload), attempt)
                        break
                    except Exception as err:  # noqa: BLE001 - reported, never dropped
                        if attempt == retries + 1:
                            record(key, payload, False, f"{type(err).__name__}: {err}", attempt)
        else:
            _run_pool(fn, todo, workers or os.cpu_count() or 1, retries, record)
        if bar is not None:
            bar.close()
        return {k: done[k] for k, _ in tasks if k in done}


def _run_pool(fn, todo, workers, retries, record) -> None:
    """All tasks on one pool; when a worker dies the pool breaks and every task in flight
    fails with it, so those tasks are rerun one at a time, each in a pool of its own, and
    only a task that kills its own worker is charged with the death."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    ctx = mp.get_context("spawn")  # no fork of numba's threads

    def pool(n: int):
        return ProcessPoolExecutor(n, mp_context=ctx, initializer=_single_thread)

    def failed(key, payload, err, attempt) -> bool:
        """Record a final failure, or say that the task is to be tried again."""
        if attempt <= retries:
            return False
        msg = (
            "worker process died"
            if isinstance(err, BrokenProcessPool)
            else (f"{type(err).__name__}: {err}")
        )
        record(key, payload, False, msg, attempt)
        return True

    suspects = []
    with pool(workers) as ex:
        futs = {ex.submit(fn, payload): (key, payload) for key, payload in todo}
        for f in as_completed(futs):
            key, payload = futs[f]
            try:
                record(key, payload, True, f.result(), 1)
            except BrokenProcessPool:
                suspects.append((key, payload))  # it died, or died with another's worker
            except Exception as err:  # noqa: BLE001 - reported, never dropped
                if not failed(key, payload, err, 1):
                    suspects.append((key, payload))
    for key, payload in suspects:
        for attempt in range(2, retries + 3):
            with pool(1) as ex:
                try:
                    record(key, payload, True, ex.submit(fn, payload).result(), attempt)
                    break
                except Exception as err:  # noqa: BLE001 - BrokenProcessPool included
                    if failed(key, payload, err, attempt):
                        break


def _run_dask(fn, todo, address, retries, record) -> None:
    from distributed import Client, as_completed

    with Client(address, timeout="20s") as client:
        futs = {}
        for key, payload in todo:
            f = client.submit(fn, payload, key=f"opticalstamp-{key}", pure=False, retries=retries)
            futs[f] = (key, payload)
        for f in as_completed(list(futs)):
            key, payload = futs[f]
            try:
                record(key, payload, True, f.result(), 1)
            except Exception as err:  # noqa: BLE001 - KilledWorker, evaluation errors
                record(key, payload, False, f"{type(err).__name__}: {err}", retries + 1)
