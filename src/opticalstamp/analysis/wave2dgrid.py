"""The 2-D path's building blocks on a grid: the holes within reach, the masks'
low-passed transmissions, the transfer functions of the slabs and the angular filters
(Fresnel losses, the acceptance cone), on the FFT frequencies of a (y, x) grid; used by
:mod:`.wave2d` (whose docstring states the model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from ..design import Design
from ..raytrace.stack import lattice_of
from ..validate import InputError
from .arrays import CPU, Backend
from .wavebase import in_band

__all__ = ["Hole", "Layer", "angular_filters", "layers_of", "mask_field_2d", "transfer"]


@dataclass(frozen=True)
class Hole:
    """One hole: shape ("rect" or "circle"), centre (um, from the pixel's axis), half
    width and half height (radius for a circle)."""

    shape: str
    cx: float
    cy: float
    hw: float
    hh: float


@dataclass(frozen=True)
class Layer:
    """A mask and the slabs below it (down to the previous mask or the sensor).

    ``slabs``: ((thickness um, index), ...); ``holes``: the holes within reach;
    ``reduced``: the mask's reduced height above the sensor (sum t / n, um).
    """

    slabs: tuple[tuple[float, float], ...]
    holes: tuple[Hole, ...]
    reduced: float


def layers_of(design: Design, pixel: tuple[int, int], reach_um: float) -> list[Layer]:
    """The masks from the sensor up, each with the slabs below it and its holes whose
    centre lies within ``reach_um`` of the pixel's axis (both rows of the lattice)."""
    lat = lattice_of(design)
    row, k = pixel
    if not (0 <= row < lat.n_rows and lat.k_lo <= k <= lat.k_hi):
        raise InputError(f"pixel: no used pixel ({row}, {k})")
    px, py = (float(v) for v in lat.centers(row, k))
    out, below, red = [], [], 0.0
    for sl in design.slabs:
        n = design.index(sl.medium)
        below.append((sl.thickness_um, n))
        red += sl.thickness_um / n
        m = sl.mask_top
        if m is None:
            continue
        holes = []
        for r in range(lat.n_rows):
            cx = lat.row_x[r] + m.offset_x_um - px
            ks = np.arange(lat.k_lo, lat.k_hi + 1)
            ks = ks[np.abs(cx + ks * lat.pitch) <= reach_um + lat.pitch]
            cy = float(lat.row_y[r] + m.offset_y_um - py)
            shape = "circle" if m.shape == "circle" else "rect"
            for c in cx + ks * lat.pitch:
                holes.append(Hole(shape, float(c), cy, m.hole_width_um / 2, m.hole_height_um / 2))
        out.append(Layer(tuple(below), tuple(holes), red))
        below = []
    return out


def mask_field_2d(
    x: np.ndarray, y: np.ndarray, holes, band: float, wavelength_um: float, bk: Backend = CPU
):
    """A mask's transmission on the grid (y, x), low-passed exactly to |lambda nu_x|,
    |lambda nu_y| <= 2 band from the holes' Fourier transforms (the 2-D counterpart of
    :func:`.wave.mask_field`): shape (y.size, x.size), real, on the backend ``bk``."""
    xp = bk.xp
    dx, dy = x[1] - x[0], y[1] - y[0]
    nx, ny = sfft.fftfreq(x.size, dx), sfft.fftfreq(y.size, dy)
    kx = np.flatnonzero(np.abs(wavelength_um * nx) <= 2 * band)
    ky = np.flatnonzero(np.abs(wavelength_um * ny) <= 2 * band)
    fx, fy = nx[kx], ny[ky]
    a = xp.zeros((fy.size, fx.size), dtype=np.complex128)
    rows: dict[tuple, np.ndarray] = {}  # holes of one shape and size on one line in y
    for h in holes:
        ex = np.exp(-2j * np.pi * fx * (h.cx - x[0]))
        key = (h.shape, h.hw, h.hh, h.cy)
        rows[key] = rows[key] + ex if key in rows else ex
    rho = None
    disks: dict[float, object] = {}  # a disk's transform by radius (both rows share it)
    for (shape, hw, hh, cy), ex in rows.items():  # each row: its shape's FT x sum of shifts
        ey = np.exp(-2j * np.pi * fy * (cy - y[0]))
        if shape == "circle":
            if rho is None:  # |f| on the backend (1e6 points: computed where they live)
                rho = xp.hypot(bk.put(fy)[:, None], bk.put(fx)[None, :])
                zero = rho == 0
                safe = xp.where(zero, 1.0, rho)
            if hw not in disks:
                disks[hw] = xp.where(zero, np.pi * hw * hw, hw * bk.j1(2 * np.pi * hw * rho) / safe)
            a += disks[hw] * bk.put(ey)[:, None] * bk.put(ex)[None, :]
        else:
            sx = 2 * hw * np.sinc(2 * hw * fx) * ex
            sy = 2 * hh * np.sinc(2 * hh * fy) * ey
            a += bk.put(np.outer(sy, sx))
    full = xp.zeros((y.size, x.size), dtype=np.complex128)
    full[bk.put(ky)[:, None], bk.put(kx)] = a
    return bk.ifft2(full).real / (dx * dy)


def transfer(
    x: np.ndarray,
    y: np.ndarray,
    slabs,
    wavelength_um: float,
    band: float,
    propagator: str,
    *,
    relative: bool = False,
    bins: tuple | None = None,
    xp=np,
):
    """Transfer function through ``slabs`` ((t, n), ...) on the FFT frequencies of the
    grid, band |lambda f_x|, |lambda f_y| < band (0 outside): shape (y.size, x.size), or
    on the FFT bins ``bins`` = (ky, kx) alone: shape (ky.size, kx.size); computed by the
    array module ``xp`` (NumPy, or CuPy for an array on the GPU: the same arithmetic).

    exact: prod exp(2 pi i t (sqrt((n / lambda)^2 - f^2) - n / lambda)); paraxial:
    prod exp(-i pi lambda t f^2 / n). ``relative``: exact over paraxial (no band).
    """
    lam = wavelength_um
    fx = sfft.fftfreq(x.size, x[1] - x[0])
    fy = sfft.fftfreq(y.size, y[1] - y[0])
    if bins is not None:
        fy, fx = fy[bins[0]], fx[bins[1]]
    inside = in_band(fx[None, :], lam, band) & in_band(fy[:, None], lam, band)
    fx, fy = xp.asarray(fx)[None, :], xp.asarray(fy)[:, None]
    f2 = fx * fx + fy * fy
    phase = xp.zeros_like(f2)
    for t, n in slabs:
        par = -np.pi * lam * t * f2 / n
        if propagator == "paraxial" and not relative:
            phase += par
            continue
        k = n / lam
        ex = 2 * np.pi * t * (xp.sqrt(xp.maximum(k * k - f2, 0.0)) - k)
        phase += ex - par if relative else ex
    h = xp.exp(1j * phase)
    if relative:
        return h
    return xp.where(xp.asarray(inside), h, 0.0)


def angular_filters(
    design: Design, x: np.ndarray, y: np.ndarray, lam: float, fresnel: bool, bins=None
):
    """The amplitude filters on the angular spectrum of the grid (y, x), one per group of
    interfaces between masks (:mod:`.wavefilter`: group 0 below the sensor-side mask with
    the pixel's acceptance cone, group i between masks i - 1 and i, the last above the
    object-side mask): exactly, as functions of |s| (no separable approximation in 2-D);
    None where a group changes nothing. ``bins`` = (ky, kx): on those FFT bins alone."""
    from .wavefilter import cone_cut, group_transmittance, interfaces

    fx = sfft.fftfreq(x.size, x[1] - x[0])
    fy = sfft.fftfreq(y.size, y[1] - y[0])
    if bins is not None:
        fy, fx = fy[bins[0]], fx[bins[1]]
    fx, fy = fx[None, :], fy[:, None]
    s = lam * np.sqrt(fx * fx + fy * fy)
    n_groups = len(design.masks) + 1
    out: list[np.ndarray | None] = [None] * n_groups
    if fresnel:
        for g in range(n_groups):
            pairs = [(n1, n2) for gi, n1, n2 in interfaces(design) if gi == g]
            if pairs:
                out[g] = np.sqrt(group_transmittance(pairs, s))
    cut = cone_cut(design)
    if cut < math.inf:
        cone = (s <= cut).astype(np.float64)
        out[0] = cone if out[0] is None else out[0] * cone
    return out
