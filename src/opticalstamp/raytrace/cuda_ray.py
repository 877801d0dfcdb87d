"""One ray on a CUDA device (numba.cuda device functions): :mod:`.rayops`' per-ray
arithmetic, the CPU kernel's own source compiled for the device, and the plumbing that
the kernels of :mod:`.cuda` share (a survivor's output, the block's ledger, the queues).

The same counter-based draws, exact 3-D Snell propagation, hole tests on the full
staggered lattice and Fresnel factors as the CPU kernel, in float64, so a ray's fate is
the CPU's ray for ray. Every product that meets a sum is :func:`mul`, which the device
compiler cannot fuse into an FMA. Imported only where a CUDA device (or numba's CUDA
simulator) is used.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from .rayops import ABSORBED, ALIVE, ESCAPED, TIR, TRANSMITTED, compile_ops

__all__ = ["ABSORBED", "ALIVE", "ESCAPED", "TIR", "TRANSMITTED"]  # the fates, named here too


@contextmanager
def _row_stack_for_numba_cuda() -> Iterator[None]:
    """numba-cuda <= 0.30 names ``np.row_stack`` (gone in numpy 2.5) once, when its
    array module is imported: numpy lends it ``np.vstack`` under that name for that import
    only, and gets it back as it was on leaving (nothing is lent where numpy has it)."""
    lent = not hasattr(np, "row_stack")
    if lent:
        setattr(np, "row_stack", np.vstack)  # noqa: B010 - the one scoped module patch
    try:
        yield
    finally:
        if lent:
            delattr(np, "row_stack")


with _row_stack_for_numba_cuda():
    from numba import config, cuda
    from numba.cuda import libdevice

    # where numba-cuda names np.row_stack; imported here, not at its first compilation
    importlib.import_module("numba.cuda.np.arrayobj")

MAX_PLANES = 32  # the ledger's planes per block in shared memory
MAX_MASKS = 16  # a ray's holes, per thread in local memory


if config.ENABLE_CUDASIM:  # the simulator computes in Python: products are rounded

    @cuda.jit(device=True, inline=True)
    def mul(a, b):
        """a * b, rounded on its own (as on the CPU)."""
        return a * b

else:

    @cuda.jit(device=True, inline=True)
    def mul(a, b):
        """a * b, rounded on its own (as on the CPU): the device compiler fuses a product
        and a sum into one FMA, rounded once, unless the product is ``dmul_rn``."""
        return libdevice.dmul_rn(a, b)


#: one ray's arithmetic (:mod:`.rayops`), compiled for the device
OPS = compile_ops(cuda.jit(device=True), mul)
uniform_pair, hole, advance, trace_one = OPS.uniform_pair, OPS.hole, OPS.advance, OPS.trace_one
reach, solve_rho, plain_sample, importance_draw = (
    OPS.reach, OPS.solve_rho, OPS.plain_draw, OPS.importance_draw,
)  # fmt: skip


@cuda.jit(device=True)
def finish(st, pl, xe, ye, we, sx, sy, gid, hrow, hk, i, nm, led, out, o_id, o_hrow, o_hk, count):
    """Count the ray in the block's ledger; append a survivor to the outputs."""
    cuda.atomic.add(led, (pl, st), 1)
    if st == TRANSMITTED:
        slot = cuda.atomic.add(count, 0, 1)
        out[slot, 0] = xe
        out[slot, 1] = ye
        out[slot, 2] = sx
        out[slot, 3] = sy
        out[slot, 4] = we
        o_id[slot] = gid
        for m in range(nm):
            o_hrow[slot, m] = hrow[i, m]
            o_hk[slot, m] = hk[i, m]


@cuda.jit(device=True)
def flush_block(led, launched, ledger, n_launched, npl):
    """Add the block's shared ledger and launched count to the global ones."""
    cuda.syncthreads()
    t = cuda.threadIdx.x
    if t < npl * 4:
        v = led[t // 4, t % 4]
        if v:
            cuda.atomic.add(ledger, (t // 4, t % 4), v)
    if t == 0:
        cuda.atomic.add(n_launched, 0, launched[0])


@cuda.jit(device=True)
def zero_block(led, launched, npl):
    t = cuda.threadIdx.x
    if t < npl * 4:
        led[t // 4, t % 4] = 0
    if t == 0:
        launched[0] = 0
    cuda.syncthreads()


@cuda.jit(device=True)
def push(qf, qid, qr, qk, q, x, y, sx, sy, ps, pp, gid, r, k):
    """Put a ray that passed the first mask (its hole r, k) in place q of a queue."""
    qf[q, 0] = x
    qf[q, 1] = y
    qf[q, 2] = sx
    qf[q, 3] = sy
    qf[q, 4] = ps
    qf[q, 5] = pp
    qid[q] = gid
    qr[q] = r
    qk[q] = k


@cuda.jit(device=True)
def stage2(q, qf, qid, qr, qk, m0, n_pre, w0, slabs, n_out, masks, lat, lim, fresnel,
            hrow, hk, led, out, o_id, o_hrow, o_hk, count):  # fmt: skip
    """Trace queued ray ``q`` from slab n_pre to the end of the stack and finish it."""
    hrow[0, m0] = qr[q]
    hk[0, m0] = qk[q]
    sx = qf[q, 2]
    sy = qf[q, 3]
    st, pl, xe, ye, ps, pp = advance(
        qf[q, 0], qf[q, 1], sx, sy, qf[q, 4], qf[q, 5], n_pre, slabs.shape[0], slabs, n_out,
        masks, lat, lim, fresnel, hrow, hk, 0,
    )  # fmt: skip
    st = TRANSMITTED if st == ALIVE else st
    finish(st, pl, xe, ye, w0 * 0.5 * (ps + pp), sx, sy, qid[q], hrow, hk, 0,
            masks.shape[0], led, out, o_id, o_hrow, o_hk, count)  # fmt: skip
