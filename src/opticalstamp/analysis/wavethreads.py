"""The wavelengths of a light side by side: the 2-D path's sources (one stack each) in
threads, in the order that ends soonest, each computed as it would be alone.

On a GPU every wavelength has a thread of the process's kept pool and a CUDA stream of
its own (one's host work overlaps another's transforms); on the CPU a few run at a time
(:data:`CPU_SIDE_BY_SIDE`), their FFTs on one thread each, one's BLAS and copies
overlapping another's transforms. The jobs are started in the order given (a costly
one last would run alone at the end: the caller puts the costliest first) and their
results come back in the jobs' own order.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
from concurrent.futures import ThreadPoolExecutor, wait

from ..device import usable_cores
from .arrays import fft_threads
from .wave import one_blas_thread

__all__ = ["CPU_SIDE_BY_SIDE", "side_by_side"]

#: Wavelengths of the 2-D path side by side on the CPU, at most (each holds its range
#: finder's basis, up to 1 GB at the prototype's shortest wavelength).
CPU_SIDE_BY_SIDE = 2


def side_by_side(fn, jobs: list[tuple], order: list[int], gpu: bool) -> list:
    """``fn(*job)`` for every job of ``jobs``, started in ``order`` (indices into
    ``jobs``) on threads (see the module's docstring; one after the other where one
    thread is all there is), each in a copy of the caller's context (the run's device
    goes along); the results in the jobs' order. BLAS runs on one thread around the pool
    (the sources' own limits, left in any order, restore 1, and this restores the
    process's at the end); none is left running on a kept thread where one fails."""
    n = len(jobs) if gpu else min(len(jobs), usable_cores(), CPU_SIDE_BY_SIDE)
    if n < 2:
        return [fn(*job) for job in jobs]
    run = _on_stream if gpu else _one_fft_thread
    with one_blas_thread(), _pool(n, gpu) as pool:
        runs = {i: pool.submit(contextvars.copy_context().run, run, fn, *jobs[i]) for i in order}
        try:
            return [runs[i].result() for i in range(len(jobs))]
        finally:
            wait(runs.values())


@contextlib.contextmanager
def _pool(n: int, gpu: bool):
    """``n`` threads: on a GPU the process's kept ones (:func:`_gpu_threads`), else new."""
    if gpu:
        yield _gpu_threads(n)
        return
    with ThreadPoolExecutor(max_workers=n) as pool:
        yield pool


@functools.lru_cache(maxsize=4)
def _gpu_threads(n: int) -> ThreadPoolExecutor:
    """The process's pool of ``n`` threads for wavelengths on a GPU, made once: CuPy
    caches FFT plans per thread (kept, with their work areas, while the process lives),
    and fresh threads made and destroyed them at every call (1.86 -> 1.47 s in white
    light, an H100)."""
    return ThreadPoolExecutor(max_workers=n, thread_name_prefix="opticalstamp-wave-gpu")


def _one_fft_thread(fn, *args):
    """``fn(*args)`` with the CPU's FFTs on one thread (:func:`~.arrays.fft_threads`)."""
    with fft_threads(1):
        return fn(*args)


def _on_stream(fn, *args):
    """``fn(*args)`` with CuPy's work queued on a non-blocking stream of its own."""
    import cupy

    with cupy.cuda.Stream(non_blocking=True) as stream:
        out = fn(*args)
        stream.synchronize()
    return out
