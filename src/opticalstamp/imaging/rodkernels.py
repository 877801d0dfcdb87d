"""Scan kernels of a rod-lens array: each pixel's responsivity map by its phase on the rods.

A rod-lens array is not shift-invariant along x: a pixel's map depends on where it sits
relative to the rod lattice (period 2R along x; the ripple of
:func:`opticalstamp.analysis.rodlens.rod_efficiency`). The pixels are sorted into
``phases`` classes by x modulo 2R; each class gets the map traced from a pixel at the
class's centre, relative to the pixel's own centre (at focus the erect 1:1 image of a
pixel lies on the pixel whatever the phase, so the residual error of the class is the
ripple's variation over 2R / phases). Maps are binned on a square grid, SVD-separated as
the stamp's traced maps are (:func:`.kernels.separable_terms`), and returned as
:class:`.kernels.ScanKernel` [phase][level]: the scan applies them like the stamp's rows.
A rod-lens array has no ghost path in the model (no ghost map).
"""

from __future__ import annotations

import math

import numpy as np

from ..design.rodlens import RodLensDesign
from ..raytrace.rodlens import trace_rods
from ..units import mm_to_um
from .kernels import ScanKernel, separable_terms

#: Phase classes of the pixels over one rod period.
PHASES = 16
#: Fine grid of the maps (um).
MAP_BIN_UM = 5.0
#: Separable terms kept (a defocused rod image is round, not separable: more than a stamp).
MAX_RANK = 4
RANK_TOL = 0.03  # above the noise floor of the maps at RAYS_MAP rays


def phase_centres(design: RodLensDesign, phases: int = PHASES) -> np.ndarray:
    """x (um) of each phase class's centre within one rod period [0, 2R)."""
    period = 2 * design.array.rod_radius_um
    return (np.arange(phases) + 0.5) * period / phases


def phase_of(design: RodLensDesign, x_um: np.ndarray, phases: int = PHASES) -> np.ndarray:
    """Phase class of pixels centred at ``x_um``."""
    period = 2 * design.array.rod_radius_um
    return np.minimum((np.mod(x_um, period) / period * phases).astype(np.int64), phases - 1)


def rod_kernel_sets(
    design: RodLensDesign,
    z_sets,
    *,
    fresnel: bool = False,
    n_rays: int,
    seed: int = 0,
    phases: int = PHASES,
    progress: bool = False,
) -> list[list[list[ScanKernel]]]:
    """Kernels [set][phase][level] for each set of heights (mm), from one trace."""
    centres = phase_centres(design, phases)
    rays = trace_rods(design, centres, n_rays=n_rays, seed=seed, fresnel=fresnel, progress=progress)
    pix = rays.pixel
    w = rays.ray_weights()
    out = []
    for z_mm in z_sets:
        per_phase: list[list[ScanKernel]] = [[] for _ in range(phases)]
        for z in z_mm:
            h = mm_to_um(float(z))
            dx = rays.landing_x(h, design.glass_index) - centres[pix]
            dy = rays.landing_y(h, design.glass_index)
            half = max(float(np.abs(dx).max(initial=0)), float(np.abs(dy).max(initial=0)))
            n = max(2, math.ceil((half + MAP_BIN_UM) * 2 / MAP_BIN_UM))
            lo = -n * MAP_BIN_UM / 2
            iy = np.clip(((dy - lo) / MAP_BIN_UM).astype(np.int64), 0, n - 1)
            ix = np.clip(((dx - lo) / MAP_BIN_UM).astype(np.int64), 0, n - 1)
            maps = np.bincount((pix * n + iy) * n + ix, weights=w, minlength=phases * n * n)
            for g, m in enumerate(maps.reshape(phases, n, n)):
                per_phase[g].append(_kernel(float(z), lo, m))
        out.append(per_phase)
    return out


def _kernel(z_mm: float, lo_um: float, m: np.ndarray) -> ScanKernel:
    if not m.any():
        zero = np.zeros((1, m.shape[0] + 1))
        return ScanKernel(z_mm, lo_um, MAP_BIN_UM, zero, zero.copy(), np.zeros(1))
    s, u, v = separable_terms(m, RANK_TOL, MAX_RANK)
    zero = np.zeros((s.size, 1))
    cy = np.hstack([zero, np.cumsum(u, axis=1)])
    cx = np.hstack([zero, np.cumsum(v, axis=1)])
    return ScanKernel(z_mm, lo_um, MAP_BIN_UM, cy, cx, s)
