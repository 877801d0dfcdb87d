"""Jobs of a report that run in processes of their own (the studies, figures when a
process is idle) while the report's sections run here.

The processes are a :class:`~concurrent.futures.ProcessPoolExecutor`'s, which are not
daemons: a study may spread its own evaluations over processes of its own (the search
and the tolerance study on the cores the report leaves idle, :func:`study_workers`).
Every such process ends with the process that started it
(:func:`~opticalstamp.studies.runner.watch_parent`)."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import contextmanager

from ..device import usable_cores
from ..studies.runner import process_pool


def workers(n_tasks: int) -> int:
    """Background processes for ``n_tasks`` tasks: one per core but the one this process
    works on, and at least two (so that on two cores the three processes share them)."""
    return max(1, min(n_tasks, max(2, usable_cores() - 1)))


def study_workers(n_tasks: int, n_spread: int) -> int:
    """Processes for each of ``n_spread`` background tasks that can spread their
    evaluations (the search, the tolerance study) when the report starts ``n_tasks``:
    the one its task runs in, and an even share of the cores that neither this process
    nor the report's :func:`workers` use (2 cores: none, so 1: in the task's own process;
    16 cores and 5 tasks: 10 idle, so 6 each). The studies' figures do not depend on it
    (seeds belong to evaluations, not to processes)."""
    spare = max(0, usable_cores() - 1 - workers(n_tasks))
    return 1 + spare // max(1, n_spread)


def timed(fn, args: tuple) -> tuple:  # pragma: no cover - runs in the background processes
    """``fn(*args)`` with the seconds it took: (result, wall s, CPU s of this process and
    of the processes it started and waited for: a study's own evaluation processes)."""
    import time

    t, c = time.perf_counter(), time.process_time() + _children_cpu()
    out = fn(*args)
    return out, time.perf_counter() - t, time.process_time() + _children_cpu() - c


def _children_cpu() -> float:  # pragma: no cover - runs in the background processes
    """CPU seconds of the processes this one started and waited for (0 where the system
    does not say)."""
    try:
        import resource
    except ImportError:
        return 0.0
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _warm() -> None:  # pragma: no cover - runs in the background process
    """Import what drawing a figure needs (the drawer's first task, while the report's
    sections run)."""
    from . import plotting  # noqa: F401 - matplotlib and the plots, loaded once
    from .plotting import stack  # noqa: F401


def only_result(name: str, results: list):
    """The result of a job of one task (the default ``join`` of :class:`Background`)."""
    (result,) = results
    return result


class Background:
    """Jobs that run in processes of their own (spawned, one numba thread each), started
    at once while the report goes on here.

    Parameters
    ----------
    jobs : name -> list of (function, arguments) or (function, arguments, cores), the
        tasks of each job; functions and results are pickled; ``cores``: how many cores
        the task keeps busy (default 1; a study that spreads its evaluations over
        processes of its own, :func:`study_workers`). The tasks go to :func:`workers`
        processes in the order given, each to the next process that is free (so the
        longest first: no process is left alone with a long task at the end while the
        others idle); each task's seconds are kept (:meth:`seconds`).
    join : ``join(name, results)``: the result of job ``name`` from its tasks' results,
        in the order given (default: the result of its one task)
    drawer : with no jobs (a quick report), one process all the same where this process
        may use more than one core, started at once and its imports made there while the
        report runs here, to draw a share of the figures (:meth:`share`)
    """

    def __init__(
        self, jobs: dict, join: Callable[[str, list], object] = only_result, drawer: bool = False
    ) -> None:
        self._pool = None
        self._join = join
        self._jobs: dict[str, list] = {}
        self._cores: list = []  # (future, cores) of every job's task, in the order given
        self._extra: list = []  # tasks given by submit()
        self._procs: list = []
        self._n = 0
        tasks = [(name, task) for name, job in jobs.items() for task in job]
        if not tasks and not (drawer and usable_cores() > 1):
            return
        import multiprocessing as mp

        self._n = workers(len(tasks)) if tasks else 1
        self._pool = process_pool(self._n)  # spawned, one numba thread each
        before = set(mp.active_children())
        for name, (fn, args, *cores) in tasks:
            fut = self._pool.submit(timed, fn, args)
            self._jobs.setdefault(name, []).append(fut)
            self._cores.append((fut, cores[0] if cores else 1))
        if not tasks:  # the drawer alone, its imports made now (not counted as busy)
            try:
                self._pool.submit(_warm)
            except (OSError, RuntimeError):  # no process can be started: all drawn here
                self._pool, self._n = None, 0
                return
        # the pool's processes (started by the first submit): the ones close() may end
        self._procs = [p for p in mp.active_children() if p not in before]

    def __enter__(self) -> Background:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def result(self, name: str):
        """The result of job ``name`` (waits for it; re-raises its error), or None if it
        was not started; :class:`~.section.NotMeasurable` where a background process
        ended without giving it (killed, or out of memory: the pool is broken then, and
        every job not yet done with it), so that the report still writes the rest."""
        from concurrent.futures.process import BrokenProcessPool

        if name not in self._jobs:
            return None
        try:
            return self._join(name, [task.result()[0] for task in self._jobs[name]])
        except BrokenProcessPool:
            from .section import NotMeasurable

            return NotMeasurable(
                "a background process ended without giving its result (killed, or out of memory?)"
            )

    def seconds(self) -> dict:
        """Per job whose tasks all finished without error, the seconds its tasks took in
        their processes: {name: {"wall_s", "cpu_s"}} (sums over the tasks; the CPU
        seconds of the one process each ran in, which the load changes far less than the
        wall seconds; a study's own evaluation processes counted once they ended)."""
        out = {}
        for name, tasks in self._jobs.items():
            if not all(t.done() and t.exception() is None for t in tasks):
                continue
            got = [t.result() for t in tasks]
            out[name] = {"wall_s": sum(g[1] for g in got), "cpu_s": sum(g[2] for g in got)}
        return out

    def _ready(self, name: str) -> bool:
        return all(task.done() for task in self._jobs[name])

    def _busy(self) -> list:
        """Cores of the tasks that run now: the first :func:`workers` unfinished ones in
        the order given (the processes take them in that order), then submit()'s."""
        jobs = [c for task, c in self._cores if not task.done()][: self._n]
        extra = [1 for task in self._extra if not task.done()]
        return (jobs + extra)[: self._n]

    def running(self) -> int:
        """How many cores the background keeps busy: its processes at work (at most one
        task each), a study that spreads its evaluations counted with its own processes."""
        return sum(self._busy())

    def submit(self, fn, *args):
        """``fn(*args)`` in a background process if one is idle now: its Future
        (``result()`` gives the result); else None (nothing started)."""
        if self._pool is None or len(self._busy()) >= self._n:
            return None
        return self._queue(fn, *args)

    def _queue(self, fn, *args):
        """``fn(*args)`` queued to the processes: its Future, or None where the pool is
        broken (a process died: run here instead)."""
        from concurrent.futures.process import BrokenProcessPool

        try:
            task = self._pool.submit(fn, *args)
        except BrokenProcessPool:
            return None
        self._extra.append(task)
        return task

    def share(self, fn, tasks: dict) -> dict:
        """name -> the Future of ``fn(*args)`` in a background process, or None where it
        is to be run here, for ``tasks`` (name -> args): with jobs, one task to each
        process that is idle now (:meth:`submit`); with the drawer alone, every other
        task, queued, while this process runs the rest."""
        if self._jobs or self._pool is None:
            return {name: self.submit(fn, *args) for name, args in tasks.items()}
        return {
            name: self._queue(fn, *args) if i % 2 else None
            for i, (name, args) in enumerate(tasks.items())
        }

    @staticmethod
    def done_or_here(task, fn, args):
        """``task``'s result, or ``fn(*args)`` here where its process ended without it."""
        from concurrent.futures.process import BrokenProcessPool

        try:
            return task.result()
        except BrokenProcessPool:
            return fn(*args)

    def _all(self) -> list:
        return [task for job in self._jobs.values() for task in job] + self._extra

    def as_completed(self, poll_s: float = 0.05):
        """The names of the jobs, each as soon as its tasks have finished (failed ones
        too)."""
        from concurrent.futures import wait

        left = list(self._jobs)
        while left:
            ready = [name for name in left if self._ready(name)]
            if not ready:
                waiting = next(t for t in self._jobs[left[0]] if not t.done())
                wait([waiting], timeout=poll_s)
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
        """End the processes: at once where jobs are still running (the report failed;
        the processes a study started end with its process:
        :func:`~opticalstamp.studies.runner.watch_parent`)."""
        if self._pool is None:
            return
        if not all(task.done() for task in self._all()):
            for proc in self._procs:  # this pool's, no other child of this process
                proc.terminate()
        self._pool.shutdown(wait=True, cancel_futures=True)
        self._pool = None
