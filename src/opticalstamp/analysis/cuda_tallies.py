"""Tallies on the GPU: the traced analyses' sums, taken where a GPU keeps the rays.

Where a GPU traced a pixel's rays (:class:`~opticalstamp.raytrace.launch.DeviceRayBatch`)
the survivors stay in device memory and are tallied there, so only the tallies come back
to the host: the folding of rays onto chart periods (the RMTF's folded LSFs,
:func:`fold`), the responsivity maps of the scan kernels (:func:`maps`), the ghost
analysis's sums per hole sequence, landing histograms and nearest landings
(:func:`ghost_tallies`) and the spots' grids and extents (:func:`spot`). Each kernel
computes, per ray, what the CPU's tally computes (:mod:`.tallies`' ``_fold``, ``_maps``,
:class:`~.tallies.GhostTally` and :class:`~.tallies.SpotTally`), in float64, and
adds it with atomics (products that the CPU rounds on their own are kept from fusing
into FMAs, :func:`~opticalstamp.raytrace.cuda_ray.mul`): the sums equal the CPU's to rounding
(the order of the additions differs, and varies from run to run), the counts are exact;
angles and landing distances use libdevice's asin and hypot, within an ulp of the CPU's.
The tally objects of :mod:`.tallies` call these where a batch's rays are on a GPU;
imported only where a GPU (or numba's CUDA simulator) traced the rays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..raytrace.cuda import THREADS, blocks
from ..raytrace.cuda_ray import cuda, mul

EMPTY = -1  # a free slot of the hash table of hole sequences
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def zeros(shape) -> object:
    """A device array of float64 zeros (a tally that stays on the device across chunks)."""
    return cuda.to_device(np.zeros(shape))


@cuda.jit(device=True)
def _landing(out, i, z, n_obj):
    """Where survivor i meets the object plane z (um above the reference plane), as
    :func:`~opticalstamp.raytrace.tally.object_plane`."""
    sx = out[i, 2]
    sy = out[i, 3]
    c = math.sqrt(mul(n_obj, n_obj) - mul(sx, sx) - mul(sy, sy))
    return out[i, 0] + z * sx / c, out[i, 1] + z * sy / c


@cuda.jit(cache=True)
def fold_kernel(out, ids, w, own, own_only, n, x0, z_um, n_obj, periods, n_bins, n_batch, res):
    """res[p, id % n_batch, iz, bin] += w per ray and Z (the CPU's ``tallies._fold``)."""
    t = cuda.grid(1)
    if t >= n * z_um.size:
        return
    i = t % n
    iz = t // n
    wi = w[i]
    if wi == 0.0 or (own_only and own[i] == 0):
        return
    xo, _ = _landing(out, i, z_um[iz], n_obj)
    xo -= x0
    b = ids[i] % n_batch
    for p in range(periods.size):
        per = periods[p]
        phi = xo - mul(math.floor(xo / per), per)
        j = int(phi / per * n_bins[p])
        if j >= n_bins[p]:
            j = n_bins[p] - 1
        cuda.atomic.add(res, (p, b, iz, j), wi)


def fold(pb, own_only: bool, z_um, n_obj, periods, n_bins, n_batches, res) -> None:
    """Fold a device batch's rays onto every period at every Z into device array ``res``
    (periods, n_batches, nz, bins): the CPU's ``tallies._fold`` of ``pb.w`` (``own_only``:
    of ``pb.w * pb.own``) on the device."""
    dev = pb.rays.device
    if dev.n == 0:
        return
    w, own = pb.on_device
    zs = cuda.to_device(np.ascontiguousarray(z_um, np.float64))
    fold_kernel[blocks(dev.n * len(z_um)), THREADS](
        dev.out, dev.ids, w, own, bool(own_only), dev.n, float(pb.x0), zs, float(n_obj),
        cuda.to_device(np.asarray(periods, np.float64)),
        cuda.to_device(np.asarray(n_bins, np.int64)), int(n_batches), res,
    )  # fmt: skip


@cuda.jit(cache=True)
def maps_kernel(
    out, w, own, n, x0, y0, z_um, n_obj, fine_lo, fine_bin, c_lo_y, c_lo_x, c_bin, fine, coarse
):
    """fine[iz, iy, ix] += own-path w; coarse[iz, iy, ix] += ghost w (``tallies._maps``)."""
    t = cuda.grid(1)
    if t >= n * z_um.size:
        return
    i = t % n
    iz = t // n
    wi = w[i]
    if wi == 0.0:
        return
    xo, yo = _landing(out, i, z_um[iz], n_obj)
    xo -= x0
    yo -= y0
    if own[i]:
        jx = int(math.floor((xo - fine_lo) / fine_bin))
        jy = int(math.floor((yo - fine_lo) / fine_bin))
        if 0 <= jx < fine.shape[2] and 0 <= jy < fine.shape[1]:
            cuda.atomic.add(fine, (iz, jy, jx), wi)
    else:
        jx = int(math.floor((xo - c_lo_x) / c_bin))
        jy = int(math.floor((yo - c_lo_y) / c_bin))
        if 0 <= jx < coarse.shape[2] and 0 <= jy < coarse.shape[1]:
            cuda.atomic.add(coarse, (iz, jy, jx), wi)


def maps(pb, z_um, n_obj, fine_lo, fine_bin, coarse_lo, coarse_bin, fine, coarse) -> None:
    """Bin a device batch's rays into the device arrays ``fine`` (own path) and
    ``coarse`` (ghost light), as the CPU's ``tallies._maps``."""
    dev = pb.rays.device
    if dev.n == 0:
        return
    w, own = pb.on_device
    zs = cuda.to_device(np.ascontiguousarray(z_um, np.float64))
    maps_kernel[blocks(dev.n * len(z_um)), THREADS](
        dev.out, w, own, dev.n, float(pb.x0), float(pb.y0), zs, float(n_obj), float(fine_lo),
        float(fine_bin), float(coarse_lo[0]), float(coarse_lo[1]), float(coarse_bin), fine,
        coarse,
    )  # fmt: skip


@cuda.jit(device=True)
def _slot(keys, key):
    """The slot of ``key`` in the open-addressing table ``keys`` (inserted where new),
    or -1 where the table is full."""
    cap = keys.size
    h = np.int64((np.uint64(key) * _GOLDEN) >> np.uint64(40)) % cap
    for _ in range(cap):
        old = keys[h]  # a plain read first: a slot once set never changes
        if old == EMPTY:
            old = cuda.atomic.cas(keys, h, EMPTY, key)
        if old == EMPTY or old == key:
            return h
        h = (h + 1) % cap
    return -1


@cuda.jit(cache=True)
def ghost_kernel(
    out, hole_row, hole_k, w, own, n, row, k_lo, radix, n0, x0, y0, n_obj, z_um, bin_um,
    n_bins, half_um, keys, s1, s2, count, lo, hi, nearest, hist, inside, inside2, full,
):  # fmt: skip
    """Per survivor: its hole sequence's slot (sums of w, w^2, count, emission angle range)
    and, for ghost light, where it lands at each Z (histogram of distances, the virtual
    detector's sums, the nearest landing per sequence), as :class:`~.tallies.GhostTally`
    sums them on the host."""
    i = cuda.grid(1)
    if i >= n:
        return
    key = np.int64(0)
    mult = np.int64(1)
    for m in range(hole_k.shape[1]):
        v = 2 * (np.int64(hole_k[i, m]) - k_lo) + (1 if hole_row[i, m] != row else 0)
        key += v * mult
        mult *= radix
    s = _slot(keys, key)
    if s < 0:
        cuda.atomic.add(full, 0, 1)
        return
    wi = w[i]
    sx = out[i, 2]
    sy = out[i, 3]
    cuda.atomic.add(s1, s, wi)
    cuda.atomic.add(s2, s, wi * wi)
    cuda.atomic.add(count, s, 1)
    theta = math.degrees(math.asin(math.sqrt(mul(sx, sx) + mul(sy, sy)) / n0))
    cuda.atomic.min(lo, s, theta)
    cuda.atomic.max(hi, s, theta)
    if own[i] or not wi > 0.0:
        return
    for iz in range(z_um.size):
        dx, dy = _landing(out, i, z_um[iz], n_obj)
        dx -= x0
        dy -= y0
        dist = math.hypot(dx, dy)
        ib = min(int(dist / bin_um), n_bins)
        cuda.atomic.add(hist, (iz, ib), wi)
        if abs(dx) <= half_um and abs(dy) <= half_um:
            cuda.atomic.add(inside, iz, wi)
            cuda.atomic.add(inside2, iz, wi * wi)
        cuda.atomic.min(nearest, (s, iz), dist)


@dataclass(frozen=True)
class DeviceGhostSums:
    """One chunk's ghost-analysis sums, per hole sequence and per Z.

    ``sequences``: per hole sequence, ((other_row, dk), ...) per mask from the sensor up
    (:class:`~opticalstamp.raytrace.tally.PathRegistry`'s form), in ascending order of
    the CPU's lexicographic key; ``s1``, ``s2``, ``count``, ``lo``, ``hi``: the sums of w,
    w^2, the rays and the range of emission angles (deg) per sequence; ``nearest``
    (sequences, nz): the nearest ghost landing (um); ``hist`` (nz, n_bins + 1),
    ``inside``, ``inside2`` (nz,): ghost light by landing distance and on the detector.
    """

    sequences: list
    s1: np.ndarray
    s2: np.ndarray
    count: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    nearest: np.ndarray
    hist: np.ndarray
    inside: np.ndarray
    inside2: np.ndarray


def ghost_tallies(
    pb, k_lo: int, k_hi: int, n0: float, z_um, bin_um: float, n_bins: int, half_um: float,
    capacity: int = 1 << 12, max_capacity: int = 1 << 20,
) -> DeviceGhostSums | None:  # fmt: skip
    """The ghost analysis's sums of one device batch, or None where the device cannot
    take them (hole sequences beyond an int64 key, or more than ``max_capacity`` of them):
    the caller then tallies the batch on the host. The hash table of hole sequences starts
    with ``capacity`` slots and is doubled while it fills up."""
    nm = pb.rays.device.hole_k.shape[1]
    radix = 2 * (int(k_hi) - int(k_lo) + 1)
    if radix**nm >= 1 << 62:
        return None
    while capacity <= max_capacity:
        t = _ghost_tallies(pb, k_lo, radix, n0, z_um, bin_um, n_bins, half_um, capacity)
        if t is not None:
            return t
        capacity *= 2
    return None


def _ghost_tallies(pb, k_lo, radix, n0, z_um, bin_um, n_bins, half_um, capacity):
    """:func:`ghost_tallies` with a table of ``capacity`` slots; None where it fills."""
    dev = pb.rays.device
    nm = dev.hole_k.shape[1]
    zs = np.ascontiguousarray(z_um, np.float64)
    nz = zs.size
    keys = cuda.to_device(np.full(capacity, EMPTY, np.int64))
    sums = [cuda.to_device(np.zeros(capacity)) for _ in range(2)]
    count = cuda.to_device(np.zeros(capacity, np.int64))
    lo = cuda.to_device(np.full(capacity, np.inf))
    hi = cuda.to_device(np.full(capacity, -np.inf))
    nearest = cuda.to_device(np.full((capacity, nz), np.inf))
    hist = zeros((nz, n_bins + 1))
    inside, inside2 = zeros(nz), zeros(nz)
    full = cuda.to_device(np.zeros(1, np.int64))
    if dev.n:
        w, own = pb.on_device
        ghost_kernel[blocks(dev.n), THREADS](
            dev.out, dev.hole_row, dev.hole_k, w, own, dev.n, int(pb.row), int(k_lo),
            radix, float(n0), float(pb.x0), float(pb.y0), float(pb.n_obj),
            cuda.to_device(zs), float(bin_um), int(n_bins), float(half_um), keys, *sums,
            count, lo, hi, nearest, hist, inside, inside2, full,
        )  # fmt: skip
    if int(full.copy_to_host()[0]):
        return None
    key = keys.copy_to_host()
    used = np.flatnonzero(key != EMPTY)
    used = used[np.argsort(key[used], kind="stable")]
    seqs = []
    for v in key[used].tolist():
        seq = []
        for _ in range(nm):
            v, d = divmod(v, radix)
            seq.append((d % 2, d // 2 + int(k_lo) - int(pb.k)))
        seqs.append(tuple(seq))
    return DeviceGhostSums(
        seqs,
        sums[0].copy_to_host()[used],
        sums[1].copy_to_host()[used],
        count.copy_to_host()[used],
        lo.copy_to_host()[used],
        hi.copy_to_host()[used],
        nearest.copy_to_host()[used],
        hist.copy_to_host(),
        inside.copy_to_host(),
        inside2.copy_to_host(),
    )


def to_device(a: np.ndarray) -> object:
    """A host array on the device (a tally's starting values)."""
    return cuda.to_device(np.ascontiguousarray(a))


@cuda.jit(cache=True)
def spot_kernel(
    out, w, own, n, x0, y0, z_um, n_obj, ghosts, band, start, step, size, cell_half,
    maps, lo, hi, inside, total,
):  # fmt: skip
    """Per survivor and Z (as :class:`~.tallies.SpotTally` on the host): the own path's
    landing extremes, the light on the grid of that Z and on the centre cell, and (once
    per survivor) the light in all."""
    t = cuda.grid(1)
    if t >= n * z_um.size:
        return
    i = t % n
    iz = t // n
    o = own[i] != 0
    wi = w[i] if ghosts or o else 0.0
    if band >= 0.0 and not (abs(out[i, 2]) >= band or abs(out[i, 3]) >= band):
        wi = 0.0  # in the band: the wave engine's light
    if band >= 0.0 and not ghosts:
        wi = 0.0
    if iz == 0:
        cuda.atomic.add(total, 0, wi)
    dx, dy = _landing(out, i, z_um[iz], n_obj)
    dx -= x0
    dy -= y0
    if o:
        cuda.atomic.min(lo, (iz, 0), dx)
        cuda.atomic.min(lo, (iz, 1), dy)
        cuda.atomic.max(hi, (iz, 0), dx)
        cuda.atomic.max(hi, (iz, 1), dy)
    if size[iz] == 0 or wi == 0.0:
        return
    jx = int(math.floor((dx - start[iz]) / step[iz]))
    jy = int(math.floor((dy - start[iz]) / step[iz]))
    if 0 <= jx < size[iz] and 0 <= jy < size[iz]:
        cuda.atomic.add(maps, (iz, jy, jx), wi)
    if abs(dx) <= cell_half and abs(dy) <= cell_half:
        cuda.atomic.add(inside, iz, wi)


def spot(pb, z_um, start, step, size, cell_um, ghosts, band, maps, lo, hi, inside, total) -> None:
    """Add a device batch's rays to a spot tally's device arrays (``band`` < 0: none)."""
    dev = pb.rays.device
    if dev.n == 0:
        return
    w, own = pb.on_device
    z = np.ascontiguousarray(z_um, np.float64)
    spot_kernel[blocks(dev.n * z.size), THREADS](
        dev.out, w, own, dev.n, float(pb.x0), float(pb.y0), to_device(z), float(pb.n_obj),
        bool(ghosts), float(band), to_device(np.asarray(start, np.float64)),
        to_device(np.asarray(step, np.float64)), to_device(np.asarray(size, np.int64)),
        float(cell_um) / 2, maps, lo, hi, inside, total,
    )  # fmt: skip
