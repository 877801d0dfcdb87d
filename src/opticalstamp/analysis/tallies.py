"""Tallies of traced rays: what the traced analyses sum over a pixel's rays.

One object per kind of tally, each with its CPU and its GPU accumulation side by side:

* :class:`FoldTally`: rays folded onto chart periods at object distances (the RMTF's
  folded LSFs, :mod:`.lsf`), and the light per lateral slope;
* :class:`MapTally`: responsivity maps on the object plane, own path on a fine grid and
  ghost light on a coarse one (the scan kernels, :mod:`.maps`);
* :class:`GhostTally`: sums per hole sequence, landing histograms, the virtual
  detector's sums and the nearest landings (:mod:`.ghosts`);
* :class:`SpotTally`: the spots' grids, the own path's extents, the centre output cell
  and the total light (:mod:`.spots`);
* :class:`BandTally`: the light beyond a wave engine's band and inside it, and where the
  former lands nearest the pixel's axis (the search's wave estimator,
  :func:`~opticalstamp.studies.waveestimate.far_light`).

A batch is tallied where its rays are: on the GPU where a GPU traced them and keeps them
(:class:`~opticalstamp.raytrace.launch.DeviceRayBatch`, the kernels of
:mod:`.cuda_tallies`), on the CPU otherwise (the numba kernels here). Both give the same
sums to rounding, the counts exactly (tests/cuda/sim_device.py feeds both the same
rays). An analysis builds its tallies, runs :func:`run` (one trace of the pixel feeds
every tally it is given) and turns the tallies into its result: no analysis knows where
its rays were traced.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numba
import numpy as np

from ..raytrace.pixel import PixelBatch, PixelTracer
from ..raytrace.tally import OWN_PATH, KeyedSums, PathRegistry

#: Target width of the bins of a folded LSF (um); each period gets round(P / this) bins.
FOLD_BIN_UM = 0.5
#: bins of the lateral slope |dX/dZ| of the light in the object medium (the last bin
#: takes every slope beyond)
SLOPE_EDGES = np.linspace(0.0, 4.0, 161)


class Tally(Protocol):
    """Anything :func:`run` feeds: it takes each batch of a pixel's traced rays."""

    def add(self, pb: PixelBatch) -> None: ...


def run(
    tracer: PixelTracer,
    pixel: tuple[int, int],
    tallies: Sequence[Tally],
    n_rays: int | None = None,
    *,
    first_id: int = 0,
    stream: int = 0,
    progress: bool = False,
) -> None:
    """Trace ``n_rays`` rays of ``pixel`` (from ray ``first_id`` of random stream
    ``stream``; None: the tracer's sampling) once and give every batch to every tally."""
    for pb in tracer.trace(pixel, n_rays, first_id=first_id, stream=stream, progress=progress):
        for t in tallies:
            t.add(pb)


class _Split:
    """A tally that adds each batch where its rays are: :meth:`_add_device` where a GPU
    keeps them (unless :attr:`host_only`: a selection the device kernels do not make),
    :meth:`_add_host` otherwise."""

    host_only = False

    def add(self, pb: PixelBatch) -> None:
        if pb.rays.device is not None and not self.host_only:
            self._add_device(pb)
        else:
            self._add_host(pb)


def _outside(pb: PixelBatch, band: float) -> np.ndarray:
    """The rays with |s_x| or |s_y| >= ``band`` (the light a wave engine of that band
    leaves to the tracer; s is conserved through the stack)."""
    b = pb.rays
    return (np.abs(b.sx) >= band) | (np.abs(b.sy) >= band)


# -- folds onto chart periods ------------------------------------------------------------
def fold_bins(periods_um: np.ndarray) -> np.ndarray:
    """Bins of a folded LSF per period: round(P / FOLD_BIN_UM), at least 8."""
    return np.maximum(8, np.round(periods_um / FOLD_BIN_UM)).astype(np.int64)


@numba.njit(inline="always", cache=True)
def _landing(x, y, sx, sy, z, n_obj, x0, y0):  # pragma: no cover
    """Where a ray (x, y, sx, sy) leaving the stack meets the object plane ``z`` (um above
    the reference plane; a straight line in the medium of index ``n_obj``), from the
    pixel's axis (x0, y0): (dx, dy). Inlined in the CPU tally kernels (the device's:
    ``cuda_tallies._landing``)."""
    c = np.sqrt(n_obj * n_obj - sx * sx - sy * sy)
    return x + z * sx / c - x0, y + z * sy / c - y0


@numba.njit(parallel=True, cache=True)
def _fold(x, sx, sy, w, batch, x0, z_um, n_obj, periods, n_bins, out):  # pragma: no cover
    """out[p, b, iz, bin] += w for each ray; prange over z (no write conflicts)."""
    for iz in numba.prange(z_um.size):
        z = z_um[iz]
        for i in range(x.size):
            wi = w[i]
            if wi == 0.0:
                continue
            xo = _landing(x[i], 0.0, sx[i], sy[i], z, n_obj, x0, 0.0)[0]
            for p in range(periods.size):
                per = periods[p]
                phi = xo - np.floor(xo / per) * per
                j = int(phi / per * n_bins[p])
                if j >= n_bins[p]:
                    j = n_bins[p] - 1
                out[p, batch[i], iz, j] += wi


def _slopes(b, w: np.ndarray, n_obj: float) -> np.ndarray:
    """Etendue per bin of SLOPE_EDGES of the rays ``b`` (weights ``w``)."""
    keep = w != 0
    sx, sy = b.sx[keep], b.sy[keep]
    c = np.sqrt(np.maximum(n_obj * n_obj - sx * sx - sy * sy, 1e-300))
    t = np.minimum(np.abs(sx) / c, SLOPE_EDGES[-1] * (1 - 1e-12))
    return np.histogram(t, SLOPE_EDGES, weights=w[keep])[0]


class FoldTally(_Split):
    """One pixel's rays folded onto every chart period at every object distance.

    Parameters
    ----------
    kinds : per fold, True for all light, False for the own path alone
    z_mm, periods_um : object distances (mm above the reference plane), chart periods
    n_batches : rays dealt into interleaved batches by ray id (their spread gives the
        standard errors)
    x0 : the pixel's axis (um); phase phi = (X - x0) mod P
    n_obj : refractive index of the object medium
    n_rays : the pixel's ray count, which the slope tally is divided by batch by batch
    outside_band : fold only the rays outside this band (|s_x| or |s_y| >= it) into the
        all-light folds; the own-path folds stay whole (tallied on the host)

    ``sums[i]`` (periods, n_batches, nz, max bins): summed weights of fold i; ``slopes[i]``
    the light per bin of lateral slope, over n_rays (NaN where a GPU tallied: not summed
    there).
    """

    def __init__(self, kinds, z_mm, periods_um, n_batches, x0, n_obj, n_rays, outside_band=None):
        self.kinds = tuple(bool(k) for k in kinds)
        self.z_um = np.asarray(z_mm, dtype=np.float64) * 1000.0
        self.periods = np.asarray(periods_um, dtype=np.float64)
        self.bins = fold_bins(self.periods)
        self.n_batches = int(n_batches)
        self.x0 = float(x0)
        self.n_obj = float(n_obj)
        self.n_rays = n_rays
        self.outside_band = outside_band
        shape = (self.periods.size, self.n_batches, self.z_um.size, int(self.bins.max()))
        self._host = [np.zeros(shape) for _ in self.kinds]
        self._slopes = [np.zeros(SLOPE_EDGES.size - 1) for _ in self.kinds]
        self._device = None  # the same sums on the GPU, once a batch was tallied there

    @property
    def host_only(self) -> bool:
        return self.outside_band is not None

    def _add_host(self, pb: PixelBatch) -> None:
        b = pb.rays
        batch = (b.ids % self.n_batches).astype(np.int64)
        keep = None if self.outside_band is None else _outside(pb, self.outside_band)
        for ghosts, out, sl in zip(self.kinds, self._host, self._slopes, strict=True):
            w = pb.w if ghosts else pb.w * pb.own
            w = w if keep is None or not ghosts else w * keep
            on = np.flatnonzero(w)  # the rays _fold would skip, left out in order
            x, sx, sy = b.x[on], b.sx[on], b.sy[on]
            _fold(
                x, sx, sy, w[on], batch[on], self.x0, self.z_um, self.n_obj, self.periods,
                self.bins, out,
            )  # fmt: skip
            sl += _slopes(b, w, self.n_obj) / self.n_rays

    def _add_device(self, pb: PixelBatch) -> None:
        from . import cuda_tallies as gpu

        self._device = self._device or [gpu.zeros(out.shape) for out in self._host]
        for ghosts, res in zip(self.kinds, self._device, strict=True):
            gpu.fold(
                pb, not ghosts, self.z_um, self.n_obj, self.periods, self.bins,
                self.n_batches, res,
            )  # fmt: skip

    @property
    def sums(self) -> list[np.ndarray]:
        if self._device is None:
            return self._host
        return [h + d.copy_to_host() for h, d in zip(self._host, self._device, strict=True)]

    @property
    def slopes(self) -> list[np.ndarray]:
        if self._device is None:
            return self._slopes
        return [sl + np.nan for sl in self._slopes]  # not tallied on the device


# -- responsivity maps -------------------------------------------------------------------
@numba.njit(parallel=True, cache=True)
def _maps(
    x, y, sx, sy, w, own, x0, y0, z_um, n_obj, fine_lo, fine_bin, coarse_lo, coarse_bin, fine,
    coarse,
):  # pragma: no cover  # fmt: skip
    """fine[iz, iy, ix] += own-path w; coarse[iz, iy, ix] += ghost w (prange over z)."""
    nfy, nfx = fine.shape[1], fine.shape[2]
    ncy, ncx = coarse.shape[1], coarse.shape[2]
    for iz in numba.prange(z_um.size):
        z = z_um[iz]
        for i in range(x.size):
            wi = w[i]
            if wi == 0.0:
                continue
            xo, yo = _landing(x[i], y[i], sx[i], sy[i], z, n_obj, x0, y0)
            if own[i]:
                jx = int(np.floor((xo - fine_lo) / fine_bin))
                jy = int(np.floor((yo - fine_lo) / fine_bin))
                if 0 <= jx < nfx and 0 <= jy < nfy:
                    fine[iz, jy, jx] += wi
            else:
                jx = int(np.floor((xo - coarse_lo[1]) / coarse_bin))
                jy = int(np.floor((yo - coarse_lo[0]) / coarse_bin))
                if 0 <= jx < ncx and 0 <= jy < ncy:
                    coarse[iz, jy, jx] += wi


class MapTally(_Split):
    """One pixel's responsivity maps: per set of object distances, the own-path light
    on a fine grid and the ghost light on a coarse grid, summed weights per bin.

    Parameters
    ----------
    sets : per set, (z_mm, fine_lo_um, fine_bin_um, (n_fine, n_fine)) : the distances
        and the fine grid (from the pixel's axis, in x and y)
    coarse_lo_um : (y, x) start of the coarse grid; coarse_bin_um, coarse_shape (ny, nx)
    x0, y0 : the pixel's axis (um); n_obj : index of the object medium
    outside_band : the ghost maps take only the rays outside this band (tallied on the
        host); the own-path maps are whole

    ``fine[i]`` (nz, n, n), ``coarse[i]`` (nz, ny, nx): the sums of set i.
    """

    def __init__(
        self, sets, coarse_lo_um, coarse_bin_um, coarse_shape, x0, y0, n_obj, outside_band=None
    ):
        self.sets = [
            (np.asarray(z, dtype=np.float64) * 1000.0, float(lo), float(b)) for z, lo, b, _ in sets
        ]
        self.coarse_lo = np.asarray(coarse_lo_um, dtype=np.float64)
        self.coarse_bin = float(coarse_bin_um)
        self.x0, self.y0, self.n_obj = float(x0), float(y0), float(n_obj)
        self.outside_band = outside_band
        self._fine = [np.zeros((np.size(z), *shape)) for z, _, _, shape in sets]
        self._coarse = [np.zeros((z.size, *coarse_shape)) for z, _, _ in self.sets]
        self._device = None

    @property
    def host_only(self) -> bool:
        return self.outside_band is not None

    def _add_host(self, pb: PixelBatch) -> None:
        b = pb.rays
        w = pb.w
        if self.outside_band is not None:  # ghost rays in the band: the wave engine's
            w = w * (pb.own | _outside(pb, self.outside_band))
        for (z_um, fine_lo, fine_bin), fine, coarse in zip(
            self.sets, self._fine, self._coarse, strict=True
        ):
            _maps(
                b.x, b.y, b.sx, b.sy, w, pb.own, self.x0, self.y0, z_um, self.n_obj,
                fine_lo, fine_bin, self.coarse_lo, self.coarse_bin, fine, coarse,
            )  # fmt: skip

    def _add_device(self, pb: PixelBatch) -> None:
        from . import cuda_tallies as gpu

        self._device = self._device or [
            (gpu.zeros(f.shape), gpu.zeros(c.shape))
            for f, c in zip(self._fine, self._coarse, strict=True)
        ]
        for (z_um, fine_lo, fine_bin), (fine, coarse) in zip(self.sets, self._device, strict=True):
            gpu.maps(
                pb, z_um, self.n_obj, fine_lo, fine_bin, self.coarse_lo, self.coarse_bin,
                fine, coarse,
            )  # fmt: skip

    @property
    def fine(self) -> list[np.ndarray]:
        if self._device is None:
            return self._fine
        return [f + d.copy_to_host() for f, (d, _) in zip(self._fine, self._device, strict=True)]

    @property
    def coarse(self) -> list[np.ndarray]:
        if self._device is None:
            return self._coarse
        return [c + d.copy_to_host() for c, (_, d) in zip(self._coarse, self._device, strict=True)]


# -- ghost paths -------------------------------------------------------------------------
def _grown(nearest: np.ndarray, n_slots: int) -> np.ndarray:
    """``nearest`` (nz, slots) with a column of inf for each slot it lacks."""
    grow = n_slots - nearest.shape[1]
    return np.hstack([nearest, np.full((nearest.shape[0], grow), np.inf)]) if grow > 0 else nearest


class GhostTally:
    """One pixel's light per hole sequence and where its ghost light lands.

    Parameters
    ----------
    n_masks : masks of the stack; pixel : (row, k); lattice : the stack's
        :class:`~opticalstamp.design.Lattice`-like (k_lo, k_hi)
    n0 : index at the pixel (emission angles); z_mm : object distances for the landings
    bin_um, n_bins : the landing histogram's bins (distance from the pixel's axis; the
        last bin takes everything beyond)
    detector_half_um : half width of the square virtual detector on the pixel's axis

    ``registry``: the hole sequences' codes; ``sums`` (:class:`KeyedSums`): per sequence
    sums of w, w^2, the rays and the range of emission angles (deg); ``nearest`` (nz,
    sequences): nearest ghost landing (um); ``hist`` (nz, n_bins + 1), ``inside``,
    ``inside2`` (nz,): ghost light by landing distance and on the detector; ``ledger``
    (planes, 4): the rays' fates per plane.
    """

    def __init__(
        self, n_masks, pixel, k_lo, k_hi, n0, z_mm, bin_um, n_bins, detector_half_um, n_planes
    ):
        self.row, self.k = pixel
        self.k_lo, self.k_hi = int(k_lo), int(k_hi)
        self.registry = PathRegistry(n_masks, self.row, self.k)
        self.n0 = float(n0)
        self.z_um = [float(z) * 1000.0 for z in z_mm]
        self.bin_um, self.n_bins = float(bin_um), int(n_bins)
        self.half_um = float(detector_half_um)
        self.sums = KeyedSums()
        nz = len(self.z_um)
        self.hist = np.zeros((nz, self.n_bins + 1))
        self.inside = np.zeros(nz)
        self.inside2 = np.zeros(nz)
        self.nearest = np.full((nz, 0), np.inf)  # per Z and path slot
        self.ledger = np.zeros((n_planes, 4), np.int64)

    def add(self, pb: PixelBatch) -> None:
        self.ledger += pb.rays.ledger
        if not (pb.rays.device is not None and self._add_device(pb)):
            self._add_host(pb)

    def _add_host(self, pb: PixelBatch) -> None:
        b = pb.rays
        w = pb.w
        codes = self.registry.ids(b)
        theta = np.degrees(np.arcsin(np.sqrt(b.sx**2 + b.sy**2) / self.n0))
        slot = self.sums.add(codes, w, theta)
        g = (codes != OWN_PATH) & (w > 0)
        for iz, z in enumerate(self.z_um):
            dx, dy = pb.offsets(z)
            dx, dy = dx[g], dy[g]
            dist = np.hypot(dx, dy)
            ib = np.minimum((dist / self.bin_um).astype(np.int64), self.n_bins)
            np.add.at(self.hist[iz], ib, w[g])
            box = (np.abs(dx) <= self.half_um) & (np.abs(dy) <= self.half_um)
            wb = w[g][box]
            np.add.at(self.inside, np.full(wb.size, iz), wb)
            np.add.at(self.inside2, np.full(wb.size, iz), wb * wb)
            self.nearest = _grown(self.nearest, len(self.sums.keys))
            np.minimum.at(self.nearest[iz], slot[g], dist)

    def _add_device(self, pb: PixelBatch) -> bool:
        """Tally on the GPU; False where it cannot take this batch (too many hole
        sequences for its table: the host tallies it)."""
        from .cuda_tallies import ghost_tallies

        t = ghost_tallies(
            pb, self.k_lo, self.k_hi, self.n0, self.z_um, self.bin_um, self.n_bins, self.half_um
        )
        if t is None:
            return False
        codes = np.array([self.registry.id_of(q) for q in t.sequences], np.int64)
        slot = self.sums.merge(codes, t.s1, t.s2, t.count, t.lo, t.hi)
        self.nearest = _grown(self.nearest, len(self.sums.keys))
        for iz in range(len(self.z_um)):
            np.minimum.at(self.nearest[iz], slot, t.nearest[:, iz])
        self.hist += t.hist
        self.inside += t.inside
        self.inside2 += t.inside2
        return True


# -- spots -------------------------------------------------------------------------------
class SpotTally(_Split):
    """One pixel's spots: at each object distance, the light on a square grid around the
    pixel's axis, the own path's edge-to-edge extent, the light on the centre output cell
    and the light in all.

    Parameters
    ----------
    z_mm : object distances (mm above the reference plane)
    edges, bins : per Z, the grid's bin edges (um from the pixel's axis, the same in x
        and y) and their width, or None: the extents alone (a pilot that sizes the grids)
    cell_um : the centre output cell's width (um)
    ghosts : False: the own path's light alone
    outside_band : count only the rays outside this band (|s_x| or |s_y| >= it; the
        band's light is the wave engine's); with ``ghosts`` False then none (the own
        path lies inside the band: the spot is the wave engine's, whose band light
        includes the near crosstalk); the own path's extents take every own ray

    ``maps[iz]`` (n, n), ``inside`` (nz,) and ``total``: summed weights; ``lo``, ``hi``
    (nz, 2): the own path's landings' extremes in x and y (inf, -inf where none).
    """

    def __init__(self, z_mm, edges, bins, cell_um, ghosts=True, outside_band=None):
        self.z_um = np.asarray(z_mm, dtype=np.float64) * 1000.0
        nz = self.z_um.size
        self.edges = edges
        sizes = [0] * nz if edges is None else [e.size - 1 for e in edges]
        self._size = np.array(sizes, np.int64)
        self._start = np.array([0.0] * nz if edges is None else [e[0] for e in edges])
        self._bin = np.ones(nz) if edges is None else np.asarray(bins, dtype=np.float64)
        self.cell_um, self.ghosts, self.outside_band = float(cell_um), bool(ghosts), outside_band
        self._maps = np.zeros((nz, max(sizes, default=0), max(sizes, default=0)))
        self._lo = np.full((nz, 2), np.inf)
        self._hi = np.full((nz, 2), -np.inf)
        self._inside = np.zeros(nz)
        self._total = np.zeros(1)
        self._device = None

    def _weights(self, pb: PixelBatch) -> np.ndarray:
        w = pb.w if self.ghosts else pb.w * pb.own
        if self.outside_band is not None:  # the rays in the band are the wave engine's
            w = w * _outside(pb, self.outside_band) * self.ghosts
        return w

    def _add_host(self, pb: PixelBatch) -> None:
        w, o = self._weights(pb), pb.own
        np.add.at(self._total, np.zeros(w.size, np.int64), w)
        for iz, z in enumerate(self.z_um):
            dx, dy = pb.offsets(z)
            lo = [dx[o].min(initial=np.inf), dy[o].min(initial=np.inf)]
            hi = [dx[o].max(initial=-np.inf), dy[o].max(initial=-np.inf)]
            self._lo[iz] = np.minimum(self._lo[iz], lo)
            self._hi[iz] = np.maximum(self._hi[iz], hi)
            if self.edges is None:
                continue
            n, e0, b = self._size[iz], self._start[iz], self._bin[iz]
            ix = np.floor((dx - e0) / b).astype(np.int64)
            iy = np.floor((dy - e0) / b).astype(np.int64)
            ok = (ix >= 0) & (ix < n) & (iy >= 0) & (iy < n)
            np.add.at(self._maps[iz], (iy[ok], ix[ok]), w[ok])
            cell = (np.abs(dx) <= self.cell_um / 2) & (np.abs(dy) <= self.cell_um / 2)
            np.add.at(self._inside, np.full(int(cell.sum()), iz), w[cell])

    def _add_device(self, pb: PixelBatch) -> None:
        from . import cuda_tallies as gpu

        if self._device is None:
            self._device = [
                gpu.zeros(self._maps.shape), gpu.to_device(np.full_like(self._lo, np.inf)),
                gpu.to_device(np.full_like(self._hi, -np.inf)), gpu.zeros(self._inside.shape),
                gpu.zeros(1),
            ]  # fmt: skip
        band = -1.0 if self.outside_band is None else float(self.outside_band)
        gpu.spot(
            pb, self.z_um, self._start, self._bin, self._size, self.cell_um, self.ghosts, band,
            *self._device,
        )  # fmt: skip

    def _with_device(self, i: int, host: np.ndarray, join) -> np.ndarray:
        return host if self._device is None else join(host, self._device[i].copy_to_host())

    @property
    def maps(self) -> list[np.ndarray]:
        m = self._with_device(0, self._maps, np.add)
        return [m[iz, :n, :n] for iz, n in enumerate(self._size)]

    @property
    def lo(self) -> np.ndarray:
        return self._with_device(1, self._lo, np.minimum)

    @property
    def hi(self) -> np.ndarray:
        return self._with_device(2, self._hi, np.maximum)

    @property
    def inside(self) -> np.ndarray:
        return self._with_device(3, self._inside, np.add)

    @property
    def total(self) -> float:
        return float(self._with_device(4, self._total, np.add)[0])


# -- the light beyond a wave band ----------------------------------------------------------
class BandTally:
    """The light of a pixel's rays beyond a wave engine's ``band`` (|s_x| or |s_y| >= it:
    the far ghost paths, which the wave engine leaves to the tracer) and inside it, and
    the nearest landing of the former from the pixel's axis on the object planes
    ``z_mm``.

    ``far``, ``inside``: summed weights; ``nearest`` (um; inf where none lands). Read on
    the host (a batch that a GPU keeps is copied back): a few sums per batch, which no
    device kernel makes.
    """

    def __init__(self, band: float, z_mm):
        self.band = float(band)
        self.z_um = [float(z) * 1000.0 for z in z_mm]
        self.far = self.inside = 0.0
        self.nearest = math.inf

    def add(self, pb: PixelBatch) -> None:
        w = pb.w
        out = _outside(pb, self.band) & (w > 0)
        self.far += float(w[out].sum())
        self.inside += float(w[~out].sum())
        if out.any():
            for z in self.z_um:
                dx, dy = pb.offsets(z)
                self.nearest = min(self.nearest, float(np.hypot(dx[out], dy[out]).min()))
