"""2-D responsivity maps of the used pixels on the object plane, for the scan simulation.

One trace per row tallies, at each object distance, the own-path light on a fine grid
around the pixel and the ghost light on a coarse grid over the wide field it reaches
(:func:`traced_maps`, :func:`traced_map_sets`); :mod:`opticalstamp.imaging.kernels` turns
them into scan kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..defaults import MAP_MAX_BINS, RAYS_MAP
from ..design import Design, square_holes
from ..raytrace.pixel import PixelTracer, Sampling, tracer_for
from ..validate import check_memory
from .paraxial import paraxial_support
from .tallies import MapTally, run


@dataclass(frozen=True)
class TracedMaps:
    """Responsivity maps of one pixel (etendue per bin, um^2 sr) at several Z.

    ``own`` (nz, n, n) on a fine grid of ``fine_bin_um`` starting at ``fine_lo_um`` in x and
    y from the pixel's axis; ``ghost`` (nz, ny, nx) on a coarse grid of
    ``coarse_bin_um`` starting at ``coarse_lo_um`` (y, x).
    """

    z_mm: np.ndarray
    own: np.ndarray
    fine_lo_um: float
    fine_bin_um: float
    ghost: np.ndarray
    coarse_lo_um: tuple[float, float]
    coarse_bin_um: float
    n_rays: int


def traced_maps(
    design: Design,
    *,
    z_mm,
    row: int = 0,
    n_rays: int = RAYS_MAP,
    seed: int = 0,
    fresnel: bool = False,
    fine_bin_um: float = 4.0,
    half_um: float | None = None,
    coarse_bin_um: float = 500.0,
    coarse_half_um: tuple[float, float] = (10_000.0, 45_000.0),
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
) -> TracedMaps:
    """Own-path maps (fine) and ghost maps (coarse) of pixel (row, 0) at every Z.

    ``sampling`` replaces ``n_rays``, ``seed`` and ``fresnel`` (its ray count, where None,
    is ``n_rays``). ``tracer``: a PixelTracer of this design whose pilot runs to reuse
    (other analyses of the same pixel share them); the sampling is still this call's.
    """
    (maps,) = traced_map_sets(
        design,
        z_sets=[z_mm],
        row=row,
        n_rays=n_rays,
        seed=seed,
        fresnel=fresnel,
        fine_bin_um=fine_bin_um,
        half_um=half_um,
        coarse_bin_um=coarse_bin_um,
        coarse_half_um=coarse_half_um,
        progress=progress,
        sampling=sampling,
        tracer=tracer,
    )
    return maps


def traced_map_sets(
    design: Design,
    *,
    z_sets,
    row: int = 0,
    n_rays: int = RAYS_MAP,
    seed: int = 0,
    fresnel: bool = False,
    fine_bin_um: float = 4.0,
    half_um: float | None = None,
    coarse_bin_um: float = 500.0,
    coarse_half_um: tuple[float, float] = (10_000.0, 45_000.0),
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
    outside_band: float | None = None,
) -> list[TracedMaps]:
    """:func:`traced_maps` for several sets of Z from one trace of the pixel.

    ``outside_band``: the ghost maps hold only the rays with |s_x| or |s_y| >= this (the
    light a wave engine of that band leaves to the tracer,
    :mod:`~opticalstamp.analysis.responsivity`); the own-path maps are whole.

    Parameters
    ----------
    z_sets : sequence of sequences of object distances (mm)
    others : as :func:`traced_maps`; where ``half_um`` is None, each set's fine grid
        covers the own-path spot at that set's largest Z, on bins of ``fine_bin_um`` or,
        for a spot wider than ``MAP_MAX_BINS`` of them (a stack too thin to confine the
        light), on that many coarser bins (``TracedMaps.fine_bin_um`` says which)

    Returns
    -------
    list of TracedMaps
        One per set, bit for bit what ``traced_maps(z_mm=z_sets[i], ...)`` returns: the
        same rays are binned onto each set's grids.
    """
    if sampling is None:
        sampling = Sampling(n_rays, seed, fresnel)
    sampling = sampling.or_rays(n_rays)
    tr = tracer_for(design, sampling, tracer)
    src = tr.source((row, 0))
    ncy = int(np.ceil(2 * coarse_half_um[0] / coarse_bin_um))
    ncx = int(np.ceil(2 * coarse_half_um[1] / coarse_bin_um))
    coarse_lo = np.array([-ncy * coarse_bin_um / 2, -ncx * coarse_bin_um / 2])
    sets = []  # per set: Z (mm), fine grid start and bin, fine grid's shape
    for z_mm in z_sets:
        zs = np.asarray(z_mm, dtype=np.float64)
        half = _own_half_width(design, float(zs.max())) if half_um is None else half_um
        # a spot wider than MAP_MAX_BINS bins (a stack too thin to confine the light):
        # coarser bins, never a grid that does not fit in memory
        fine_bin = max(fine_bin_um, 2 * half / MAP_MAX_BINS)
        nf = int(np.ceil(2 * half / fine_bin))
        check_memory(
            8.0 * zs.size * max(nf * nf, ncy * ncx),
            f"the responsivity maps of {zs.size} object distances",
        )
        sets.append((zs, -nf * fine_bin / 2, fine_bin, (nf, nf)))
    t = MapTally(sets, coarse_lo, coarse_bin_um, (ncy, ncx), src.x, src.y, tr.n_obj, outside_band)
    run(tr, (row, 0), [t], progress=progress)
    return [
        TracedMaps(
            zs,
            fine / sampling.n_rays,
            fine_lo,
            fine_bin,
            coarse / sampling.n_rays,
            (float(coarse_lo[0]), float(coarse_lo[1])),
            coarse_bin_um,
            sampling.n_rays,
        )
        for (zs, fine_lo, fine_bin, _), fine, coarse in zip(sets, t.fine, t.coarse, strict=True)
    ]


def _own_half_width(design: Design, z_mm: float) -> float:
    """Half width (um) enclosing the own-path spot at z_mm (paraxial bound + 20 % margin).

    For circular holes the bound of the circumscribed squares is used."""
    sq = square_holes(design)
    lo, hi = paraxial_support(sq, z_mm, 0)
    lo_y, hi_y = paraxial_support(sq, z_mm, 1)
    return 1.2 * max(abs(lo), abs(hi), abs(lo_y), abs(hi_y)) + 10.0
