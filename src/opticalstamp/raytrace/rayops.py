"""One ray's arithmetic, written once and compiled twice.

The counter-based draws (SplitMix64 of the seed key, the global ray index and a draw
counter), the hole test on the full staggered lattice, the Fresnel transmittances, the
exact 3-D Snell propagation through a stack of slabs and masks, the Newton solve for the
direction that joins two points across layered slabs, and the plain and importance
draws of a ray: :func:`compile_ops` compiles them with the compiler it is given, numba's
``njit`` for the CPU kernels (:mod:`.kernel`, inlined into them) and numba.cuda's device
``jit`` for the GPU kernels (:mod:`.cuda_ray`, :mod:`.cuda`). One code path under two
compilers, so that a ray's fate is the same on either device ray for ray.

Every product that meets a sum is written ``mul(a, b)``: on the CPU a plain product
(numba does not contract products into FMAs unless asked: the plain kernel, ``run_plain``,
is compiled with fastmath and may fuse them, so its rays agree with the GPU's to rounding,
the importance kernel's exactly), on a GPU one that the device compiler cannot fuse into
an FMA (``dmul_rn``), so that both round it on its own.

numba caches the kernels that inline these functions by their own files' timestamps
(:mod:`.kernel`, :mod:`.cuda`), not this one's: each of those files carries this file's
hash (``RAYOPS_SHA``), which tests/test_rayops.py checks, so that an edit here has to
touch them too and their cached kernels are compiled again.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

TRANSMITTED, ABSORBED, TIR, ESCAPED = 0, 1, 2, 3
ALIVE = -1  # a ray that goes on (between the stages of a queued kernel)

_U32 = 2.0**-32
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S32 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(32)
_S33 = np.uint64(33)
_MASK32 = np.uint64(0xFFFFFFFF)
_MASK31 = np.uint64(0x7FFFFFFF)


class RayOps(NamedTuple):
    """The per-ray functions, compiled for one device (:func:`compile_ops`)."""

    mix: object
    uniform_pair: object
    centred: object
    hole: object
    fresnel_sp: object
    advance: object
    trace_one: object
    reach: object
    solve_rho: object
    plain_draw: object
    importance_draw: object


def compile_ops(jit, mul) -> RayOps:  # noqa: C901 - one closure per per-ray function
    """The per-ray functions compiled by ``jit`` (a decorator: numba.njit with its
    options, or numba.cuda.jit(device=True)); ``mul(a, b)``, compiled by the same, is a
    product rounded on its own."""

    @jit
    def mix(z):
        """SplitMix64's finaliser."""
        z = (z ^ (z >> _S30)) * _M1
        z = (z ^ (z >> _S27)) * _M2
        return z ^ (z >> _S31)

    @jit
    def uniform_pair(key, gid, draw):
        """Two independent uniforms in (0, 1) for draw ``draw`` of ray ``gid``."""
        z = mix(key ^ (np.uint64(gid) * _GOLDEN + np.uint64(draw) * _M2))
        hi = np.float64(z >> _S32)
        lo = np.float64(z & _MASK32)
        return (hi + 0.5) * _U32, (lo + 0.5) * _U32

    @jit
    def centred(bits31):
        """A uniform in (-1/2, 1/2) from 31 random bits (int32 conversion vectorises)."""
        return mul(np.float64(np.int32(bits31)) + 0.5, 2.0**-31) - 0.5

    @jit
    def hole(x, y, masks, m, lat):
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

    @jit
    def fresnel_sp(n1, n2, c1, c2):
        """Fresnel power transmittances (Ts, Tp) = 1 - r^2 of one interface between
        indices n1 and n2; c1, c2: the cosines of the angles of incidence and
        refraction."""
        a = mul(n1, c1)
        b = mul(n2, c2)
        rs = (a - b) / (a + b)
        a2 = mul(n2, c1)
        b2 = mul(n1, c2)
        rp = (a2 - b2) / (a2 + b2)
        return 1.0 - mul(rs, rs), 1.0 - mul(rp, rp)

    @jit
    def advance(
        x, y, sx, sy, ps, pp, i0, i1, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, slot
    ):
        """Slabs i0 ... i1 - 1 of the stack: (status, plane, x, y, ps, pp), status ALIVE
        where the ray goes on past slab i1 - 1; the hole (row, k) of each mask met is
        written to hrow/hk[slot]. ps, pp: the products of the s and p Fresnel
        transmittances so far (planar parallel interfaces keep the plane of incidence:
        s and p never mix)."""
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
                    ts, tp = fresnel_sp(n, n2, c / n, math.sqrt(c2sq) / n2)
                    ps = mul(ps, ts)
                    pp = mul(pp, tp)
        return ALIVE, i1 - 1, x, y, ps, pp

    @jit
    def trace_one(x, y, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, slot):
        """Trace one ray through every slab: (status, plane, x, y, weight); the weight
        carries the unpolarised transmittance (prod Ts + prod Tp) / 2 of the interfaces
        crossed (with ``fresnel``)."""
        st, pl, x, y, ps, pp = advance(
            x, y, sx, sy, 1.0, 1.0, 0, slabs.shape[0], slabs, n_out, masks, lat, lim,
            fresnel, hrow, hk, slot,
        )  # fmt: skip
        return (TRANSMITTED if st == ALIVE else st), pl, x, y, w * 0.5 * (ps + pp)

    @jit
    def reach(rho, slabs, n_pre):
        """D(rho) = sum d_i rho / c_i, D'(rho), and D(rho)/rho for the first n_pre slabs."""
        dr = 0.0
        dd = 0.0
        for i in range(n_pre):
            n2 = mul(slabs[i, 1], slabs[i, 1])
            c2 = n2 - mul(rho, rho)
            c = math.sqrt(c2)
            dr += slabs[i, 0] / c
            dd += slabs[i, 0] * n2 / (c2 * c)
        return mul(rho, dr), dd, dr

    @jit
    def solve_rho(r, slabs, n_pre, n_min, d_eq):
        """|s| that carries a ray a lateral distance r across the first n_pre slabs
        (Newton's method, kept inside (0, n_min))."""
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

    @jit
    def plain_draw(key, gid, src):
        """Sample ``gid`` of plain Lambertian sampling from the source
        src = [cx, cy, ax, ay, w0, n0, ...]: (is a ray, x, y, sx, sy), a position on the
        rectangle and s uniform in the square [-n0, n0]^2 (a ray where |s| < n0)."""
        g = np.uint64(gid) * _GOLDEN
        z0 = mix(key ^ g)
        z1 = mix(key ^ (g + _M2))
        n0 = src[5]
        xa = src[0] + mul(centred(z0 >> _S33), src[2])
        ya = src[1] + mul(centred(z0 & _MASK31), src[3])
        a = 2.0 * n0 * centred(z1 >> _S33)
        c2 = 2.0 * n0 * centred(z1 & _MASK31)
        return mul(a, a) + mul(c2, c2) < n0 * n0, xa, ya, a, c2

    @jit
    def importance_draw(
        key, gid, src, slabs, n_pre, hole_w, hole_h, circ, tgt_x, tgt_y, tgt_prob, tgt_alias,
        tgt_q,
    ):  # fmt: skip
        """Ray ``gid`` of importance sampling: (x, y, sx, sy, w). A point on the source
        rectangle, a hole of the first mask from the alias table (tgt_*), a uniform
        point in it, and the direction that joins the two (:func:`solve_rho`); the
        weight w0 / (pdf(s) pi n0^2), pdf(s) = tgt_q |J|, J = d(x_t)/d(s). hole_w, hole_h,
        circ: the first mask's hole half sizes and whether it is a circle (the caller's, once
        a kernel: the CPU's loop does not read them again ray by ray)."""
        hw = hole_w
        hh = hole_h
        nt = tgt_prob.size
        u1, u2 = uniform_pair(key, gid, 0)
        x0 = src[0] + mul(u1 - 0.5, src[2])
        y0 = src[1] + mul(u2 - 0.5, src[3])
        u3, u4 = uniform_pair(key, gid, 1)
        t = min(int(u3 * nt), nt - 1)
        if u4 >= tgt_prob[t]:
            t = tgt_alias[t]
        u5, u6 = uniform_pair(key, gid, 2)
        if circ:
            rr = hw * math.sqrt(u5)
            ph = 2.0 * math.pi * u6
            xt = tgt_x[t] + mul(rr, math.cos(ph))
            yt = tgt_y[t] + mul(rr, math.sin(ph))
        else:
            xt = tgt_x[t] + mul(mul(2.0, u5) - 1.0, hw)
            yt = tgt_y[t] + mul(mul(2.0, u6) - 1.0, hh)
        dx = xt - x0
        dy = yt - y0
        r = math.sqrt(mul(dx, dx) + mul(dy, dy))
        rho = solve_rho(r, slabs, n_pre, src[6], src[7])
        f, fp, q = reach(rho, slabs, n_pre)
        sx = rho * dx / r if r > 0.0 else 0.0
        sy = rho * dy / r if r > 0.0 else 0.0
        w = src[4] / (tgt_q[t] * fp * q * math.pi * src[5] * src[5])
        return x0, y0, sx, sy, w

    return RayOps(
        mix, uniform_pair, centred, hole, fresnel_sp, advance, trace_one, reach, solve_rho,
        plain_draw, importance_draw,
    )  # fmt: skip
