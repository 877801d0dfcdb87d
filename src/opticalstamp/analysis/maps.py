"""2-D responsivity maps of the used pixels on the object plane, for the scan simulation.

One trace per row tallies, at each object distance, the own-path light on a fine grid
around the pixel and the ghost light on a coarse grid over the wide field it reaches
(:func:`traced_maps`, :func:`traced_map_sets`); :mod:`opticalstamp.imaging.kernels` turns
them into scan kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..defaults import MAP_MAX_BINS, RAYS_MAP
from ..design import Design, square_holes
from ..raytrace.pixel import PixelTracer, Sampling, tracer_for
from ..validate import check_memory
from .paraxial import paraxial_support


@numba.njit(parallel=True, cache=True)
def _maps(
    x,
    y,
    sx,
    sy,
    w,
    own,
    x0,
    y0,
    z_um,
    n_obj,
    fine_lo,
    fine_bin,
    coarse_lo,
    coarse_bin,
    fine,
    coarse,
):  # pragma: no cover
    """fine[iz, iy, ix] += own-path w; coarse[iz, iy, ix] += ghost w (prange over z)."""
    nfy, nfx = fine.shape[1], fine.shape[2]
    ncy, ncx = coarse.shape[1], coarse.shape[2]
    for iz in numba.prange(z_um.size):
        z = z_um[iz]
        for i in range(x.size):
            wi = w[i]
            if wi == 0.0:
                continue
            c = np.sqrt(n_obj * n_obj - sx[i] * sx[i] - sy[i] * sy[i])
            xo = x[i] + z * sx[i] / c - x0
            yo = y[i] + z * sy[i] / c - y0
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
    sets = []  # per set: Z (mm), fine grid start and bin, fine and coarse tallies
    for z_mm in z_sets:
        zs = np.asarray(z_mm, dtype=np.float64)
        half = _own_half_width(design, float(zs.max())) if half_um is None else half_um
        # a spot wider than MAP_MAX_BINS bins (a stack too thin to confine the light):
        # coarser bins, never a grid that does not fit in memory
        fine_bin = max(fine_bin_um, 2 * half / MAP_MAX_BINS)
        nf = int(np.ceil(2 * half / fine_bin))
        fine_lo = -nf * fine_bin / 2
        check_memory(
            8.0 * zs.size * max(nf * nf, ncy * ncx),
            f"the responsivity maps of {zs.size} object distances",
        )
        sets.append(
            (zs, fine_lo, fine_bin, np.zeros((zs.size, nf, nf)), np.zeros((zs.size, ncy, ncx)))
        )
    on_gpu = None  # the same maps on the device, where a GPU keeps the rays
    for pb in tr.trace((row, 0), progress=progress):
        b = pb.rays
        if b.device is not None and outside_band is None:
            from . import cuda_tallies as gpu

            on_gpu = on_gpu or [(gpu.zeros(f.shape), gpu.zeros(c.shape)) for *_, f, c in sets]
            for (zs, fine_lo, fine_bin, _, _), (fine, coarse) in zip(sets, on_gpu, strict=True):
                gpu.maps(
                    pb, zs * 1000.0, tr.n_obj, fine_lo, fine_bin, coarse_lo,
                    coarse_bin_um, fine, coarse,
                )  # fmt: skip
            continue
        w = pb.w
        if outside_band is not None:  # ghost rays in the band: the wave engine's
            out = (np.abs(b.sx) >= outside_band) | (np.abs(b.sy) >= outside_band)
            w = w * (pb.own | out)
        for zs, fine_lo, fine_bin, fine, coarse in sets:
            _maps(
                b.x,
                b.y,
                b.sx,
                b.sy,
                w,
                pb.own,
                src.x,
                src.y,
                zs * 1000.0,
                tr.n_obj,
                fine_lo,
                fine_bin,
                coarse_lo,
                coarse_bin_um,
                fine,
                coarse,
            )
    for (*_, fine, coarse), dev in zip(sets, on_gpu or (), strict=False):  # none on a CPU
        fine += dev[0].copy_to_host()
        coarse += dev[1].copy_to_host()
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
        for zs, fine_lo, fine_bin, fine, coarse in sets
    ]


def _own_half_width(design: Design, z_mm: float) -> float:
    """Half width (um) enclosing the own-path spot at z_mm (paraxial bound + 20 % margin).

    For circular holes the bound of the circumscribed squares is used."""
    sq = square_holes(design)
    lo, hi = paraxial_support(sq, z_mm, 0)
    lo_y, hi_y = paraxial_support(sq, z_mm, 1)
    return 1.2 * max(abs(lo), abs(hi), abs(lo_y), abs(hi_y)) + 10.0
