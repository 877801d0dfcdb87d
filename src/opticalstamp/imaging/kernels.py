"""Scan kernels: each used pixel's responsivity map at a set of object distances, in the
form the scan simulation applies fast.

The own-path map R(X, Y) (X, Y from the pixel's axis, um) is stored as a short sum of
separable terms, R = sum_k s_k u_k(Y) v_k(X), each factor as a cumulative table on a fine
grid (its integral from the grid's start), so the weight of any document pixel, of any
size and at any sub-pixel offset, is a difference of two interpolated values (exact for
a map that is uniform within each grid bin). Rectangular holes in the paraxial limit are
exactly separable (rank 1, closed form, :mod:`opticalstamp.responsivity`); a traced map
(circular holes, or the exact tracer) is split by a singular value decomposition and
truncated where the remaining singular values fall below ``rank_tol`` of the first.

Ghost light lands millimetres away (docs/paper-comparison.md); it is kept as a coarse
map (0.5 mm bins) of etendue per bin, applied to a block-averaged document.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from ..analysis.maps import TracedMaps, traced_map_sets
from ..analysis.paraxial import (
    paraxial_cumulative,
    paraxial_support,
)
from ..defaults import RAYS_MAP
from ..design import AnyDesign, Design
from ..raytrace.pixel import PixelTracer, Sampling, tracer_for


@dataclass(frozen=True)
class ScanKernel:
    """Responsivity of the pixels of one row at one object distance.

    Attributes
    ----------
    z_mm : object distance
    lo_um, bin_um : fine grid start (from the pixel's axis) and step, both axes
    cum_y, cum_x : (K, n + 1) cumulative integrals of the separable factors at the grid
        edges lo_um + i bin_um
    scale : (K,) singular values s_k (etendue units: um^2 sr overall)
    ghost : (ny, nx) ghost etendue per coarse bin or None; rows = Y, cols = X
    ghost_lo_um : (Y, X) of the coarse grid's first edge; ghost_bin_um its step
    """

    z_mm: float
    lo_um: float
    bin_um: float
    cum_y: np.ndarray
    cum_x: np.ndarray
    scale: np.ndarray
    ghost: np.ndarray | None = None
    ghost_lo_um: tuple[float, float] = (0.0, 0.0)
    ghost_bin_um: float = 1.0

    def without_ghosts(self) -> ScanKernel:
        """This kernel without its ghost map (and with the coarse grid of none)."""
        return replace(self, ghost=None, ghost_lo_um=(0.0, 0.0), ghost_bin_um=1.0)

    @property
    def own_etendue(self) -> float:
        return float((self.scale * self.cum_y[:, -1] * self.cum_x[:, -1]).sum())

    @property
    def ghost_etendue(self) -> float:
        return 0.0 if self.ghost is None else float(self.ghost.sum())

    def weights(self, axis: int, offsets_um: np.ndarray, width_um: float) -> np.ndarray:
        """(K, len(offsets)) integrals of factor k over [o - w/2, o + w/2] (axis 0 = Y)."""
        cum = self.cum_y if axis == 0 else self.cum_x
        edges = self.lo_um + np.arange(cum.shape[1]) * self.bin_um
        o = np.asarray(offsets_um, dtype=np.float64)
        out = np.empty((cum.shape[0], o.size))
        for k in range(cum.shape[0]):
            hi = np.interp(o + width_um / 2, edges, cum[k])
            lo = np.interp(o - width_um / 2, edges, cum[k])
            out[k] = hi - lo
        return out

    @property
    def half_um(self) -> float:
        """Half width of the own-path support (um)."""
        return max(abs(self.lo_um), abs(self.lo_um + (self.cum_x.shape[1] - 1) * self.bin_um))


def paraxial_kernel(design: Design, z_mm: float, bin_um: float = 1.0) -> ScanKernel:
    """Rank-1 closed-form own-path kernel (rectangular holes, paraxial)."""
    lo_x, hi_x = paraxial_support(design, z_mm, 0)
    lo_y, hi_y = paraxial_support(design, z_mm, 1)
    half = max(abs(lo_x), abs(hi_x), abs(lo_y), abs(hi_y)) + 2 * bin_um
    n = int(np.ceil(2 * half / bin_um))
    lo = -n * bin_um / 2
    edges = lo + np.arange(n + 1) * bin_um
    cy = paraxial_cumulative(design, z_mm, edges, 1)
    cx = paraxial_cumulative(design, z_mm, edges, 0)
    return ScanKernel(z_mm, lo, bin_um, cy[None, :], cx[None, :], np.ones(1))


def separable_terms(
    m: np.ndarray, rank_tol: float = 0.02, max_rank: int = 4, partial: bool = False
):
    """SVD of a 2-D map [y, x] into (scale, u (K, ny), v (K, nx)), signs made positive.
    ``partial``: only the leading ``max_rank`` + 1 terms, by a randomized range finder
    (:func:`_randomized_svd`; for the wave engine's large maps)."""
    if partial and min(m.shape) > 4 * (max_rank + 8):
        u, s, vt = _randomized_svd(m, max_rank + 1)
    else:
        u, s, vt = np.linalg.svd(m, full_matrices=False)
    k = int(max(1, min(max_rank, np.sum(s > rank_tol * s[0]))))
    u, s, vt = u[:, :k].T.copy(), s[:k].copy(), vt[:k].copy()
    for i in range(k):  # make the dominant term's factors positive
        if u[i].sum() < 0:
            u[i] *= -1
            vt[i] *= -1
    return s, u, vt


def _randomized_svd(m: np.ndarray, k: int, oversample: int = 8, power: int = 3):
    """The leading ``k`` singular triplets of ``m`` (Halko, Martinsson & Tropp 2011: a
    Gaussian sketch of k + ``oversample`` columns, ``power`` subspace iterations, then
    the exact SVD of the small projection); seeded, so the kernels are reproducible."""
    omega = np.random.default_rng(0).standard_normal((m.shape[1], k + oversample))
    q = np.linalg.qr(m @ omega)[0]
    for _ in range(power):
        q = np.linalg.qr(m @ np.linalg.qr(m.T @ q)[0])[0]
    ub, s, vt = np.linalg.svd(q.T @ m, full_matrices=False)
    return (q @ ub)[:, :k], s[:k], vt[:k]


def map_kernel(
    z_mm: float,
    own: np.ndarray,
    lo_um: float,
    bin_um: float,
    rank_tol=0.02,
    max_rank=4,
    partial: bool = False,
) -> ScanKernel:
    """A kernel from a near-field map [y, x] (um^2 sr per bin, bins of ``bin_um`` from
    ``lo_um`` in x and y about the pixel's axis), separated by SVD (``partial``: as
    :func:`separable_terms`)."""
    s, u, v = separable_terms(own, rank_tol, max_rank, partial)
    zero = np.zeros((s.size, 1))
    cy = np.hstack([zero, np.cumsum(u, axis=1)])
    cx = np.hstack([zero, np.cumsum(v, axis=1)])
    return ScanKernel(float(z_mm), lo_um, bin_um, cy, cx, s)


def _with_ghost(k: ScanKernel, maps: TracedMaps, iz: int) -> ScanKernel:
    """``k`` with the coarse ghost map of ``maps`` at its ``iz``-th distance."""
    return replace(
        k, ghost=maps.ghost[iz], ghost_lo_um=maps.coarse_lo_um, ghost_bin_um=maps.coarse_bin_um
    )


def traced_kernels(
    maps: TracedMaps, ghosts: bool = True, rank_tol: float = 0.02, max_rank: int = 4
) -> list[ScanKernel]:
    """Kernels from traced maps (own path by SVD, ghost map kept coarse)."""
    out = []
    for iz, z in enumerate(maps.z_mm):
        k = map_kernel(z, maps.own[iz], maps.fine_lo_um, maps.fine_bin_um, rank_tol, max_rank)
        out.append(_with_ghost(k, maps, iz) if ghosts else k)
    return out


#: bin of the wave engine's near-field maps that wave kernels are made of (um): the traced
#: kernels' (maps.traced_map_sets fine_bin_um)
WAVE_BIN_UM = 4.0
#: separable terms of a wave map kept down to this fraction of the first singular value:
#: the prototype's near crosstalk from the staggered row (300-600 um away in y, 0.06 % of
#: the light) makes terms of 3e-4 and 4e-5, and puts the map's y centroid at +0.107,
#: +0.168, +0.229 um (0.5, 2, 3.5 mm); rank 1 (the traced kernels' 0.02) gave +0.002 to
#: +0.006 and a fit of scans made so put the layers' y shifts 15 errors off (docs/fit.md),
#: rank 2 (1e-4) +0.119, +0.187, +0.254, rank 3 (this) +0.106, +0.166, +0.227
WAVE_RANK_TOL = 3e-5
#: wavelengths per LED of a colour scanner's grey light in the wave kernels
#: (:func:`~opticalstamp.analysis.spectrum.grey_light`): its LEDs' bands are 18-32 nm
#: wide; at 3 per LED (the RMTF's channels) the prototype's LSFs at 0.5-3.5 mm move by
#: 3e-4 of the light in L1, its light by 1.5e-5 and the centre cell's share by 1e-5, at
#: 2.5 times the cost (the rgb quick report's scans 27 s)
GREY_POINTS = 1


def wave_near_kernels(
    design: Design, z_mm, row: int, fresnel: bool = False, progress: bool = False
) -> list[ScanKernel]:
    """One row's near-field kernels by wave optics at each height, the stack traversed
    once: the wave engine's map of the light in its band (own path, its diffraction,
    near crosstalk; :func:`~opticalstamp.analysis.wavespectral.wave_response_spectral`,
    under the light of the design's grey scans,
    :func:`~opticalstamp.analysis.spectrum.grey_light`: a colour scanner's three LEDs lit
    together at the luminance weights) on ``WAVE_BIN_UM`` bins, SVD-separated (partial
    SVD, terms down to ``WAVE_RANK_TOL`` of the first).
    :func:`stamp_kernel_sets` adds the traced ghost map of the light beyond the band
    (traced with ``outside_band``): the join of :mod:`~opticalstamp.analysis.responsivity`.
    ``fresnel``: the wave engine's Fresnel losses (:mod:`~opticalstamp.analysis.wavefilter`),
    as the traced part has them. Holes that are not rectangles take the 2-D path's maps
    (minutes a height on a CPU; ``progress``: its bar and expected cost)."""
    from ..analysis.responsivity import resolve_optics
    from ..analysis.spectrum import grey_light
    from ..analysis.wave import one_blas_thread
    from ..analysis.wavespectral import wave_response_spectral

    opt = resolve_optics(design, "wave", channels=True)  # a colour scanner's: mixed
    zs = np.asarray(z_mm, dtype=np.float64)
    r = wave_response_spectral(
        design,
        zs,
        spectrum=grey_light(design, GREY_POINTS),
        pixel=(row, 0),
        sampling=opt.sampling,
        fresnel=fresnel,
        progress=progress,
    )
    out = []
    with one_blas_thread():  # thin products: BLAS's threads only spin (the engine's rule)
        for iz, z in enumerate(zs):
            edges, m = r.spot(iz, WAVE_BIN_UM)
            k = map_kernel(
                z, m * WAVE_BIN_UM**2, float(edges[0]), WAVE_BIN_UM, WAVE_RANK_TOL, partial=True
            )
            out.append(k)
    return out


def mirrored_y(k: ScanKernel) -> ScanKernel:
    """``k`` mirrored in Y (R(X, -Y)): its Y factors reversed on a grid symmetric about the
    pixel's axis (a wave kernel's: :func:`wave_near_kernels`), the cumulative tables
    cum'(i) = cum(n) - cum(n - i); the ghost map is the caller's (the traced one of
    the row)."""
    n = k.cum_y.shape[1] - 1
    if abs(2 * k.lo_um + n * k.bin_um) > 1e-9 * max(1.0, abs(k.lo_um)):
        raise ValueError("kernels: a grid not symmetric about the pixel's axis")
    cum_y = k.cum_y[:, -1:] - k.cum_y[:, ::-1]
    return replace(k, cum_y=cum_y)


def kernel_source(design: AnyDesign, source: str = "auto", fresnel: bool = False) -> str:
    """What ``source`` means for this design: "paraxial" or "trace" (see :func:`scan_kernels`;
    each kind of design says, :func:`~opticalstamp.imaging.kinds.scanner_of`).

    Raises
    ------
    ValueError
        For an unknown source, "paraxial" with circular holes, or anything but "auto" and
        "trace" for a rod-lens array.
    """
    from .kinds import scanner_of

    return scanner_of(design).kernel_source(design, source, fresnel)


def _rays(source: str, n_rays: int) -> int:
    """Rays traced for kernels of this source (ghost maps alone need no more than 2^20)."""
    return n_rays if source == "trace" else min(n_rays, 1 << 20)


def scan_kernels(
    design: AnyDesign,
    z_mm,
    *,
    source: str = "auto",
    ghosts: bool = True,
    fresnel: bool = False,
    n_rays: int = RAYS_MAP,
    seed: int = 0,
    progress: bool = False,
    tracer: PixelTracer | None = None,
) -> list[list[ScanKernel]]:
    """Kernels [row][level] for the used-pixel rows at the distances ``z_mm``.

    ``source``: "paraxial" (closed form own path; needs rectangular holes), "trace" (own
    path from the exact tracer, SVD-separated), or "auto" (paraxial where the holes are
    rectangular, Fresnel losses are off and no own-path ray is steeper than
    ``PARAXIAL_MAX_SLOPE`` (:func:`~opticalstamp.analysis.paraxial.paraxial_max_slope`: a stack
    much thinner than its holes is not paraxial), else trace). Ghost maps always come from
    the tracer (2^20 rays are plenty for 0.5 mm bins). ``tracer``: a PixelTracer of this
    design whose pilot runs to reuse (the kernels are the same with or without it).
    """
    (out,) = _kernel_sets(design, [z_mm], source, ghosts, fresnel, n_rays, seed, progress, tracer)
    return out


def _kernel_sets(
    design: AnyDesign,
    z_sets,
    source: str,
    ghosts: bool,
    fresnel: bool,
    n_rays: int,
    seed: int,
    progress: bool,
    tracer: PixelTracer | None,
) -> list[list[list[ScanKernel]]]:
    """Kernels [set][row][level] for each set of distances, from one trace per row
    (a rod-lens array: [set][phase class][level], from one trace)."""
    from .kinds import scanner_of

    kind = scanner_of(design)
    source = kind.kernel_source(design, source, fresnel)
    return kind.kernel_sets(design, z_sets, source, ghosts, fresnel, n_rays, seed, progress, tracer)


def stamp_kernel_sets(
    design: Design,
    z_sets,
    source: str,
    ghosts: bool,
    fresnel: bool,
    n_rays: int,
    seed: int,
    progress: bool,
    tracer: PixelTracer | None,
) -> list[list[list[ScanKernel]]]:
    """A stamp's kernels [set][row][level] for each set of distances (``source`` resolved:
    "paraxial", "trace" or "wave"), from one trace per row where anything is traced."""
    sampling = Sampling(_rays(source, n_rays), seed, fresnel)
    tr = tracer_for(design, sampling, tracer)  # one reverse path for every row
    band, twins, wave_rows = None, [], {}
    if source == "wave":  # the tracer keeps the light beyond the wave engine's band
        from ..analysis.responsivity import resolve_optics
        from ..analysis.spectrum import grey_light
        from ..analysis.wavespectral import mirror_rows

        opt = resolve_optics(design, "wave", channels=True)  # the grey light's band
        band, twins = opt.band, mirror_rows(design, opt.sampling, grey_light(design, GREY_POINTS))
    out = [[] for _ in z_sets]
    for row in range(design.sensor.rows):
        maps = [None] * len(z_sets)
        if z_sets and (source == "trace" or ghosts):
            maps = traced_map_sets(
                design,
                z_sets=z_sets,
                row=row,
                sampling=sampling,
                tracer=tr,
                progress=progress,
                outside_band=band,
            )
        near = {}
        if source == "wave":  # every set's heights from one wave run of the row
            zs = sorted({float(z) for z_mm in z_sets for z in np.atleast_1d(z_mm)})
            twin = twins[row]
            if twin is None:
                ks = wave_near_kernels(design, zs, row, fresnel, progress)
                near = dict(zip(zs, ks, strict=True))
                wave_rows[row] = near
            else:  # row A's view mirrored in y (the nominal staggered lattice)
                near = {z: mirrored_y(k) for z, k in wave_rows[twin].items()}
        for ks, z_mm, m in zip(out, z_sets, maps, strict=True):
            if source == "wave":
                row_k = [near[float(z)] for z in np.atleast_1d(z_mm)]
                ks.append([_with_ghost(k, m, i) if ghosts else k for i, k in enumerate(row_k)])
            else:
                ks.append(_row_kernels(design, z_mm, source, ghosts, m))
    return out


def _row_kernels(
    design: Design, z_mm, source: str, ghosts: bool, maps: TracedMaps | None
) -> list[ScanKernel]:
    """One row's kernels at each distance, from its traced maps (where traced)."""
    if source == "trace":
        return traced_kernels(maps, ghosts=ghosts)
    ks = []
    for iz, z in enumerate(np.asarray(z_mm, dtype=np.float64)):
        k = paraxial_kernel(design, float(z))
        ks.append(_with_ghost(k, maps, iz) if ghosts else k)
    return ks


@dataclass(frozen=True)
class KernelCache:
    """Scan kernels of one design, built once for several scans (:func:`kernel_cache`).

    Attributes
    ----------
    fingerprint : the design's fingerprint
    source : "paraxial" or "trace", as resolved by :func:`kernel_source`
    ghosts, fresnel, seed : how the kernels were made
    n_rays : rays traced per row
    kernels : kernels [row][level] by the tuple of levels (mm) of a scan
    """

    fingerprint: str
    source: str
    ghosts: bool
    fresnel: bool
    n_rays: int
    seed: int
    kernels: Mapping[tuple[float, ...], list[list[ScanKernel]]]

    def lookup(
        self,
        design: AnyDesign,
        levels,
        *,
        source: str = "auto",
        ghosts: bool = True,
        fresnel: bool = False,
        n_rays: int = RAYS_MAP,
        seed: int = 0,
    ) -> list[list[ScanKernel]]:
        """Kernels [row][level]: what ``scan_kernels(design, levels, ...)`` returns.

        A cache with ghost maps serves scans without them (the maps are dropped).

        Raises
        ------
        ValueError
            Where the cache was made for another design, other settings or other levels.
        """
        src = kernel_source(design, source, fresnel)
        want = {
            "design": design.fingerprint(),
            "kernel source": src,
            "fresnel": fresnel,
            "rays": _rays(src, n_rays),
            "seed": seed,
        }
        have = {
            "design": self.fingerprint,
            "kernel source": self.source,
            "fresnel": self.fresnel,
            "rays": self.n_rays,
            "seed": self.seed,
        }
        for name, v in want.items():
            if have[name] != v:
                raise ValueError(f"kernels: built for {name} {have[name]!r}, not {v!r}")
        if ghosts and not self.ghosts:
            raise ValueError("kernels: built without ghost light, the scan needs it")
        key = tuple(float(z) for z in levels)
        if key not in self.kernels:
            raise ValueError(f"kernels: none built for the levels {list(key)} mm")
        rows = self.kernels[key]
        if ghosts or not self.ghosts:
            return rows
        return [[k.without_ghosts() for k in ks] for ks in rows]


def kernel_cache(
    design: AnyDesign,
    level_sets,
    *,
    source: str = "auto",
    ghosts: bool = True,
    fresnel: bool = False,
    n_rays: int = RAYS_MAP,
    seed: int = 0,
    progress: bool = False,
    tracer: PixelTracer | None = None,
) -> KernelCache:
    """Kernels for the scans at each set of levels, from one trace per row.

    Parameters
    ----------
    level_sets : sequence of sequences of distances (mm), one per scan (a scan's levels,
        :func:`opticalstamp.imaging.scan.scan_levels`); repeated sets are built once
    others : as :func:`scan_kernels`

    Returns
    -------
    KernelCache
        Whose kernels for each set are bit for bit those of
        ``scan_kernels(design, levels, ...)``: the same rays are binned onto each set's
        maps.
    """
    keys = list(dict.fromkeys(tuple(float(z) for z in zs) for zs in level_sets))
    src = kernel_source(design, source, fresnel)
    sets = _kernel_sets(design, keys, src, ghosts, fresnel, n_rays, seed, progress, tracer)
    return KernelCache(
        design.fingerprint(),
        src,
        ghosts,
        fresnel,
        _rays(src, n_rays),
        seed,
        dict(zip(keys, sets, strict=True)),
    )
