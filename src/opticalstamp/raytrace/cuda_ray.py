"""One ray on a CUDA device (numba.cuda device functions): the arithmetic of
:mod:`.kernel`'s ``_trace_one``, its generator and its importance sampling, that the
kernels of :mod:`.cuda` run per thread.

The same counter-based draws (SplitMix64 of the seed key, the global ray index and a draw
counter), the same exact 3-D Snell propagation, hole tests on the full staggered lattice
and Fresnel factors as the CPU kernel, in float64, so a ray's fate is the CPU's ray for
ray. Every product that the CPU rounds on its own and that meets a sum is written
:func:`mul`, which the device compiler cannot fuse into an FMA. Imported only where a CUDA
device (or numba's CUDA simulator) is used.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np


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

TRANSMITTED, ABSORBED, TIR, ESCAPED = 0, 1, 2, 3
ALIVE = -1  # a ray that goes on (between the stages of the queued kernel)
MAX_PLANES = 32  # the ledger's planes per block in shared memory
MAX_MASKS = 16  # a ray's holes, per thread in local memory

_U32 = 2.0**-32
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S32 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(32)
_S33 = np.uint64(33)
_MASK32 = np.uint64(0xFFFFFFFF)
_MASK31 = np.uint64(0x7FFFFFFF)


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


@cuda.jit(device=True, inline=True)
def mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@cuda.jit(device=True, inline=True)
def uniform_pair(key, gid, draw):
    z = mix(key ^ (np.uint64(gid) * _GOLDEN + np.uint64(draw) * _M2))
    hi = np.float64(z >> _S32)
    lo = np.float64(z & _MASK32)
    return (hi + 0.5) * _U32, (lo + 0.5) * _U32


@cuda.jit(device=True, inline=True)
def centred(bits31):
    return mul(np.float64(bits31) + 0.5, 2.0**-31) - 0.5


@cuda.jit(device=True)
def hole(x, y, masks, m, lat):
    p = lat[0]
    ip = 1.0 / p
    ox = masks[m, 3]
    oy = masks[m, 4]
    hw = masks[m, 1]
    hh = masks[m, 2]
    circ = masks[m, 0] == 1.0
    for r in range(int(lat[3])):
        x0 = lat[4 + 2 * r] + ox
        k = math.floor(mul(x - x0, ip) + 0.5)
        if k < lat[1] or k > lat[2]:
            continue
        dx = x - (x0 + mul(k, p))
        dy = y - (lat[5 + 2 * r] + oy)
        if circ:
            if mul(dx, dx) + mul(dy, dy) <= hw * hw:
                return r, int(k)
        elif abs(dx) <= hw and abs(dy) <= hh:
            return r, int(k)
    return -1, 0


@cuda.jit(device=True)
def advance(x, y, sx, sy, ps, pp, i0, i1, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, slot):
    """Slabs i0 ... i1 - 1 of :func:`opticalstamp.raytrace.kernel._trace_one`: (status,
    plane, x, y, ps, pp), status ALIVE where the ray goes on past slab i1 - 1; ps, pp:
    the products of the s and p Fresnel transmissions so far."""
    s2 = mul(sx, sx) + mul(sy, sy)
    n_sl = slabs.shape[0]
    for i in range(i0, i1):
        d = slabs[i, 0]
        n = slabs[i, 1]
        c = math.sqrt(mul(n, n) - s2)
        x += d * sx / c
        y += d * sy / c
        if abs(x) > lim[0] or abs(y) > lim[1]:
            return ESCAPED, i, x, y, ps, pp
        m = int(slabs[i, 2])
        if m >= 0:
            r, k = hole(x, y, masks, m, lat)
            if r < 0:
                return ABSORBED, i, x, y, ps, pp
            hrow[slot, m] = r
            hk[slot, m] = k
        n2 = slabs[i + 1, 1] if i + 1 < n_sl else n_out
        if n2 != n:
            c2sq = mul(n2, n2) - s2
            if c2sq <= 0.0:
                return TIR, i, x, y, ps, pp
            if fresnel:
                c1 = c / n
                cc2 = math.sqrt(c2sq) / n2
                a = mul(n, c1)
                b = mul(n2, cc2)
                rs = (a - b) / (a + b)
                a2 = mul(n2, c1)
                b2 = mul(n, cc2)
                rp = (a2 - b2) / (a2 + b2)
                ps = mul(ps, 1.0 - mul(rs, rs))
                pp = mul(pp, 1.0 - mul(rp, rp))
    return ALIVE, i1 - 1, x, y, ps, pp


@cuda.jit(device=True)
def trace_one(x, y, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, slot):
    """As :func:`opticalstamp.raytrace.kernel._trace_one` (status, plane, x, y, weight)."""
    n_sl = slabs.shape[0]
    st, pl, x, y, ps, pp = advance(
        x, y, sx, sy, 1.0, 1.0, 0, n_sl, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, slot
    )
    return (TRANSMITTED if st == ALIVE else st), pl, x, y, w * 0.5 * (ps + pp)


@cuda.jit(device=True)
def reach(rho, slabs, n_pre):
    dr = 0.0
    dd = 0.0
    for i in range(n_pre):
        n2 = mul(slabs[i, 1], slabs[i, 1])
        c2 = n2 - mul(rho, rho)
        c = math.sqrt(c2)
        dr += slabs[i, 0] / c
        dd += slabs[i, 0] * n2 / (c2 * c)
    return mul(rho, dr), dd, dr


@cuda.jit(device=True)
def solve_rho(r, slabs, n_pre, n_min, d_eq):
    if r <= 0.0:
        return 0.0
    rho = n_min * r / math.sqrt(mul(d_eq, d_eq) + mul(r, r))
    for _ in range(60):
        f, fp, _q = reach(rho, slabs, n_pre)
        step = (f - r) / fp
        new = rho - step
        if new >= n_min:
            new = mul(0.5, rho + n_min)
        elif new <= 0.0:
            new = mul(0.5, rho)
        if abs(new - rho) <= 1e-15 * n_min:
            return new
        rho = new
    return rho


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
def plain_sample(key, gid, src):
    """Sample ``gid`` of plain Lambertian sampling: (is a ray, x, y, sx, sy)."""
    g = np.uint64(gid) * _GOLDEN
    z0 = mix(key ^ g)
    z1 = mix(key ^ (g + _M2))
    n0 = src[5]
    xa = src[0] + mul(centred(z0 >> _S33), src[2])
    ya = src[1] + mul(centred(z0 & _MASK31), src[3])
    a = 2.0 * n0 * centred(z1 >> _S33)
    c2 = 2.0 * n0 * centred(z1 & _MASK31)
    return mul(a, a) + mul(c2, c2) < n0 * n0, xa, ya, a, c2


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
