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

from dataclasses import dataclass

import numpy as np

from ..analysis.lsf import (
    TracedMaps,
    paraxial_cumulative,
    paraxial_support,
    traced_maps,
)
from ..design import Design
from ..raytrace.pixel import PixelTracer, Sampling


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
    ghost: np.ndarray | None
    ghost_lo_um: tuple[float, float]
    ghost_bin_um: float

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
    return ScanKernel(z_mm, lo, bin_um, cy[None, :], cx[None, :], np.ones(1), None, (0.0, 0.0), 1.0)


def separable_terms(m: np.ndarray, rank_tol: float = 0.02, max_rank: int = 4):
    """SVD of a 2-D map [y, x] into (scale, u (K, ny), v (K, nx)), signs made positive."""
    u, s, vt = np.linalg.svd(m, full_matrices=False)
    k = int(max(1, min(max_rank, np.sum(s > rank_tol * s[0]))))
    u, s, vt = u[:, :k].T.copy(), s[:k].copy(), vt[:k].copy()
    for i in range(k):  # make the dominant term's factors positive
        if u[i].sum() < 0:
            u[i] *= -1
            vt[i] *= -1
    return s, u, vt


def traced_kernels(
    maps: TracedMaps, ghosts: bool = True, rank_tol: float = 0.02, max_rank: int = 4
) -> list[ScanKernel]:
    """Kernels from traced maps (own path by SVD, ghost map kept coarse)."""
    out = []
    for iz, z in enumerate(maps.z_mm):
        s, u, v = separable_terms(maps.own[iz], rank_tol, max_rank)
        zero = np.zeros((s.size, 1))
        cy = np.hstack([zero, np.cumsum(u, axis=1)])
        cx = np.hstack([zero, np.cumsum(v, axis=1)])
        out.append(
            ScanKernel(
                float(z),
                maps.fine_lo_um,
                maps.fine_bin_um,
                cy,
                cx,
                s,
                maps.ghost[iz] if ghosts else None,
                maps.coarse_lo_um,
                maps.coarse_bin_um,
            )
        )
    return out


def scan_kernels(
    design: Design,
    z_mm,
    *,
    source: str = "auto",
    ghosts: bool = True,
    fresnel: bool = False,
    n_rays: int = 1 << 22,
    seed: int = 0,
    progress: bool = False,
) -> list[list[ScanKernel]]:
    """Kernels [row][level] for the used-pixel rows at the distances ``z_mm``.

    ``source``: "paraxial" (closed form own path; needs rectangular holes), "trace" (own
    path from the exact tracer, SVD-separated), or "auto" (paraxial where the holes are
    rectangular and Fresnel losses are off, else trace). Ghost maps always come from
    the tracer (2^20 rays are plenty for 0.5 mm bins).
    """
    zs = np.asarray(z_mm, dtype=np.float64)
    rect = all(m.shape != "circle" for m in design.masks)
    if source == "auto":
        source = "paraxial" if rect and not fresnel else "trace"
    if source not in ("paraxial", "trace"):
        raise ValueError(f"kernel source must be auto, paraxial or trace (got {source!r})")
    if source == "paraxial" and not rect:
        raise ValueError("paraxial kernels need rectangular holes (this design has circles)")
    rays = n_rays if source == "trace" else min(n_rays, 1 << 20)
    sampling = Sampling(rays, seed, fresnel)
    tracer = PixelTracer(design, sampling)  # one reverse path for every row
    out = []
    for row in range(design.sensor.rows):
        maps = None
        if source == "trace" or ghosts:
            maps = traced_maps(
                design, z_mm=zs, row=row, sampling=sampling, tracer=tracer, progress=progress
            )
        if source == "trace":
            ks = traced_kernels(maps, ghosts=ghosts)
        else:
            ks = []
            for iz, z in enumerate(zs):
                k = paraxial_kernel(design, float(z))
                if ghosts:
                    k = ScanKernel(
                        k.z_mm,
                        k.lo_um,
                        k.bin_um,
                        k.cum_y,
                        k.cum_x,
                        k.scale,
                        maps.ghost[iz],
                        maps.coarse_lo_um,
                        maps.coarse_bin_um,
                    )
                ks.append(k)
        out.append(ks)
    return out
