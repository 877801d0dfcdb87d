"""Line-spread functions of the used pixels on the object plane, folded onto chart periods.

A bar chart that varies along x only (paper Eq. 1, Fig. 11) sees a pixel through the
x-marginal of its responsivity map, the *line-spread function* LSF(X) = integral of
R(X, Y) dY (um sr per um of X). For a chart of period P only the LSF folded modulo P
matters: h_P(phi) = sum_m LSF(phi + m P). Both ways to get it are here:

* :func:`traced_folded_lsf` reverse-traces each pixel row once (exact 3-D tracer,
  importance sampling, own and ghost paths, optional Fresnel losses) and folds every ray
  onto every period at every object distance in one compiled pass. Rays are dealt into
  ``n_batches`` interleaved batches (ray id modulo n_batches), which gives the standard
  errors of anything computed from the folded LSF.
* :func:`~opticalstamp.analysis.paraxial.paraxial_folded_lsf` folds the closed form of
  the own path for rectangular holes in the paraxial limit (:mod:`.paraxial`).

The 2-D maps of the scan simulation are :mod:`.maps`'.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..defaults import RAYS_LSF
from ..design import Design
from ..raytrace.pixel import PixelTracer, Sampling, tracer_for
from .tallies import SLOPE_EDGES, FoldTally, fold_bins, run


@dataclass(frozen=True)
class FoldedLSF:
    """LSFs of the used pixels folded onto chart periods.

    Attributes
    ----------
    z_mm : (nz,) object distances above the reference plane (mm)
    periods_um : (np,) chart periods (um)
    rows : list of (x_um, y_um) of the traced pixel of each row (k = 0)
    h : list over periods of arrays (n_rows, n_batches, nz, n_bins_p): etendue
        (um^2 sr) per bin of phase phi = (X - x_pixel) mod P, summed over batches it is
        the full estimate
    method : "trace" or "paraxial"
    n_rays : rays per row (trace) or 0
    ghosts, fresnel : what light is included
    slope_power : (len(SLOPE_EDGES) - 1,) etendue (um^2 sr) per bin of |dX/dZ|, the
        lateral slope along x of the light in the object medium (traced; None where not
        tallied): how fast its image moves with Z (:func:`fast_light`)
    """

    z_mm: np.ndarray
    periods_um: np.ndarray
    rows: list[tuple[float, float]]
    h: list[np.ndarray]
    method: str
    n_rays: int
    ghosts: bool
    fresnel: bool
    slope_power: np.ndarray | None = None

    @property
    def n_batches(self) -> int:
        return self.h[0].shape[1]


def fast_light(lsf: FoldedLSF) -> dict | None:
    """How fast the light's image moves with Z: ``slope`` (lower edges of SLOPE_EDGES)
    and ``beyond``, the fraction of the light whose lateral slope |dX/dZ| in the object
    medium exceeds each. Light of slope t moves one chart period P in Z = P / t: ghost
    copies of a periodic chart (slopes far from the own path's) make the RMTF oscillate
    with that period in Z, which a coarser grid aliases (:func:`~opticalstamp.analysis.
    rmtf.crossing_brackets` sets its step from this). None where not tallied."""
    if lsf.slope_power is None or lsf.slope_power.sum() <= 0:
        return None
    beyond = np.cumsum(lsf.slope_power[::-1])[::-1] / lsf.slope_power.sum()
    return {"slope": SLOPE_EDGES[:-1].tolist(), "beyond": beyond.tolist()}


def row_pixels(design: Design) -> list[tuple[int, int]]:
    """(row, k = 0) of the traced pixel of each row of used pixels."""
    return [(r, 0) for r in range(design.sensor.rows)]


def traced_folded_lsf(
    design: Design,
    *,
    z_mm,
    periods_um,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    ghosts: bool = True,
    fresnel: bool = False,
    n_batches: int = 16,
    chunk: int = 1 << 20,
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
    outside_band: float | None = None,
) -> FoldedLSF:
    """Fold each row's traced LSF onto every period at every Z (one trace per row).

    ``sampling`` replaces ``n_rays``, ``seed``, ``fresnel`` and ``chunk`` (its ray count,
    where None, is ``n_rays``; rounded up to a multiple of ``n_batches``). ``tracer``: a
    PixelTracer of this design whose pilot runs to reuse (other analyses of the same
    pixels share them); the sampling is still this call's. ``outside_band``: fold only
    the rays with |s_x| or |s_y| >= this (the light a wave engine of that band leaves to
    the tracer, :mod:`~opticalstamp.analysis.responsivity`); s is conserved through
    the stack, so the test is the same at every plane.
    """
    s = _lsf_sampling(sampling, n_rays, seed, fresnel, chunk, n_batches)
    (lsf,) = _traced_folds(
        design, (ghosts,), z_mm, periods_um, s, n_batches, progress, tracer, outside_band
    )
    return lsf


def traced_folded_lsf_pair(
    design: Design,
    *,
    z_mm,
    periods_um,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    fresnel: bool = False,
    n_batches: int = 16,
    chunk: int = 1 << 20,
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
    outside_band: float | None = None,
) -> tuple[FoldedLSF, FoldedLSF]:
    """All light and the own path alone, folded from one trace per row.

    The parameters are those of :func:`traced_folded_lsf`; ``outside_band`` applies to
    the all-light fold only (the wave engine gives the rest, the own path stays whole).
    Each ray is folded twice: with its weight, and with its weight where it followed
    the own path (the tracer's own-path mask,
    :attr:`~opticalstamp.raytrace.pixel.PixelBatch.own`) and 0 elsewhere.

    Returns
    -------
    (FoldedLSF, FoldedLSF)
        Own and ghost light, and the own path only: bit for bit what
        ``traced_folded_lsf(..., ghosts=True)`` and ``(..., ghosts=False)`` return for
        the same arguments, for the cost of one trace.
    """
    s = _lsf_sampling(sampling, n_rays, seed, fresnel, chunk, n_batches)
    both, own = _traced_folds(
        design, (True, False), z_mm, periods_um, s, n_batches, progress, tracer, outside_band
    )
    return both, own


def folded_subset(lsf: FoldedLSF, z_mm, periods_um) -> FoldedLSF | None:
    """``lsf`` at the given distances and periods only (in the order given), or None where
    ``lsf`` lacks one of them.

    Each (Z, period) of a traced fold is tallied on its own from the same rays in the same
    order, so the subset is bit for bit what the same trace folded onto these distances
    and periods alone gives (same rays, seed, light and Fresnel option).
    """
    zs = np.asarray(z_mm, dtype=np.float64)
    per = np.asarray(periods_um, dtype=np.float64)
    iz = [np.flatnonzero(lsf.z_mm == z) for z in zs]
    ip = [np.flatnonzero(lsf.periods_um == p) for p in per]
    if any(i.size == 0 for i in iz + ip):
        return None
    iz = np.array([i[0] for i in iz])
    h = [np.ascontiguousarray(lsf.h[int(i[0])][:, :, iz, :]) for i in ip]
    return replace(lsf, z_mm=zs, periods_um=per, h=h)


def _lsf_sampling(
    sampling: Sampling | None, n_rays: int, seed: int, fresnel: bool, chunk: int, n_batches: int
) -> Sampling:
    """The sampling of a folded LSF, its ray count rounded up to a multiple of n_batches."""
    if sampling is None:
        sampling = Sampling(n_rays, seed, fresnel, chunk)
    sampling = sampling.or_rays(n_rays)
    return replace(sampling, n_rays=int(np.ceil(sampling.n_rays / n_batches)) * n_batches)


def _traced_folds(
    design: Design,
    kinds: tuple[bool, ...],
    z_mm,
    periods_um,
    sampling: Sampling,
    n_batches: int,
    progress: bool,
    tracer: PixelTracer | None,
    outside_band: float | None = None,
) -> list[FoldedLSF]:
    """One trace per row, folded once per entry of ``kinds`` (True: ghost light too);
    ``outside_band`` as :func:`traced_folded_lsf` for the all-light kinds (tallied on
    the CPU); an own-path fold stays whole (the own path lies inside the band)."""
    n_rays = sampling.n_rays
    tr = tracer_for(design, sampling, tracer)
    zs = np.asarray(z_mm, dtype=np.float64)
    per = np.asarray(periods_um, dtype=np.float64)
    nb = fold_bins(per)
    hs = [[np.zeros((design.sensor.rows, n_batches, zs.size, int(n))) for n in nb] for _ in kinds]
    slope_tallies = [np.zeros(SLOPE_EDGES.size - 1) for _ in kinds]  # over the rows
    rows = []
    for row, k in row_pixels(design):
        src = tr.source((row, k))
        rows.append((src.x, src.y))
        t = FoldTally(kinds, zs, per, n_batches, src.x, tr.n_obj, n_rays, outside_band)
        run(tr, (row, k), [t], progress=progress)
        for tally, sl in zip(slope_tallies, t.slopes, strict=True):
            tally += sl
        for h, out in zip(hs, t.sums, strict=True):
            for p in range(per.size):
                # each batch holds n_rays / n_batches samples: scale so batches sum to the mean
                h[p][row] = out[p, :, :, : nb[p]] / n_rays
    return [
        FoldedLSF(
            zs,
            per,
            rows,
            h,
            "trace",
            n_rays,
            ghosts,
            sampling.fresnel,
            None if np.isnan(sl).any() else sl / len(rows),
        )
        for ghosts, h, sl in zip(kinds, hs, slope_tallies, strict=True)
    ]
