"""Independent evaluations on a local process pool or a Dask cluster, journalled.

A *task* is (key, payload): the key names the evaluation (a hash of what it evaluates
and its seed), the payload is what the worker function needs (plain data). Results are
appended to a JSON-lines journal as they arrive (flushed and synced), so a study that is
interrupted resumes where it stopped: tasks whose key is already in the journal are not
run again. An evaluation that raises is retried ``retries`` times and then journalled as
failed with its error and payload; a worker process that dies takes its task with it and
the pool is restarted, the task counted as a failed attempt. Seeds belong to tasks, not
workers, so results are identical for any number of workers.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Iterable
from pathlib import Path

from .io import to_json


def task_key(payload: dict) -> str:
    """Stable key of a payload (sorted JSON, SHA-256, 16 hex digits)."""
    blob = json.dumps(payload, sort_keys=True, default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def read_journal(path: Path | None) -> dict[str, dict]:
    """Finished entries by key (a truncated last line, from a kill, is ignored)."""
    done: dict[str, dict] = {}
    if path is None or not path.exists():
        return done
    for line in path.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        done[rec["key"]] = rec
    return done


def _append(path: Path | None, rec: dict) -> None:
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        fh.write(to_json(rec).replace("\n", " ") + "\n")
        fh.flush()
        os.fsync(fh.fileno())


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

    Each record: {"key", "payload", "ok", "result" or "error", "attempts"}.
    ``workers``: local processes (default: every core); 1 runs in this process.
    ``dask_address``: run on that Dask scheduler instead (``tcp://host:port``).
    """
    tasks = list(tasks)
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
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    attempts = {k: 0 for k, _ in todo}
    pending = list(todo)
    ctx = mp.get_context("spawn")  # no fork of numba's threads
    while pending:
        with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_single_thread) as ex:
            futs = {}
            for key, payload in pending:
                attempts[key] += 1
                futs[ex.submit(fn, payload)] = (key, payload)
            pending = []
            broken = False
            while futs:
                fin, _ = wait(futs, return_when=FIRST_COMPLETED)
                for f in fin:
                    key, payload = futs.pop(f)
                    try:
                        record(key, payload, True, f.result(), attempts[key])
                    except BrokenProcessPool:
                        broken = True
                        pending.append((key, payload))
                    except Exception as err:  # noqa: BLE001
                        if attempts[key] <= retries:
                            pending.append((key, payload))
                        else:
                            record(
                                key, payload, False, f"{type(err).__name__}: {err}", attempts[key]
                            )
                if broken:  # the pool is dead: collect what is left and restart it
                    for key, payload in futs.values():
                        pending.append((key, payload))
                    futs = {}
        # a task that keeps killing its worker is marked, not retried forever
        for key, payload in list(pending):
            if attempts[key] > retries:
                pending.remove((key, payload))
                record(key, payload, False, "worker process died", attempts[key])


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
