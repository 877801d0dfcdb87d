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

TRANSMITTED, ABSORBED, TIR, ESCAPED = 0, 1, 2, 3
STATUS_NAMES = ("transmitted", "absorbed", "tir", "escaped")

_U32 = 2.0**-32
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S32 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(32)
_MASK32 = np.uint64(0xFFFFFFFF)

_JIT = dict(cache=True, nogil=True, error_model="numpy")


@nb.njit(inline="always", **_JIT)
def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@nb.njit(inline="always", **_JIT)
def _uniform_pair(key, gid, draw):
    """Two independent uniforms in (0, 1) for draw ``draw`` of ray ``gid``."""
    z = _mix(key ^ (np.uint64(gid) * _GOLDEN + np.uint64(draw) * _M2))
    hi = np.float64(z >> _S32)
    lo = np.float64(z & _MASK32)
    return (hi + 0.5) * _U32, (lo + 0.5) * _U32


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


@nb.njit(inline="always", **_JIT)
def _hole(x, y, masks, m, lat):
    """(row, k) of the hole of mask ``m`` containing (x, y), or (-1, 0) if blocked."""
    p = lat[0]
    ip = 1.0 / p
    ox = masks[m, 3]
    oy = masks[m, 4]
    hw = masks[m, 1]
    hh = masks[m, 2]
    circ = masks[m, 0] == 1.0
    for r in range(int(lat[3])):
        x0 = lat[4 + 2 * r] + ox
        k = math.floor((x - x0) * ip + 0.5)
        if k < lat[1] or k > lat[2]:
            continue
        dx = x - (x0 + k * p)
        dy = y - (lat[5 + 2 * r] + oy)
        if circ:
            if dx * dx + dy * dy <= hw * hw:
                return r, int(k)
        elif abs(dx) <= hw and abs(dy) <= hh:
            return r, int(k)
    return -1, 0


@nb.njit(inline="always", **_JIT)
def _fresnel_sp(n1, n2, c1, c2):
    """Fresnel power transmittances (Ts, Tp) of one interface; c1, c2 = cos of the angles.

    Parameters
    ----------
    n1, n2 : float, refractive indices before and after the interface
    c1, c2 : float, cosines of the angles of incidence and refraction

    Returns
    -------
    ts, tp : float, 1 - r^2 for s and p polarisation (energy conservation)
    """
    a = n1 * c1
    b = n2 * c2
    rs = (a - b) / (a + b)
    a2 = n2 * c1
    b2 = n1 * c2
    rp = (a2 - b2) / (a2 + b2)
    return 1.0 - rs * rs, 1.0 - rp * rp


@nb.njit(inline="always", **_JIT)
def _trace_one(x, y, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, slot):
    """Trace one ray through ``slabs``; write hole (row, k) per mask into hrow/hk[slot].

    With ``fresnel`` the returned weight carries the unpolarised transmittance of the
    whole stack, (prod Ts + prod Tp) / 2: planar parallel interfaces keep the plane of
    incidence, so s and p never mix and each polarisation's transmittances multiply.
    Rays that stop early return their weight with the losses of the interfaces crossed.

    Returns status, plane (exit plane index where it stopped), x, y, weight.
    """
    s2 = sx * sx + sy * sy
    ps = 1.0
    pp = 1.0
    n_sl = slabs.shape[0]
    for i in range(n_sl):
        d = slabs[i, 0]
        n = slabs[i, 1]
        c = math.sqrt(n * n - s2)
        x += d * sx / c
        y += d * sy / c
        if abs(x) > lim[0] or abs(y) > lim[1]:
            return ESCAPED, i, x, y, w * 0.5 * (ps + pp)
        m = int(slabs[i, 2])
        if m >= 0:
            r, k = _hole(x, y, masks, m, lat)
            if r < 0:
                return ABSORBED, i, x, y, w * 0.5 * (ps + pp)
            hrow[slot, m] = r
            hk[slot, m] = k
        n2 = slabs[i + 1, 1] if i + 1 < n_sl else n_out
        if n2 != n:
            c2sq = n2 * n2 - s2
            if c2sq <= 0.0:
                return TIR, i, x, y, w * 0.5 * (ps + pp)
            if fresnel:
                ts, tp = _fresnel_sp(n, n2, c / n, math.sqrt(c2sq) / n2)
                ps *= ts
                pp *= tp
    return TRANSMITTED, n_sl - 1, x, y, w * 0.5 * (ps + pp)


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
uniform_pair = _uniform_pair
fresnel_sp = _fresnel_sp


# -- importance sampling: the direction that joins two points through layered slabs ------
@nb.njit(inline="always", **_JIT)
def _reach(rho, slabs, n_pre):
    """D(rho) = sum d_i rho / c_i, D'(rho), and D(rho)/rho for the first n_pre slabs."""
    dr = 0.0
    dd = 0.0
    for i in range(n_pre):
        n2 = slabs[i, 1] * slabs[i, 1]
        c2 = n2 - rho * rho
        c = math.sqrt(c2)
        dr += slabs[i, 0] / c
        dd += slabs[i, 0] * n2 / (c2 * c)
    return rho * dr, dd, dr


@nb.njit(inline="always", **_JIT)
def _solve_rho(r, slabs, n_pre, n_min, d_eq):
    """|s| that carries a ray a lateral distance r across the first n_pre slabs."""
    if r <= 0.0:
        return 0.0
    rho = n_min * r / math.sqrt(d_eq * d_eq + r * r)
    for _ in range(60):
        f, fp, _q = _reach(rho, slabs, n_pre)
        step = (f - r) / fp
        new = rho - step
        if new >= n_min:
            new = 0.5 * (rho + n_min)
        elif new <= 0.0:
            new = 0.5 * rho
        if abs(new - rho) <= 1e-15 * n_min:
            return new
        rho = new
    return rho


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
    nt = tgt_prob.size
    for b in nb.prange(n_blocks):
        start = b * block
        stop = min(start + block, n_rays)
        c = 0
        led = np.zeros((ledger.shape[1], 4), np.int64)
        for j in range(start, stop):
            gid = first_id + j
            u1, u2 = _uniform_pair(key, gid, 0)
            x0 = src[0] + (u1 - 0.5) * src[2]
            y0 = src[1] + (u2 - 0.5) * src[3]
            u3, u4 = _uniform_pair(key, gid, 1)
            t = min(int(u3 * nt), nt - 1)
            if u4 >= tgt_prob[t]:
                t = tgt_alias[t]
            u5, u6 = _uniform_pair(key, gid, 2)
            if circ:
                rr = hw * math.sqrt(u5)
                ph = 2.0 * math.pi * u6
                xt = tgt_x[t] + rr * math.cos(ph)
                yt = tgt_y[t] + rr * math.sin(ph)
            else:
                xt = tgt_x[t] + (2.0 * u5 - 1.0) * hw
                yt = tgt_y[t] + (2.0 * u6 - 1.0) * hh
            dx = xt - x0
            dy = yt - y0
            r = math.sqrt(dx * dx + dy * dy)
            rho = _solve_rho(r, slabs, n_pre, src[6], src[7])
            f, fp, q = _reach(rho, slabs, n_pre)
            sx = rho * dx / r if r > 0.0 else 0.0
            sy = rho * dy / r if r > 0.0 else 0.0
            w = src[4] / (tgt_q[t] * fp * q * math.pi * src[5] * src[5])
            slot = start + c
            st, pl, xe, ye, we = _trace_one(
                x0, y0, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, o_hrow, o_hk, slot
            )
            led[pl, st] += 1
            c += _commit(st, xe, ye, sx, sy, we, gid, slot, o_x, o_y, o_sx, o_sy, o_w, o_id)
        counts[b] = c
        ledger[b] = led


_S33 = np.uint64(33)
_MASK31 = np.uint64(0x7FFFFFFF)


@nb.njit(inline="always", **_JIT)
def _centred(bits31):
    """A uniform in (-1/2, 1/2) from 31 random bits (int32 conversion vectorises)."""
    return (np.float64(np.int32(bits31)) + 0.5) * 2.0**-31 - 0.5


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
                gid = np.uint64(first_id + start + j) * _GOLDEN
                z0 = _mix(key ^ gid)
                z1 = _mix(key ^ (gid + _M2))
                xa = src[0] + _centred(z0 >> _S33) * src[2]
                ya = src[1] + _centred(z0 & _MASK31) * src[3]
                a = 2.0 * n0 * _centred(z1 >> _S33)
                c2 = 2.0 * n0 * _centred(z1 & _MASK31)
                s2 = a * a + c2 * c2
                ok[j] = s2 < n0sq
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
