"""Independent evaluations on a local process pool or a Dask cluster, journalled.

A *task* is (key, payload): the key names the evaluation (a hash of what it evaluates
and its seed), the payload is what the worker function needs (plain data). Results are
appended to a JSON-lines journal as they arrive (flushed and synced), so a study that is
interrupted resumes where it stopped: tasks whose key is already in the journal are not
run again. Journal lines that are not records (a truncated last line, garbage) and
records whose results break the study's rules (``check``: NaN, negative or missing
figures) are skipped with one :class:`JournalWarning` and evaluated again; a fresh result
that breaks them is journalled as failed, so a journal reads back the same every time. A
run holds a lock on its journal (``<journal>.lock``, removed when it ends), so that a
second run on the same output stops at once with :class:`JournalLocked`. An evaluation
that raises is retried ``retries`` times and then journalled as failed with its error
and payload; when a worker process dies, the tasks that were in flight with it are rerun
one at a time in pools of their own, so that only the task that kills its worker is
marked ("worker process died"). Seeds belong to tasks, not workers, so results are
identical for any number of workers.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Iterable
from pathlib import Path

from ..device import usable_cores
from ..io.files import to_json
from ..io.journal import append_record, journal_lock, read_journal


def task_key(payload: dict) -> str:
    """Stable key of a payload (sorted JSON, SHA-256, 16 hex digits). A payload's
    ``device`` (where its rays are traced) is not part of it: a result is the same on
    either device, so a journal made on one resumes on the other."""
    named = {k: v for k, v in payload.items() if k != "device"}
    blob = json.dumps(named, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def watch_parent() -> None:  # pragma: no cover - runs in worker processes
    """In a spawned worker: a thread that ends the worker, and the processes it started,
    as soon as the process that started it is gone (killed, or ending its pool at once);
    a worker waiting for its next task would otherwise live on, orphaned."""
    import multiprocessing as mp
    import threading

    parent = mp.parent_process()
    if parent is None:
        return

    def watch() -> None:
        from multiprocessing.connection import wait

        wait([parent.sentinel])
        for child in mp.active_children():
            child.terminate()
        os._exit(1)

    threading.Thread(target=watch, name="watch-parent", daemon=True).start()


def single_thread() -> None:  # pragma: no cover - runs in worker processes
    """A worker process: one numba thread, ended with the process that started it."""
    import numba

    numba.set_num_threads(1)
    watch_parent()


def process_pool(n: int):
    """``n`` spawned worker processes (no fork of numba's threads), one numba thread each,
    each ended with the process that started it (:func:`single_thread`)."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(n, mp_context=mp.get_context("spawn"), initializer=single_thread)


class WorkerPool:
    """Local worker processes kept across several :func:`run_tasks` calls (a search's
    generations): started by the first call that needs them, started again after one
    died, ended on leaving the ``with`` block. A process costs seconds to start (each
    imports the library and loads numba's cached kernels): with a pool per generation a
    ray search of 5 generations of 24 on 2 cores took 20 s on 2 processes, 11 s on one.

    ``workers``: the processes (default: every core this process may use)."""

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or usable_cores()
        self._ex = None

    def executor(self):
        """The pool's executor, started at the first call."""
        if self._ex is None:
            self._ex = process_pool(self.workers)
        return self._ex

    def discard(self) -> None:
        """End the processes (a worker died, or the work is done); the next call of
        :meth:`executor` starts new ones."""
        if self._ex is not None:
            self._ex.shutdown(wait=True, cancel_futures=True)
            self._ex = None

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc) -> None:
        self.discard()


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
    lock: bool = True,
    check: Callable[[dict, dict], str | None] | None = None,
    pool: WorkerPool | None = None,
) -> dict[str, dict]:
    """Run ``fn(payload)`` for every task not yet journalled; return records by key.

    Parameters
    ----------
    fn : callable
        The evaluation, ``fn(payload) -> dict``.
    tasks : iterable of (str, dict)
        (key, payload) pairs.
    workers : int, optional
        Local processes (default: every core this process may use); 1 runs in this
        process.
    pool : WorkerPool, optional
        Local processes kept across calls, used instead of ``workers`` new ones (its
        ``workers`` processes; one runs in this process).
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
    lock : bool
        Take the journal's lock for this call (False: the caller holds it, as
        :func:`opticalstamp.studies.search.search` does across its generations).
    check : callable, optional
        ``check(payload, result) -> None | str``: the rules of a result (None: kept; else
        the rule broken). Journalled results that break them are skipped with a
        :class:`JournalWarning` and evaluated again; a fresh result that breaks them is
        journalled as failed (``"error": "ResultError: ..."``), not retried.

    Returns
    -------
    dict
        Records by key: {"key", "payload", "ok", "result" or "error", "attempts"}.

    Raises
    ------
    JournalLocked
        Before any work, when another process runs on the same journal.
    InputError
        Before any work, when the journal is a folder or not a regular file.
    """
    tasks = list(tasks)

    def broken(rec: dict) -> str | None:
        return None if check is None else check(rec["payload"], rec["result"])

    with journal_lock(journal if lock else None):  # before any work: one run at a time
        done = read_journal(journal, check=broken if check is not None else None)
        todo = [(k, p) for k, p in tasks if k not in done]
        bar = None
        if progress and todo:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), desc=desc, unit="eval")

        def record(key, payload, ok, value, attempts):
            why = None
            if ok and not isinstance(value, dict):
                why = f"the result is not a JSON object (got {type(value).__name__})"
            elif ok and check is not None:  # the result as the journal will read it back
                why = check(json.loads(to_json(payload)), json.loads(to_json(value)))
            if why:  # what the journal would skip on resume is a failure now
                ok, value = False, f"ResultError: {why}"
            rec = {"key": key, "payload": payload, "ok": ok, "attempts": attempts}
            rec["result" if ok else "error"] = value
            done[key] = rec
            append_record(journal, rec)
            if bar is not None:
                bar.update(1)

        if not todo:
            pass  # everything is journalled already: nothing to connect to or start
        elif dask_address:
            _run_dask(fn, todo, dask_address, retries, record)
        elif (pool.workers if pool else workers or usable_cores()) <= 1 or len(todo) <= 1:
            for key, payload in todo:
                for attempt in range(1, retries + 2):
                    try:
                        record(key, payload, True, fn(payload), attempt)
                        break
                    except Exception as err:  # noqa: BLE001 - reported, never dropped
                        if attempt == retries + 1:
                            record(key, payload, False, f"{type(err).__name__}: {err}", attempt)
        else:
            _run_pool(fn, todo, workers or usable_cores(), retries, record, pool)
        if bar is not None:
            bar.close()
        return {k: done[k] for k, _ in tasks if k in done}


def _run_pool(fn, todo, workers, retries, record, shared: WorkerPool | None = None) -> None:
    """All tasks on one pool (``shared``'s where given, else ``workers`` new processes);
    when a worker dies the pool breaks and every task in flight fails with it, so those
    tasks are rerun one at a time, each in a pool of its own, and only a task that kills
    its own worker is charged with the death (a broken ``shared`` pool is started anew
    at its next use)."""
    from concurrent.futures import as_completed
    from concurrent.futures.process import BrokenProcessPool

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

    suspects, broke = [], False
    own = shared is None
    ex = process_pool(workers) if own else shared.executor()

    def submit_all(ex) -> dict:
        return {ex.submit(fn, payload): (key, payload) for key, payload in todo}

    try:
        try:
            futs = submit_all(ex)
        except BrokenProcessPool:  # the kept pool broke while idle (a worker was killed)
            if own:
                raise
            shared.discard()
            ex = shared.executor()
            futs = submit_all(ex)
        for f in as_completed(futs):
            key, payload = futs[f]
            try:
                record(key, payload, True, f.result(), 1)
            except BrokenProcessPool:
                suspects.append((key, payload))  # it died, or died with another's worker
                broke = True
            except Exception as err:  # noqa: BLE001 - reported, never dropped
                if not failed(key, payload, err, 1):
                    suspects.append((key, payload))
    finally:
        if own:
            ex.shutdown(wait=True)
    if broke and not own:
        shared.discard()  # broken: new processes for the next call
    for key, payload in suspects:
        for attempt in range(2, retries + 3):
            with process_pool(1) as ex:
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
