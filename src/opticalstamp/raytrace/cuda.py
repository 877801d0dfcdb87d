"""The ray kernel on a CUDA device (numba.cuda): the same rays as :mod:`.kernel`.

Imported only when a CUDA device is asked for (``--device cuda`` or ``auto`` with the
optional ``opticalstamp[cuda]`` installed): nothing of it is imported on the CPU path.

Each thread takes one sample: the same counter-based draws (SplitMix64 of the seed key,
the global ray index and a draw counter), the same exact 3-D Snell propagation, hole
tests on the full staggered lattice and Fresnel factors as the CPU kernel, in float64,
so a ray's fate is the CPU's ray for ray. Survivors are appended through an atomic
counter (their order is restored from their ids on the host); the ledger and the launched
count are summed per block in shared memory. Only plain atomics, shared memory and
``syncthreads`` are used, so the same kernels run under numba's CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``), which is how the test suite checks them without a GPU.
"""

from __future__ import annotations

import math

import numpy as np

if not hasattr(np, "row_stack"):  # numba-cuda <= 0.30 calls np.row_stack, gone in numpy 2.5
    setattr(np, "row_stack", np.vstack)  # noqa: B010

from numba import cuda  # noqa: E402

TRANSMITTED, ABSORBED, TIR, ESCAPED = 0, 1, 2, 3
THREADS = 128
MAX_PLANES = 32  # the ledger's planes per block in shared memory

_U32 = 2.0**-32
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S32 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(32)
_S33 = np.uint64(33)
_MASK32 = np.uint64(0xFFFFFFFF)
_MASK31 = np.uint64(0x7FFFFFFF)


@cuda.jit(device=True, inline=True)
def _mix(z):
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@cuda.jit(device=True, inline=True)
def _uniform_pair(key, gid, draw):
    z = _mix(key ^ (np.uint64(gid) * _GOLDEN + np.uint64(draw) * _M2))
    hi = np.float64(z >> _S32)
    lo = np.float64(z & _MASK32)
    return (hi + 0.5) * _U32, (lo + 0.5) * _U32


@cuda.jit(device=True, inline=True)
def _centred(bits31):
    return (np.float64(bits31) + 0.5) * 2.0**-31 - 0.5


@cuda.jit(device=True)
def _hole(x, y, masks, m, lat):
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


@cuda.jit(device=True)
def _trace_one(x, y, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, slot):
    """As :func:`opticalstamp.raytrace.kernel._trace_one` (status, plane, x, y, weight)."""
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
                c1 = c / n
                cc2 = math.sqrt(c2sq) / n2
                a = n * c1
                b = n2 * cc2
                rs = (a - b) / (a + b)
                a2 = n2 * c1
                b2 = n * cc2
                rp = (a2 - b2) / (a2 + b2)
                ps *= 1.0 - rs * rs
                pp *= 1.0 - rp * rp
    return TRANSMITTED, n_sl - 1, x, y, w * 0.5 * (ps + pp)


@cuda.jit(device=True)
def _reach(rho, slabs, n_pre):
    dr = 0.0
    dd = 0.0
    for i in range(n_pre):
        n2 = slabs[i, 1] * slabs[i, 1]
        c2 = n2 - rho * rho
        c = math.sqrt(c2)
        dr += slabs[i, 0] / c
        dd += slabs[i, 0] * n2 / (c2 * c)
    return rho * dr, dd, dr


@cuda.jit(device=True)
def _solve_rho(r, slabs, n_pre, n_min, d_eq):
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


@cuda.jit(device=True)
def _finish(st, pl, xe, ye, we, sx, sy, gid, hrow, hk, i, nm, led, out, o_id, o_hrow, o_hk, count):
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
def _flush(led, launched, ledger, n_launched, npl):
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
def _zero(led, launched, npl):
    t = cuda.threadIdx.x
    if t < npl * 4:
        led[t // 4, t % 4] = 0
    if t == 0:
        launched[0] = 0
    cuda.syncthreads()


@cuda.jit(cache=True)  # compiled once, kept between processes where numba-cuda can
def plain_kernel(
    first_id, n_rays, key, src, slabs, n_out, masks, lat, lim, fresnel,
    hrow, hk, out, o_id, o_hrow, o_hk, count, ledger, n_launched,
):  # fmt: skip
    """Plain Lambertian samples first_id ... first_id + n_rays - 1 (see run_plain):
    samples outside |s| < n0 are not rays and not launched."""
    led = cuda.shared.array((MAX_PLANES, 4), np.int64)
    launched = cuda.shared.array(1, np.int64)
    npl = slabs.shape[0]
    _zero(led, launched, npl)
    i = cuda.grid(1)
    if i < n_rays:
        gid = first_id + i
        g = np.uint64(gid) * _GOLDEN
        z0 = _mix(key ^ g)
        z1 = _mix(key ^ (g + _M2))
        n0 = src[5]
        xa = src[0] + _centred(z0 >> _S33) * src[2]
        ya = src[1] + _centred(z0 & _MASK31) * src[3]
        a = 2.0 * n0 * _centred(z1 >> _S33)
        c2 = 2.0 * n0 * _centred(z1 & _MASK31)
        if a * a + c2 * c2 < n0 * n0:
            cuda.atomic.add(launched, 0, 1)
            st, pl, xe, ye, we = _trace_one(
                xa, ya, a, c2, src[4], slabs, n_out, masks, lat, lim, fresnel, hrow, hk, i
            )
            _finish(st, pl, xe, ye, we, a, c2, gid, hrow, hk, i, masks.shape[0], led, out,
                    o_id, o_hrow, o_hk, count)  # fmt: skip
    _flush(led, launched, ledger, n_launched, npl)


@cuda.jit(cache=True)
def importance_kernel(
    first_id, n_rays, key, src, slabs, n_out, masks, lat, lim, fresnel, n_pre,
    tgt_x, tgt_y, tgt_prob, tgt_alias, tgt_q,
    hrow, hk, out, o_id, o_hrow, o_hk, count, ledger, n_launched,
):  # fmt: skip
    """Importance-sampled rays first_id ... first_id + n_rays - 1 (see run_importance)."""
    led = cuda.shared.array((MAX_PLANES, 4), np.int64)
    launched = cuda.shared.array(1, np.int64)
    npl = slabs.shape[0]
    _zero(led, launched, npl)
    i = cuda.grid(1)
    if i < n_rays:
        cuda.atomic.add(launched, 0, 1)
        gid = first_id + i
        m0 = int(slabs[n_pre - 1, 2])
        hw = masks[m0, 1]
        hh = masks[m0, 2]
        circ = masks[m0, 0] == 1.0
        nt = tgt_prob.size
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
        st, pl, xe, ye, we = _trace_one(
            x0, y0, sx, sy, w, slabs, n_out, masks, lat, lim, fresnel, hrow, hk, i
        )
        _finish(st, pl, xe, ye, we, sx, sy, gid, hrow, hk, i, masks.shape[0], led, out,
                o_id, o_hrow, o_hk, count)  # fmt: skip
    _flush(led, launched, ledger, n_launched, npl)


def run(first_id, n_rays, key, src, args, fresnel, n_pre, targets=None) -> dict:
    """Trace one chunk on the device; the survivors in ray order (as the CPU's):
    ``ids, x, y, sx, sy, w, hole_row, hole_k``, the ``ledger`` and ``n_launched``.
    ``targets``: the alias table (importance sampling) or None (plain sampling)."""
    slabs, n_out, masks, lat, lim = args
    nm, npl = masks.shape[0], slabs.shape[0]
    if npl > MAX_PLANES:
        raise ValueError(f"the CUDA kernel handles at most {MAX_PLANES} planes (got {npl})")
    d = cuda.to_device
    dargs = (d(slabs), float(n_out), d(masks), d(lat), d(lim), bool(fresnel))
    hrow = cuda.device_array((n_rays, nm), np.int8)
    hk = cuda.device_array((n_rays, nm), np.int32)
    cap = n_rays  # survivors: at most one per ray
    out = cuda.device_array((cap, 5), np.float64)
    o_id = cuda.device_array(cap, np.int64)
    o_hrow = cuda.device_array((cap, nm), np.int8)
    o_hk = cuda.device_array((cap, nm), np.int32)
    count = d(np.zeros(1, np.int64))
    ledger = d(np.zeros((npl, 4), np.int64))
    launched = d(np.zeros(1, np.int64))
    blocks = (n_rays + THREADS - 1) // THREADS
    common = (hrow, hk, out, o_id, o_hrow, o_hk, count, ledger, launched)
    with np.errstate(over="ignore"):  # the simulator's uint64 hashing wraps, as on the device
        if targets is None:
            plain_kernel[blocks, THREADS](first_id, n_rays, key, d(src), *dargs, *common)
        else:
            tg = targets
            importance_kernel[blocks, THREADS](
                first_id, n_rays, key, d(src), *dargs, int(n_pre),
                d(tg.x), d(tg.y), d(tg.prob), d(tg.alias), d(tg.q_per_area), *common,
            )  # fmt: skip
    n = int(count.copy_to_host()[0])
    o = out[:n].copy_to_host() if n else np.zeros((0, 5))
    ids = o_id[:n].copy_to_host() if n else np.zeros(0, np.int64)
    order = np.argsort(ids, kind="stable")
    return {
        "ids": ids[order],
        "x": o[order, 0],
        "y": o[order, 1],
        "sx": o[order, 2],
        "sy": o[order, 3],
        "w": o[order, 4],
        "hole_row": (o_hrow[:n].copy_to_host() if n else np.zeros((0, nm), np.int8))[order],
        "hole_k": (o_hk[:n].copy_to_host() if n else np.zeros((0, nm), np.int32))[order],
        "ledger": ledger.copy_to_host(),
        "n_launched": int(launched.copy_to_host()[0]),
    }
