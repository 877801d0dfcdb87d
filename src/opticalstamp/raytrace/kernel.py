"""The ray kernel (numba): exact 3-D tracing through a stack of slabs and absorbing masks.

The Python driver that launches rays in chunks is :mod:`opticalstamp.raytrace.launch`.

Rays are described in phase space by their position (x, y) on a plane and their
*invariant direction* s = n (sin(theta) cos(phi), sin(theta) sin(phi)), which Snell's law
keeps constant across planar interfaces normal to z (the vector form of Snell's law for
a z-normal interface changes only the z component). In slab i the ray advances laterally
by d_i s / sqrt(n_i^2 - |s|^2); where |s| >= n_i the ray is totally internally reflected
and killed. The etendue measure is dx dy dsx dsy, so a Lambertian emitter in a medium of
index n fills the disk |s| <= n uniformly (paper Fig. 4's virtual light source).

Hole membership is arithmetic on the periodic staggered lattice over the full array
(k = round((x - x_row - offset) / pitch), then a test against that one hole), so holes
many pitches away are found at grazing angles.

Random numbers come from a counter-based generator (a SplitMix64 hash of the seed, the
global ray index and a draw counter), so a ray's fate depends only on (seed, ray index):
results are identical for any chunk size or thread count.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..validate import check_seed
from .rayops import ABSORBED, ESCAPED, TIR, TRANSMITTED, compile_ops

__all__ = ["ABSORBED", "ESCAPED", "TIR", "TRANSMITTED"]  # the fates, named here too

STATUS_NAMES = ("transmitted", "absorbed", "tir", "escaped")
#: the hash of rayops.py this file's cached kernels were compiled with: numba checks only
#: this file's timestamp, so an edit of rayops.py must change this line (tests/test_rayops.py)
RAYOPS_SHA = "b0192603c2d0f7b6"

_JIT = dict(cache=True, nogil=True, error_model="numpy")


@nb.njit(inline="always", nogil=True, error_model="numpy")
def _mul(a, b):
    """a * b: numba rounds a product on its own unless fastmath allows a contraction."""
    return a * b


#: one ray's arithmetic (:mod:`.rayops`), compiled for the CPU and inlined into the kernels
OPS = compile_ops(nb.njit(inline="always", nogil=True, error_model="numpy"), _mul)
_trace_one, _plain_draw, _importance_draw = OPS.trace_one, OPS.plain_draw, OPS.importance_draw


def seed_key(seed: int, stream: int = 0) -> np.uint64:
    """The generator key for ``seed`` (an integer in [0, 2^63 - 1]) and a ``stream``."""
    check_seed(seed)
    z = (int(seed) * 0x9E3779B97F4A7C15 + int(stream) * 0xD1B54A32D192ED03 + 1) % 2**64
    for _ in range(2):
        z ^= z >> 30
        z = z * 0xBF58476D1CE4E5B9 % 2**64
        z ^= z >> 27
        z = z * 0x94D049BB133111EB % 2**64
        z ^= z >> 31
    return np.uint64(z)


@nb.njit(**_JIT)
def trace_bundle(x, y, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, status, plane, hrow, hk):
    for j in nb.prange(x.size):
        st, pl, xo, yo, wo = _trace_one(
            x[j], y[j], sx[j], sy[j], w[j], slabs, n_out, masks, lat, lim, fresnel, hrow, hk, j
        )
        status[j] = st
        plane[j] = pl
        x[j] = xo
        y[j] = yo
        w[j] = wo


#: Public names of the generator and the Fresnel helper for other compiled kernels
#: (the rod-lens tracer): one generator, so every tracer is seeded the same way.
uniform_pair = OPS.uniform_pair
fresnel_sp = OPS.fresnel_sp


@nb.njit(inline="always", **_JIT)
def _commit(st, xe, ye, sx, sy, we, gid, slot, o_x, o_y, o_sx, o_sy, o_w, o_id):
    """Store a transmitted ray in ``slot``; return 1 if stored."""
    if st != TRANSMITTED:
        return 0
    o_x[slot] = xe
    o_y[slot] = ye
    o_sx[slot] = sx
    o_sy[slot] = sy
    o_w[slot] = we
    o_id[slot] = gid
    return 1


@nb.njit(parallel=True, **_JIT)
def run_importance(
    first_id,
    n_rays,
    block,
    key,
    src,
    slabs,
    n_out,
    masks,
    lat,
    lim,
    fresnel,
    n_pre,
    tgt_x,
    tgt_y,
    tgt_prob,
    tgt_alias,
    tgt_q,
    o_x,
    o_y,
    o_sx,
    o_sy,
    o_w,
    o_id,
    o_hrow,
    o_hk,
    counts,
    ledger,
):
    """Importance-sampled launch of rays first_id ... first_id + n_rays - 1.

    src = [cx, cy, ax, ay, w0, n0, n_min, d_eq]: a rectangle ax x ay centred at (cx, cy)
    (a point if ax = ay = 0) emitting Lambertian light into the medium of index n0; w0 is
    pi n0^2 A (etendue of the area) or 1 (a point). The direction is chosen by picking a
    hole of the first mask from the alias table (tgt_*), a uniform point in it, and the
    ray joining the two points; the weight w0 / (pdf(s) pi n0^2) with
    pdf(s) = tgt_q |J| (tgt_q: pick probability per unit hole area, J = d(x_t)/d(s)).
    Survivors are written, in ray order, at b * block + (0 ... counts[b] - 1).
    """
    n_blocks = (n_rays + block - 1) // block
    m0 = int(slabs[n_pre - 1, 2])
    hw = masks[m0, 1]
    hh = masks[m0, 2]
    circ = masks[m0, 0] == 1.0
    for b in nb.prange(n_blocks):
        start = b * block
        stop = min(start + block, n_rays)
        c = 0
        led = np.zeros((ledger.shape[1], 4), np.int64)
        for j in range(start, stop):
            gid = first_id + j
            x0, y0, sx, sy, w = _importance_draw(
                key, gid, src, slabs, n_pre, hw, hh, circ, tgt_x, tgt_y, tgt_prob, tgt_alias,
                tgt_q,
            )  # fmt: skip
            slot = start + c
            st, pl, xe, ye, we = _trace_one(
                x0, y0, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, o_hrow, o_hk, slot
            )
            led[pl, st] += 1
            c += _commit(st, xe, ye, sx, sy, we, gid, slot, o_x, o_y, o_sx, o_sy, o_w, o_id)
        counts[b] = c
        ledger[b] = led


@nb.njit(parallel=True, fastmath=True, **_JIT)
def run_plain(
    first_id,
    n_rays,
    block,
    n_workers,
    key,
    src,
    slabs,
    n_out,
    masks,
    lat,
    lim,
    fresnel,
    n_pre,
    o_x,
    o_y,
    o_sx,
    o_sy,
    o_w,
    o_id,
    o_hrow,
    o_hk,
    counts,
    launched,
    ledger,
):
    """Plain Lambertian launch of samples first_id ... first_id + n_rays - 1.

    Each sample draws a position on the source and s uniformly in the square
    [-n0, n0]^2; samples outside the disk |s| < n0 are not rays (rejection sampling of
    the Lambertian law) and are not counted as launched. A block is processed in
    vectorisable stages: draw, propagate to the first mask, hole test; only rays that
    pass the first mask (or stop before it) are traced in full.
    """
    n_blocks = (n_rays + block - 1) // block
    n0 = src[5]
    m0 = int(slabs[n_pre - 1, 2])
    ox = masks[m0, 3]
    oy = masks[m0, 4]
    hw = masks[m0, 1]
    hh = masks[m0, 2]
    circ = masks[m0, 0] == 1.0
    ip = 1.0 / lat[0]
    p = lat[0]
    klo = lat[1]
    khi = lat[2]
    rect = not circ
    hw2 = hw * hw
    # row B (absent in a one-row lattice: a hole of negative size never contains a point)
    hwb = hw if lat[3] == 2 else -1.0
    hw2b = hw2 if lat[3] == 2 else -1.0
    xa0 = lat[4] + ox
    ya0 = lat[5] + oy
    xb0 = lat[6] + ox
    yb0 = lat[7] + oy
    n0sq = n0 * n0
    n_workers = min(n_blocks, n_workers)
    for wk in nb.prange(n_workers):
        # scratch allocated once per worker; blocks wk, wk + n_workers, ... are its work
        x0 = np.empty(block)
        y0 = np.empty(block)
        sx = np.empty(block)
        sy = np.empty(block)
        xt = np.empty(block)
        yt = np.empty(block)
        ok = np.empty(block, np.bool_)
        led = np.zeros((ledger.shape[1], 4), np.int64)
        for b in range(wk, n_blocks, n_workers):
            start = b * block
            m = min(start + block, n_rays) - start
            # draws: hash 0 -> source position, hash 1 -> direction (31 bits per uniform)
            d0 = slabs[0, 0]
            for j in range(m):
                okj, xa, ya, a, c2 = _plain_draw(key, first_id + start + j, src)
                s2 = a * a + c2 * c2
                ok[j] = okj
                g = d0 / math.sqrt(max(n0sq - s2, 1e-300))
                x0[j] = xa
                y0[j] = ya
                sx[j] = a
                sy[j] = c2
                xt[j] = xa + g * a
                yt[j] = ya + g * c2
            for i in range(1, n_pre):
                d = slabs[i, 0]
                n2 = slabs[i, 1] * slabs[i, 1]
                for j in range(m):
                    s2 = sx[j] * sx[j] + sy[j] * sy[j]
                    g = d / math.sqrt(max(n2 - s2, 1e-300))
                    xt[j] += g * sx[j]
                    yt[j] += g * sy[j]
            npass = 0
            nok = 0
            for j in range(m):
                k = math.floor((xt[j] - xa0) * ip + 0.5)
                dx = xt[j] - (xa0 + k * p)
                dy = yt[j] - ya0
                ina = ((abs(dx) <= hw) & (abs(dy) <= hh) & rect) | (
                    (dx * dx + dy * dy <= hw2) & circ
                )
                ina &= (k >= klo) & (k <= khi)
                k = math.floor((xt[j] - xb0) * ip + 0.5)
                dx = xt[j] - (xb0 + k * p)
                dy = yt[j] - yb0
                inb = ((abs(dx) <= hwb) & (abs(dy) <= hh) & rect) | (
                    (dx * dx + dy * dy <= hw2b) & circ
                )
                inb &= (k >= klo) & (k <= khi)
                far = (abs(xt[j]) > lim[0]) | (abs(yt[j]) > lim[1])
                okj = ok[j]
                nok += okj
                okj = okj & (ina | inb | far)
                ok[j] = okj
                npass += okj
            c = 0
            led[:] = 0
            led[n_pre - 1, ABSORBED] = nok - npass
            if npass > 0:
                for j in range(m):
                    if ok[j]:
                        slot = start + c
                        st, pl, xe, ye, we = _trace_one(
                            x0[j],
                            y0[j],
                            sx[j],
                            sy[j],
                            src[4],
                            slabs,
                            n_out,
                            masks,
                            lat,
                            lim,
                            fresnel,
                            o_hrow,
                            o_hk,
                            slot,
                        )
                        led[pl, st] += 1
                        c += _commit(
                            st,
                            xe,
                            ye,
                            sx[j],
                            sy[j],
                            we,
                            first_id + start + j,
                            slot,
                            o_x,
                            o_y,
                            o_sx,
                            o_sy,
                            o_w,
                            o_id,
                        )
            counts[b] = c
            launched[b] = nok
            ledger[b] = led
