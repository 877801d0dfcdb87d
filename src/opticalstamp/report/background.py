"""Jobs of a report that run in processes of their own (the studies, figures when a
process is idle) while the report's sections run here."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import contextmanager


def workers(n_tasks: int) -> int:
    """Background processes for ``n_tasks`` tasks: one per core but the one this process
    works on, and at least two (so that on two cores the three processes share them)."""
    import os

    return max(1, min(n_tasks, max(2, (os.cpu_count() or 1) - 1)))


def one_numba_thread() -> None:  # pragma: no cover - runs in the background processes
    import numba

    numba.set_num_threads(1)


def timed(fn, args: tuple) -> tuple:  # pragma: no cover - runs in the background processes
    """``fn(*args)`` with the seconds it took: (result, wall s, CPU s of this process)."""
    import time

    t, c = time.perf_counter(), time.process_time()
    out = fn(*args)
    return out, time.perf_counter() - t, time.process_time() - c


def only_result(name: str, results: list):
    """The result of a job of one task (the default ``join`` of :class:`Background`)."""
    (result,) = results
    return result


class Background:
    """Jobs that run in processes of their own (spawned, one numba thread each), started
    at once while the report goes on here.

    Parameters
    ----------
    jobs : name -> list of (function, arguments), the tasks of each job; functions and
        results are pickled. The tasks go to :func:`workers` processes in the order
        given, each to the next process that is free (so the longest first: no process
        is left alone with a long task at the end while the others idle); each task's
        seconds are kept (:meth:`seconds`).
    join : ``join(name, results)``: the result of job ``name`` from its tasks' results,
        in the order given (default: the result of its one task)
    """

    def __init__(self, jobs: dict, join: Callable[[str, list], object] = only_result) -> None:
        self._pool = None
        self._join = join
        self._jobs: dict[str, list] = {}
        self._extra: list = []  # tasks given by submit()
        self._n = 0
        tasks = [(name, task) for name, job in jobs.items() for task in job]
        if not tasks:
            return
        import multiprocessing as mp

        ctx = mp.get_context("spawn")  # no fork of numba's threads
        self._n = workers(len(tasks))
        self._pool = ctx.Pool(self._n, initializer=one_numba_thread)
        for name, (fn, args) in tasks:
            self._jobs.setdefault(name, []).append(self._pool.apply_async(timed, (fn, args)))

    def __enter__(self) -> Background:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def result(self, name: str):
        """The result of job ``name`` (waits for it; re-raises its error), or None if it
        was not started."""
        if name not in self._jobs:
            return None
        return self._join(name, [task.get()[0] for task in self._jobs[name]])

    def seconds(self) -> dict:
        """Per job whose tasks all finished without error, the seconds its tasks took in
        their processes: {name: {"wall_s", "cpu_s"}} (sums over the tasks; the CPU
        seconds of the one process each ran in, which the load changes far less than the
        wall seconds)."""
        out = {}
        for name, tasks in self._jobs.items():
            if not all(t.ready() and t.successful() for t in tasks):
                continue
            got = [t.get() for t in tasks]
            out[name] = {"wall_s": sum(g[1] for g in got), "cpu_s": sum(g[2] for g in got)}
        return out

    def _ready(self, name: str) -> bool:
        return all(task.ready() for task in self._jobs[name])

    def running(self) -> int:
        """How many background processes are at work (tasks not finished, at most one per
        process)."""
        return min(self._n, sum(not task.ready() for task in self._all()))

    def submit(self, fn, *args):
        """``fn(*args)`` in a background process if one is idle now: its AsyncResult
        (``get()`` gives the result); else None (nothing started)."""
        if self._pool is None or self.running() >= self._n:
            return None
        task = self._pool.apply_async(fn, args)
        self._extra.append(task)
        return task

    def _all(self) -> list:
        return [task for job in self._jobs.values() for task in job] + self._extra

    def as_completed(self, poll_s: float = 0.05):
        """The names of the jobs, each as soon as its tasks have finished (failed ones
        too)."""
        left = list(self._jobs)
        while left:
            ready = [name for name in left if self._ready(name)]
            if not ready:
                waiting = next(t for t in self._jobs[left[0]] if not t.ready())
                waiting.wait(poll_s)
                continue
            for name in ready:
                left.remove(name)
                yield name

    @contextmanager
    def cores(self):
        """Numba threads of this process for a section: one per core the running jobs
        leave free, at least one (more threads than free cores only burn CPU time that
        the jobs could use; a result does not depend on the thread count)."""
        import numba

        before = numba.get_num_threads()
        free = max(1, numba.config.NUMBA_NUM_THREADS - self.running())
        numba.set_num_threads(min(before, free))
        try:
            yield
        finally:
            numba.set_num_threads(before)

    def close(self) -> None:
        """End the processes: at once where jobs are still running (the report failed)."""
        if self._pool is None:
            return
        if all(self._ready(name) for name in self._jobs):
            self._pool.close()
        else:
            self._pool.terminate()
        self._pool.join()
        self._pool = None
