"""Launching rays: the Python driver of the numba kernel (:mod:`.kernel`).

Rays are launched in chunks of bounded memory from a source (plain Lambertian sampling,
or importance sampling over the first mask's holes) and the survivors are returned in
launch order as :class:`RayBatch`; :func:`trace_rays` traces given rays. Results are
identical for any chunk size or thread count (see :mod:`.kernel` for the generator).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import numba as nb
import numpy as np
from tqdm.asyncio import tqdm as console_tqdm
from tqdm.auto import tqdm

from ..device import run_device
from .kernel import run_importance, run_plain, seed_key, trace_bundle
from .sampling import Source, hole_targets
from .stack import Path

BLOCK = 4096
#: Least rays per chunk on a GPU: a chunk costs a few kernel launches and transfers, which
#: at ~1e11 rays/s outweigh a CPU-sized chunk's trace. It never changes an estimate beyond
#: rounding (the device's sums are order-free atomics anyway).
DEVICE_CHUNK = 1 << 24


def progress_bar(iterable=None, *, progress: bool, **kwargs) -> tqdm:
    """A tqdm bar, shown when ``progress`` and stderr is a terminal: in a captured log
    (a pipe, a file, a batch job) it is left out rather than filling the log with
    carriage returns. In a notebook (tqdm.auto's widget, no terminal) it is shown
    whenever ``progress``."""
    console = tqdm is console_tqdm
    return tqdm(iterable, disable=(None if console else False) if progress else True, **kwargs)


def chunk_for(chunk: int, device: str) -> int:
    """Rays per chunk that :func:`launch` uses for ``chunk`` on ``device`` (cpu, cuda).
    Under numba's CUDA simulator (no launch costs to amortise) the chunk is the caller's,
    so that the tests see several chunks."""
    gpu = device == "cuda" and not nb.config.ENABLE_CUDASIM
    return max(BLOCK, int(chunk), DEVICE_CHUNK if gpu else 0)


@dataclass(frozen=True)
class RayBatch:
    """Rays of one chunk that left the last plane of the path, in launch order.

    Attributes
    ----------
    ids : (n,) int64, global ray index
    x, y : (n,) float64, position on the last exit plane (um)
    sx, sy : (n,) float64, invariant direction n sin(theta) (cos phi, sin phi)
    w : (n,) float64, weight (etendue um^2 sr, or power fraction for a point source)
    hole_row, hole_k : (n, n_masks) int8 / int32, hole passed in each mask (row, index)
    ledger : (n_planes, 4) int64, rays by exit plane and status (see STATUS_NAMES)
    n_launched : int, physical rays launched (ledger total)
    n_samples : int, samples drawn: estimates are sums of ``w`` divided by this
    block_ledger : (n_blocks, n_planes, 4) int64, the ledger of each :data:`BLOCK` of rays
        launched (the chunk's first ray starts block 0), so that a span of whole blocks
        can be cut out of the chunk with its own ledger
        (:meth:`~opticalstamp.raytrace.pixel.PixelTracer.trace`); None where not kept
    """

    ids: np.ndarray
    x: np.ndarray
    y: np.ndarray
    sx: np.ndarray
    sy: np.ndarray
    w: np.ndarray
    hole_row: np.ndarray
    hole_k: np.ndarray
    ledger: np.ndarray
    n_launched: int
    n_samples: int
    block_ledger: np.ndarray | None = None
    #: The survivors in device memory (:class:`~opticalstamp.raytrace.cuda.DeviceRays`)
    #: where a GPU traced them, for tallies on the device; None on the CPU.
    device: ClassVar[Any] = None


class DeviceRayBatch:
    """A :class:`RayBatch` whose survivors a GPU traced and keeps: ``device`` holds them
    for tallies on the device; the host arrays (in ray order, read-only) are copied back
    on first use, so code that reads a RayBatch reads this one unchanged."""

    def __init__(self, device: Any, n_samples: int) -> None:
        self.device = device
        self.ledger = device.ledger
        self.n_launched = device.n_launched
        self.n_samples = int(n_samples)

    @cached_property
    def _host(self) -> dict:
        h = self.device.host()
        for v in h.values():
            v.flags.writeable = False
        return h

    ids = property(lambda self: self._host["ids"])
    x = property(lambda self: self._host["x"])
    y = property(lambda self: self._host["y"])
    sx = property(lambda self: self._host["sx"])
    sy = property(lambda self: self._host["sy"])
    w = property(lambda self: self._host["w"])
    hole_row = property(lambda self: self._host["hole_row"])
    hole_k = property(lambda self: self._host["hole_k"])


@dataclass(frozen=True)
class TraceResult:
    """Per-ray fate from :func:`trace_rays`."""

    status: np.ndarray  # (n,) int8, see STATUS_NAMES
    plane: np.ndarray  # (n,) int16, exit-plane index where the ray stopped
    x: np.ndarray
    y: np.ndarray
    w: np.ndarray
    hole_row: np.ndarray  # (n, n_masks) int8, -1 where not reached
    hole_k: np.ndarray  # (n, n_masks) int32


def _kernel_args(path: Path) -> tuple:
    return (
        np.ascontiguousarray(path.slabs),
        float(path.index_out),
        np.ascontiguousarray(path.masks),
        path.lattice.as_array(),
        path.limits,
    )


def trace_rays(path: Path, x, y, sx, sy, w=None, *, fresnel: bool = False) -> TraceResult:
    """Trace given rays (start plane z = bottom of the path's first slab).

    Parameters
    ----------
    path : Path
    x, y : (n,) array, start positions (um)
    sx, sy : (n,) array, invariant direction components (|s| < index of the first slab)
    w : (n,) array, optional initial weights (default 1)
    fresnel : bool, apply unpolarised Fresnel transmission at index steps, exactly:
        (prod Ts + prod Tp) / 2 over the interfaces the ray crosses
    """
    x = np.array(x, dtype=np.float64, ndmin=1)
    n = x.size
    y = np.array(y, dtype=np.float64, ndmin=1)
    sx = np.broadcast_to(np.asarray(sx, dtype=np.float64), (n,)).copy()
    sy = np.broadcast_to(np.asarray(sy, dtype=np.float64), (n,)).copy()
    w = np.ones(n) if w is None else np.array(w, dtype=np.float64, ndmin=1)
    if np.any(sx**2 + sy**2 >= path.slabs[0, 1] ** 2):
        raise ValueError("|s| must be smaller than the index of the first slab")
    status = np.empty(n, np.int8)
    plane = np.empty(n, np.int16)
    hrow = np.full((n, path.n_masks), -1, np.int8)
    hk = np.zeros((n, path.n_masks), np.int32)
    trace_bundle(x, y, sx, sy, w, *_kernel_args(path), fresnel, status, plane, hrow, hk)
    return TraceResult(status, plane, x, y, w, hrow, hk)


def launch(
    path: Path,
    source: Source,
    n_rays: int,
    seed: int,
    *,
    stream: int = 0,
    fresnel: bool = False,
    importance: bool = True,
    chunk: int = 1 << 21,
    first_id: int = 0,
    progress: bool = False,
    hole_weights: np.ndarray | None = None,
    device: str | None = None,
    scratch: dict | None = None,
) -> Iterator[RayBatch]:
    """Launch ``n_rays`` Lambertian rays from ``source`` and trace them, chunk by chunk.

    Rays first_id ... first_id + n_rays - 1 are drawn from the counter-based generator
    keyed by (seed, stream), so any chunking or thread count yields the same rays.
    Memory is bounded by ``chunk``; a progress bar is shown when ``progress``
    (:func:`progress_bar`).
    ``hole_weights`` (one per lattice site) steers importance sampling towards the holes
    of the first mask that matter (see :func:`~opticalstamp.sources.hole_targets`).
    ``device``: cpu, cuda or auto (:func:`~opticalstamp.device.run_device`; None: the
    device of the run in progress, the CPU outside one); the same rays either way.
    On a GPU a chunk holds at least :data:`DEVICE_CHUNK` rays (:func:`chunk_for`).
    ``scratch``: a dict the caller keeps between launches (a tracer's): the CPU kernel's
    output buffers are taken from it where they fit and put back at the end, so that one
    tracer's launches write into memory already mapped (fresh buffers each launch cost
    page faults, ~130 MB a launch at 2^21 rays; a launch running beside another takes
    its own). The rays yielded are copies either way.

    Yields
    ------
    RayBatch or DeviceRayBatch
        The rays of each chunk that reached the end of the path (on a GPU they stay in
        device memory and are copied back on first use).
    """
    if n_rays < 0:
        raise ValueError("n_rays must be >= 0")
    where = run_device(device)
    chunk = chunk_for(chunk, where)
    gpu = None
    if where == "cuda":
        from . import cuda as gpu
    n0 = float(path.slabs[0, 1])
    key = seed_key(seed, stream)
    if importance:
        tg = hole_targets(path, source, hole_weights)
        n_pre = tg.n_pre
        d, n = path.slabs[:n_pre, 0], path.slabs[:n_pre, 1]
        n_min = float(n.min())
        d_eq = float((d * n_min / n).sum())
        w0 = 1.0 if source.is_point else math.pi * n0 * n0 * source.area
    else:
        n_pre, n_min, d_eq = path.first_mask_slab + 1, n0, 0.0
        # per square sample: (2 n0)^2 A of etendue, or 4/pi of the power of a point
        w0 = 4.0 / math.pi if source.is_point else 4.0 * n0 * n0 * source.area
    src = np.array([source.x, source.y, source.width, source.height, w0, n0, n_min, d_eq])
    args = _kernel_args(path)
    nm, npl = path.n_masks, path.slabs.shape[0]
    size = min(chunk, max(n_rays, 1)) if gpu is None else 0  # the CPU kernel's buffers
    bufs = _buffers(size, nm, scratch)
    bar = progress_bar(total=n_rays, unit="ray", unit_scale=True, leave=False, progress=progress)
    done = 0
    try:
        while done < n_rays:
            m = min(chunk, n_rays - done)
            nb_ = (m + BLOCK - 1) // BLOCK
            counts = np.zeros(nb_, np.int64)
            ledger = np.zeros((nb_, npl, 4), np.int64)
            if gpu is not None:
                r = gpu.run(
                    first_id + done, m, key, src, args, fresnel, n_pre, tg if importance else None
                )
                yield DeviceRayBatch(r, m)
                done += m
                bar.update(m)
                continue
            if importance:
                run_importance(
                    first_id + done,
                    m,
                    BLOCK,
                    key,
                    src,
                    *args,
                    fresnel,
                    n_pre,
                    tg.x,
                    tg.y,
                    tg.prob,
                    tg.alias,
                    tg.q_per_area,
                    *bufs,
                    counts,
                    ledger,
                )
                n_launched = m
            else:
                launched = np.zeros(nb_, np.int64)
                run_plain(
                    first_id + done,
                    m,
                    BLOCK,
                    nb.get_num_threads(),
                    key,
                    src,
                    *args,
                    fresnel,
                    n_pre,
                    *bufs,
                    counts,
                    launched,
                    ledger,
                )
                n_launched = int(launched.sum())
            idx = _survivor_index(counts)
            yield RayBatch(
                bufs[5][idx],
                bufs[0][idx],
                bufs[1][idx],
                bufs[2][idx],
                bufs[3][idx],
                bufs[4][idx],
                bufs[6][idx],
                bufs[7][idx],
                ledger.sum(axis=0),
                n_launched,
                m,
                ledger if importance else None,  # plain sampling launches more than m
            )
            done += m
            bar.update(m)
    finally:
        bar.close()
        if scratch is not None and size:
            scratch.clear()  # the latest launch's buffers, for the next one
            scratch[(size, nm)] = bufs


def _buffers(size: int, nm: int, scratch: dict | None) -> tuple:
    """The CPU kernel's output buffers for chunks of ``size`` rays and ``nm`` masks: taken
    from ``scratch`` where it holds them (none is left there while they are in use),
    else new."""
    kept = scratch.pop((size, nm), None) if scratch is not None else None
    if kept is not None:
        return kept
    return (
        np.empty(size),
        np.empty(size),
        np.empty(size),
        np.empty(size),
        np.empty(size),
        np.empty(size, np.int64),
        np.empty((size, nm), np.int8),
        np.empty((size, nm), np.int32),
    )


def _survivor_index(counts: np.ndarray) -> np.ndarray:
    starts = np.arange(counts.size, dtype=np.int64) * BLOCK
    total = int(counts.sum())
    offs = np.cumsum(counts) - counts
    return np.repeat(starts - offs, counts) + np.arange(total, dtype=np.int64)
