"""The ray kernels on a CUDA device (numba.cuda): the same rays as :mod:`.kernel`.

Imported only when a CUDA device is asked for (``--device cuda`` or ``auto`` with the
optional ``opticalstamp[cuda]`` installed): nothing of it is imported on the CPU path.

Each thread takes one sample and traces it with :mod:`.cuda_ray` (one ray's arithmetic,
the CPU kernel's). Survivors are appended through an atomic counter (their order is
restored from their ids on the host) and stay in device memory (:class:`DeviceRays`); the
ledger and the launched count are summed per block in shared memory. Only plain atomics,
shared memory and ``syncthreads`` are used (but in the per-warp queue, which needs warp
intrinsics), so the kernels run under numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``),
which is how the test suite checks them without a GPU.
"""

from __future__ import annotations

import numpy as np
from numba import config

from ..device import DeviceUnavailable
from .cuda_ray import (  # first: it shims numpy for numba-cuda before importing numba.cuda
    ALIVE,
    MAX_MASKS,
    MAX_PLANES,
    TRANSMITTED,
    advance,
    cuda,
    finish,
    flush_block,
    importance_draw,
    mul,
    plain_sample,
    push,
    stage2,
    trace_one,
    zero_block,
)

THREADS = 128
#: the hash of rayops.py this file's cached kernels were compiled with: numba checks only
#: this file's timestamp, so an edit of rayops.py must change this line (tests/test_rayops.py)
RAYOPS_SHA = "b0192603c2d0f7b6"
QUEUE = 2 * THREADS  # rays a block's queue holds (shared memory)
QUEUE_BLOCKS = 4096  # blocks of the queued kernels (each loops over tiles of THREADS rays)
WARP = 32
WARPS = THREADS // WARP  # warps per block
WARP_QUEUE = 2 * WARP  # rays a warp's queue holds
FULL_MASK = 0xFFFFFFFF
QUEUES = ("block", "warp", "none")  # the plain kernels: queued per block or warp, or not


@cuda.jit(cache=True)  # compiled once, kept between processes where numba-cuda can
def plain_kernel(
    first_id, n_rays, key, src, slabs, n_out, masks, lat, lim, fresnel,
    out, o_id, o_hrow, o_hk, count, ledger, n_launched,
):  # fmt: skip
    """Plain Lambertian samples first_id ... first_id + n_rays - 1 (see run_plain):
    samples outside |s| < n0 are not rays and not launched."""
    hrow = cuda.local.array((1, MAX_MASKS), np.int8)
    hk = cuda.local.array((1, MAX_MASKS), np.int32)
    led = cuda.shared.array((MAX_PLANES, 4), np.int64)
    launched = cuda.shared.array(1, np.int64)
    npl = slabs.shape[0]
    zero_block(led, launched, npl)
    i = cuda.grid(1)
    if i < n_rays:
        gid = first_id + i
        ok, xa, ya, a, c2 = plain_sample(key, gid, src)
        if ok:
            cuda.atomic.add(launched, 0, 1)
            st, pl, xe, ye, we = trace_one(
                xa, ya, a, c2, src[4], slabs, n_out, masks, lat, lim, fresnel, hrow, hk, 0
            )
            finish(st, pl, xe, ye, we, a, c2, gid, hrow, hk, 0, masks.shape[0], led, out,
                    o_id, o_hrow, o_hk, count)  # fmt: skip
    flush_block(led, launched, ledger, n_launched, npl)


@cuda.jit(cache=True)
def plain_queue_kernel(
    first_id, n_rays, key, src, slabs, n_out, masks, lat, lim, fresnel, n_pre,
    out, o_id, o_hrow, o_hk, count, ledger, n_launched,
):  # fmt: skip
    """:func:`plain_kernel`'s rays, traced in two stages with a queue per block.

    Each block takes tiles of THREADS samples (grid-stride). Every thread traces its
    sample through the slabs up to the first mask (stage 1); the few rays that pass it
    (about 2 % for the prototype) are put in the block's queue in shared memory. Whenever
    the queue holds THREADS rays, every thread takes one and traces the rest of the stack
    (stage 2), so the long traces run in full warps instead of one thread of a warp
    tracing while the others wait. Only shared-memory atomics and ``syncthreads``: it
    runs under numba's CUDA simulator, where it is checked ray for ray against the CPU.
    """
    hrow = cuda.local.array((1, MAX_MASKS), np.int8)
    hk = cuda.local.array((1, MAX_MASKS), np.int32)
    led = cuda.shared.array((MAX_PLANES, 4), np.int64)
    launched = cuda.shared.array(1, np.int64)
    qf = cuda.shared.array((QUEUE, 6), np.float64)  # x, y, sx, sy, ps, pp
    qid = cuda.shared.array(QUEUE, np.int64)
    qr = cuda.shared.array(QUEUE, np.int8)
    qk = cuda.shared.array(QUEUE, np.int32)
    qn = cuda.shared.array(1, np.int32)
    npl = slabs.shape[0]
    nm = masks.shape[0]
    m0 = int(slabs[n_pre - 1, 2])
    t = cuda.threadIdx.x
    if t == 0:
        qn[0] = 0
    zero_block(led, launched, npl)
    n_tiles = (n_rays + THREADS - 1) // THREADS
    for tile in range(cuda.blockIdx.x, n_tiles, cuda.gridDim.x):
        i = tile * THREADS + t
        if i < n_rays:
            gid = first_id + i
            ok, xa, ya, a, c2 = plain_sample(key, gid, src)
            if ok:
                cuda.atomic.add(launched, 0, 1)
                st, pl, xe, ye, ps, pp = advance(
                    xa, ya, a, c2, 1.0, 1.0, 0, n_pre, slabs, n_out, masks, lat, lim,
                    fresnel, hrow, hk, 0,
                )  # fmt: skip
                if st == ALIVE and n_pre < npl:
                    q = cuda.atomic.add(qn, 0, 1)
                    push(qf, qid, qr, qk, q, xe, ye, a, c2, ps, pp, gid, hrow[0, m0], hk[0, m0])
                else:
                    st = TRANSMITTED if st == ALIVE else st
                    finish(st, pl, xe, ye, src[4] * 0.5 * (ps + pp), a, c2, gid, hrow, hk, 0,
                            nm, led, out, o_id, o_hrow, o_hk, count)  # fmt: skip
        cuda.syncthreads()
        full = qn[0]
        if full >= THREADS:  # the same for every thread of the block
            stage2(full - THREADS + t, qf, qid, qr, qk, m0, n_pre, src[4], slabs, n_out,
                    masks, lat, lim, fresnel, hrow, hk, led, out, o_id, o_hrow, o_hk,
                    count)  # fmt: skip
            cuda.syncthreads()
            if t == 0:
                qn[0] = full - THREADS
        cuda.syncthreads()
    if t < qn[0]:  # what is left in the queue
        stage2(t, qf, qid, qr, qk, m0, n_pre, src[4], slabs, n_out, masks, lat, lim,
                fresnel, hrow, hk, led, out, o_id, o_hrow, o_hk, count)  # fmt: skip
    flush_block(led, launched, ledger, n_launched, npl)


@cuda.jit(cache=True)
def plain_warp_kernel(
    first_id, n_rays, key, src, slabs, n_out, masks, lat, lim, fresnel, n_pre,
    out, o_id, o_hrow, o_hk, count, ledger, n_launched,
):  # fmt: skip
    """:func:`plain_queue_kernel` with a queue per warp instead of per block: the rays that
    pass the first mask are placed with ``ballot_sync`` and ``popc`` (each lane's place
    is the number of passing lanes below it), and a warp traces the rest of the stack as
    soon as its own queue holds 32 rays, with no block-wide barrier. The simulator has no
    warp intrinsics: this kernel is checked on a GPU against the per-block one."""
    hrow = cuda.local.array((1, MAX_MASKS), np.int8)
    hk = cuda.local.array((1, MAX_MASKS), np.int32)
    led = cuda.shared.array((MAX_PLANES, 4), np.int64)
    launched = cuda.shared.array(1, np.int64)
    qf = cuda.shared.array((WARPS, WARP_QUEUE, 6), np.float64)  # x, y, sx, sy, ps, pp
    qid = cuda.shared.array((WARPS, WARP_QUEUE), np.int64)
    qr = cuda.shared.array((WARPS, WARP_QUEUE), np.int8)
    qk = cuda.shared.array((WARPS, WARP_QUEUE), np.int32)
    npl = slabs.shape[0]
    nm = masks.shape[0]
    m0 = int(slabs[n_pre - 1, 2])
    t = cuda.threadIdx.x
    wq = t // WARP
    lane = t % WARP
    qn = 0  # the warp's queue length: the same in every lane
    zero_block(led, launched, npl)
    n_tiles = (n_rays + THREADS - 1) // THREADS
    for tile in range(cuda.blockIdx.x, n_tiles, cuda.gridDim.x):
        i = tile * THREADS + t
        alive = False
        xe = ye = a = c2 = ps = pp = 0.0
        gid = first_id + i
        if i < n_rays:
            ok, xa, ya, a, c2 = plain_sample(key, gid, src)
            if ok:
                cuda.atomic.add(launched, 0, 1)
                st, pl, xe, ye, ps, pp = advance(
                    xa, ya, a, c2, 1.0, 1.0, 0, n_pre, slabs, n_out, masks, lat, lim,
                    fresnel, hrow, hk, 0,
                )  # fmt: skip
                alive = st == ALIVE and n_pre < npl
                if not alive:
                    st = TRANSMITTED if st == ALIVE else st
                    finish(st, pl, xe, ye, src[4] * 0.5 * (ps + pp), a, c2, gid, hrow, hk, 0,
                            nm, led, out, o_id, o_hrow, o_hk, count)  # fmt: skip
        ballot = cuda.ballot_sync(FULL_MASK, alive)
        if alive:
            q = qn + cuda.popc(ballot & cuda.lanemask_lt())
            push(qf[wq], qid[wq], qr[wq], qk[wq], q, xe, ye, a, c2, ps, pp, gid, hrow[0, m0],
                  hk[0, m0])  # fmt: skip
        qn += cuda.popc(ballot)
        cuda.syncwarp(FULL_MASK)
        if qn >= WARP:
            stage2(qn - WARP + lane, qf[wq], qid[wq], qr[wq], qk[wq], m0, n_pre, src[4],
                    slabs, n_out, masks, lat, lim, fresnel, hrow, hk, led, out, o_id, o_hrow,
                    o_hk, count)  # fmt: skip
            qn -= WARP
            cuda.syncwarp(FULL_MASK)
    if lane < qn:  # what is left in the warp's queue
        stage2(lane, qf[wq], qid[wq], qr[wq], qk[wq], m0, n_pre, src[4], slabs, n_out,
                masks, lat, lim, fresnel, hrow, hk, led, out, o_id, o_hrow, o_hk,
                count)  # fmt: skip
    flush_block(led, launched, ledger, n_launched, npl)


@cuda.jit(cache=True)
def importance_kernel(
    first_id, n_rays, key, src, slabs, n_out, masks, lat, lim, fresnel, n_pre,
    tgt_x, tgt_y, tgt_prob, tgt_alias, tgt_q,
    out, o_id, o_hrow, o_hk, count, ledger, n_launched,
):  # fmt: skip
    """Importance-sampled rays first_id ... first_id + n_rays - 1 (see run_importance)."""
    hrow = cuda.local.array((1, MAX_MASKS), np.int8)
    hk = cuda.local.array((1, MAX_MASKS), np.int32)
    led = cuda.shared.array((MAX_PLANES, 4), np.int64)
    launched = cuda.shared.array(1, np.int64)
    npl = slabs.shape[0]
    zero_block(led, launched, npl)
    i = cuda.grid(1)
    if i < n_rays:
        cuda.atomic.add(launched, 0, 1)
        gid = first_id + i
        m0 = int(slabs[n_pre - 1, 2])
        x0, y0, sx, sy, w = importance_draw(
            key, gid, src, slabs, n_pre, masks[m0, 1], masks[m0, 2], masks[m0, 0] == 1.0,
            tgt_x, tgt_y, tgt_prob, tgt_alias, tgt_q,
        )  # fmt: skip
        st, pl, xe, ye, we = trace_one(
            x0, y0, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, 0
        )
        finish(st, pl, xe, ye, we, sx, sy, gid, hrow, hk, 0, masks.shape[0], led, out,
                o_id, o_hrow, o_hk, count)  # fmt: skip
    flush_block(led, launched, ledger, n_launched, npl)


@cuda.jit(cache=True)
def accept_kernel(out, o_hrow, o_hk, n, s2_max, row, k, w_acc, own):
    """The pixel's angular response and own-path test of survivor i (device order):
    w_acc = w where |s|^2 <= s2_max else 0; own = 1 where every hole is (row, k)."""
    i = cuda.grid(1)
    if i < n:
        sx = out[i, 2]
        sy = out[i, 3]
        w_acc[i] = out[i, 4] if mul(sx, sx) + mul(sy, sy) <= s2_max else 0.0
        o = 1
        for m in range(o_hrow.shape[1]):
            if o_hrow[i, m] != row or o_hk[i, m] != k:
                o = 0
        own[i] = o


def blocks(n: int) -> int:
    """Blocks of :data:`THREADS` threads that cover ``n`` items (at least one)."""
    return max(1, (n + THREADS - 1) // THREADS)


class DeviceRays:
    """The survivors of one chunk, kept in device memory in the order threads appended
    them (``out`` columns x, y, sx, sy, w; ``ids``; ``hole_row``, ``hole_k``), with the
    chunk's ``ledger`` and ``n_launched`` on the host. :meth:`host` copies them back in
    ray order; device tallies read them where they are."""

    def __init__(self, n, out, ids, hole_row, hole_k, ledger, n_launched):
        self.n = int(n)
        self.out = out
        self.ids = ids
        self.hole_row = hole_row
        self.hole_k = hole_k
        self.ledger = ledger
        self.n_launched = int(n_launched)
        self._order = None

    def order(self) -> np.ndarray:
        """The permutation that puts device order into ray order (by id); computed once."""
        if self._order is None:
            ids = self.ids[: self.n].copy_to_host() if self.n else np.zeros(0, np.int64)
            self._order = np.argsort(ids, kind="stable")
        return self._order

    def to_host(self, a, order: np.ndarray) -> np.ndarray:
        """Device array ``a`` (survivors first) on the host, in ray order."""
        if self.n == 0:
            return np.zeros((0, *a.shape[1:]), a.dtype)
        return a[: self.n].copy_to_host()[order]

    def host(self) -> dict:
        """``ids, x, y, sx, sy, w, hole_row, hole_k`` in ray order, as the CPU's."""
        order = self.order()
        o = self.to_host(self.out, order)
        return {
            "ids": self.to_host(self.ids, order),
            "x": o[:, 0].copy(),
            "y": o[:, 1].copy(),
            "sx": o[:, 2].copy(),
            "sy": o[:, 3].copy(),
            "w": o[:, 4].copy(),
            "hole_row": self.to_host(self.hole_row, order),
            "hole_k": self.to_host(self.hole_k, order),
        }

    def accept(self, s2_max: float, row: int, k: int):
        """(w_acc, own) on the device: weights inside the acceptance cone and the
        own-path flags (int8) of pixel (row, k), in device order."""
        w_acc = cuda.device_array(max(self.n, 1), np.float64)
        own = cuda.device_array(max(self.n, 1), np.int8)
        if self.n:
            accept_kernel[blocks(self.n), THREADS](
                self.out, self.hole_row, self.hole_k, self.n, float(s2_max), int(row),
                int(k), w_acc, own,
            )  # fmt: skip
        return w_acc, own


def _compact(a, n: int):
    """The first ``n`` rows of device array ``a`` in an array of their own (the chunk's
    buffers, sized for every ray, are freed; a kept batch holds its survivors only)."""
    c = cuda.device_array((max(n, 1), *a.shape[1:]), a.dtype)
    if n:
        c[:n].copy_to_device(a[:n])
    return c


def run(
    first_id, n_rays, key, src, args, fresnel, n_pre, targets=None, queue: str = "block"
) -> DeviceRays:
    """Trace one chunk on the device; its survivors stay there (:class:`DeviceRays`).
    ``targets``: the alias table (importance sampling) or None (plain sampling);
    ``queue`` (plain sampling, one of :data:`QUEUES`): in two stages with a queue per
    block (:func:`plain_queue_kernel`) or per warp (:func:`plain_warp_kernel`, not under
    the simulator), or one thread per ray throughout (:func:`plain_kernel`); the same
    rays every way."""
    if queue not in QUEUES:
        raise ValueError(f"queue: must be one of {', '.join(QUEUES)} (got {queue!r})")
    if queue == "warp" and config.ENABLE_CUDASIM:
        raise ValueError("queue: warp needs warp intrinsics, which the CUDA simulator lacks")
    slabs, n_out, masks, lat, lim = args
    nm, npl = masks.shape[0], slabs.shape[0]
    if npl > MAX_PLANES or nm > MAX_MASKS:
        raise DeviceUnavailable(
            f"device cuda: the CUDA kernels trace at most {MAX_MASKS} masks and {MAX_PLANES} "
            f"planes (this stack has {nm} and {npl}); trace it with --device cpu"
        )
    d = cuda.to_device
    dargs = (d(slabs), float(n_out), d(masks), d(lat), d(lim), bool(fresnel))
    cap = n_rays  # survivors: at most one per ray
    out = cuda.device_array((cap, 5), np.float64)
    o_id = cuda.device_array(cap, np.int64)
    o_hrow = cuda.device_array((cap, nm), np.int8)
    o_hk = cuda.device_array((cap, nm), np.int32)
    count = d(np.zeros(1, np.int64))
    ledger = d(np.zeros((npl, 4), np.int64))
    launched = d(np.zeros(1, np.int64))
    common = (out, o_id, o_hrow, o_hk, count, ledger, launched)
    if targets is None and queue != "none":
        kernel = plain_queue_kernel if queue == "block" else plain_warp_kernel
        kernel[min(blocks(n_rays), QUEUE_BLOCKS), THREADS](
            first_id, n_rays, key, d(src), *dargs, int(n_pre), *common
        )
    elif targets is None:
        plain_kernel[blocks(n_rays), THREADS](first_id, n_rays, key, d(src), *dargs, *common)
    else:
        tg = targets
        importance_kernel[blocks(n_rays), THREADS](
            first_id, n_rays, key, d(src), *dargs, int(n_pre),
            d(tg.x), d(tg.y), d(tg.prob), d(tg.alias), d(tg.q_per_area), *common,
        )  # fmt: skip
    n = int(count.copy_to_host()[0])
    out, o_id, o_hrow, o_hk = (_compact(a, n) for a in (out, o_id, o_hrow, o_hk))
    return DeviceRays(
        n, out, o_id, o_hrow, o_hk, ledger.copy_to_host(), int(launched.copy_to_host()[0])
    )
