"""The blur of a scan on its own output grid: what restoration deconvolves.

A stamp's scan is a merged line: output column c is read by the used pixel of row
``c mod R`` (R = 2 for the staggered rows), centred at ((m + 1/2) p, (c + 1/2) p) on the
page, p the output pitch. With f[i, j] the page band-limited to the output grid's
Nyquist frequency and sampled at the cell centres, the shading-corrected scan is

    g[m, c] = sum_{i, j} f[i, j] K_{c mod R}[m - i, c - j] + noise,

with K_r the responsivity of row r band-limited the same way and sampled at Y = a p
(+ the row's residual line offset, averaged over the motion smear), X = -b p (+ the
pixel's residual x offset), times p^2, divided by the white signal (own + ghost etendue,
times the white reference) as :func:`~opticalstamp.imaging.scan.simulate_scan`
normalises. The responsivity already integrates over the sensor pixel: integrating it
again over the output cell (the page as cell means) puts a second sinc in the model, 17 %
too little transfer at 200 dpi, and over-sharpens (measured in docs/restore.md). The
model is exact for a band-limited page; a real page's detail finer than the output grid
aliases, the model's error, measured in docs/restore.md, which enters restoration's
regularisation.

The merged image is shift-invariant (one kernel, R = 1 in effect) where the rows'
kernels are equal; :attr:`OutputKernel.row_difference` says how far they are from it.
Restoration handles R phases exactly (:mod:`opticalstamp.imaging.restore`).

Ghost light lands millimetres away, where the page's own blur of a few hundred
micrometres does not matter: it is kept as a coarse kernel (the tracer's 0.5 mm bins)
and removed as a background computed from the scan itself (:func:`ghost_background`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..design import AnyDesign
from ..raytrace.stack import lattice_of
from .convolve import fft_convolve
from .kernels import KernelCache, ScanKernel
from .kinds import scanner_of
from .scan import ScanSettings, kernels_for, pixel_groups, scan_pitch

#: output pixels kept beyond a kernel's support for the band-limited kernel's tails
KERNEL_MARGIN = 24


@dataclass(frozen=True)
class OutputKernel:
    """The own-path blur of each column phase at one height, on the output grid, and the
    ghost light's coarse kernel.

    Attributes
    ----------
    z_mm : float height
    pitch_um : output pitch p
    own : (R, 2 hy + 1, 2 hx + 1) K_r[a, b] at own[r, hy + a, hx + b]; column c uses
        own[c % R]
    ghost : (R, gy, gx) ghost light per coarse cell of ``ghost_cells`` output pixels
        (normalised as own), centred at [gy // 2, gx // 2] in the same (a, b) sense, or
        None
    ghost_cells : output pixels per side of a ghost cell (the tracer's 0.5 mm bins,
        rounded)
    white : the white signal the kernels are divided by (um^2 sr)
    """

    z_mm: float
    pitch_um: float
    own: np.ndarray
    ghost: np.ndarray | None
    ghost_cells: int
    white: float

    @property
    def phases(self) -> int:
        return self.own.shape[0]

    @property
    def own_fraction(self) -> float:
        """Sum of the own kernel (mean over phases): 1 - ghost fraction for a white
        reference of 1."""
        return float(self.own.sum(axis=(1, 2)).mean())

    @property
    def ghost_fraction(self) -> float:
        return 0.0 if self.ghost is None else float(self.ghost.sum(axis=(1, 2)).mean())

    @property
    def row_difference(self) -> float:
        """Largest difference between the phases' own kernels over the largest value: 0
        where the merged image is shift-invariant."""
        k = self.own
        return float(np.abs(k - k.mean(axis=0)).max() / max(np.abs(k).max(), 1e-300))

    def transfer(self, nu_x, nu_y=0.0) -> np.ndarray:
        """The own path's transfer function (mean over phases) at spatial frequencies
        (cycles per output pixel), normalised to 1 at zero frequency: the optics' MTF
        with its sign, sampled by the output cell."""
        hy, hx = self.own.shape[1] // 2, self.own.shape[2] // 2
        k = self.own.mean(axis=0)
        nu = np.atleast_1d(np.asarray(nu_x, dtype=np.float64))
        ph_x = np.exp(-2j * np.pi * np.outer(nu, np.arange(-hx, hx + 1)))
        ph_y = np.exp(-2j * np.pi * float(nu_y) * np.arange(-hy, hy + 1))
        t = np.einsum("ab,a,nb->n", k, ph_y, ph_x).real / k.sum()
        return t if np.ndim(nu_x) else t[0]


def _phase_and_offset(x_pix: np.ndarray, p: float, n_phases: int) -> tuple[int, float]:
    c = np.round(x_pix[0] / p - 0.5)
    return int(c) % n_phases, float(x_pix[0] - (c + 0.5) * p)


def _factor_ft(cum: np.ndarray, lo: float, step: float, xi: np.ndarray) -> np.ndarray:
    """(K, len(xi)) Fourier transforms at ``xi`` (cycles/um) of the separable factors whose
    cumulative tables are ``cum`` (exact for factors uniform within each table bin)."""
    mass = np.diff(cum, axis=1)
    centres = lo + (np.arange(mass.shape[1]) + 0.5) * step
    return (mass @ np.exp(-2j * np.pi * np.outer(centres, xi))) * np.sinc(xi * step)


def _own_grid(k: ScanKernel, p: float, dy: float, dx: float, smear: float) -> np.ndarray:
    """K[a, b]: the responsivity band-limited to the output grid's Nyquist frequency and
    sampled at Y = a p + dy, X = -b p - dx (times p^2), its Y averaged over the motion
    smear. Built from the transfer function, K^(nu_y, nu_x) = R^(nu_y / p, -nu_x / p)
    sinc(nu_y smear / p) exp(2 pi i (nu_y dy + nu_x dx) / p) for |nu| < 1/2 (Poisson
    summation: no aliasing), on a grid wide enough for the band-limited tails."""
    h = int(np.ceil((k.half_um + smear / 2 + abs(dy) + abs(dx)) / p)) + KERNEL_MARGIN
    n = 2 * h + 1
    nu = np.fft.fftfreq(n)  # cycles per output pixel, |nu| < 1/2 (n odd)
    fy = _factor_ft(k.cum_y, k.lo_um, k.bin_um, nu / p)
    fy *= np.sinc(nu * smear / p) * np.exp(2j * np.pi * nu * dy / p)
    fx = _factor_ft(k.cum_x, k.lo_um, k.bin_um, -nu / p) * np.exp(2j * np.pi * nu * dx / p)
    kft = np.einsum("k,ka,kb->ab", k.scale, fy, fx)
    return np.fft.fftshift(np.fft.ifft2(kft).real)


def _ghost_grid(k: ScanKernel, dy: float, dx: float, step: float) -> np.ndarray:
    """The coarse ghost map resampled to [a, b] on a grid of ``step`` um (a: Y = a step +
    dy, b: X = -b step - dx), its total kept."""
    g = k.ghost
    b = k.ghost_bin_um
    y0, x0 = k.ghost_lo_um
    ny, nx = g.shape
    ext = max(abs(y0), abs(y0 + ny * b), abs(x0), abs(x0 + nx * b)) + abs(dy) + abs(dx) + b
    h = int(np.ceil(ext / step)) + 1
    aa, bb = np.meshgrid(np.arange(-h, h + 1), np.arange(-h, h + 1), indexing="ij")
    iy = (aa * step + dy - y0) / b - 0.5
    jx = (-bb * step - dx - x0) / b - 0.5
    out = ndimage.map_coordinates(g, [iy, jx], order=1, mode="constant", cval=0.0)
    total = out.sum()
    return out * (g.sum() / total) if total > 0 else out


def output_kernel(
    design: AnyDesign,
    z_mm: float,
    *,
    settings: ScanSettings | None = None,
    seed: int = 0,
    ghosts: bool = True,
    kernels: list[list[ScanKernel]] | KernelCache | None = None,
) -> OutputKernel:
    """The scan's blur at ``z_mm`` on its output grid, from the same scan kernels (source,
    rays, seed, Fresnel) and the same normalisation as :func:`simulate_scan` with
    ``settings``; ``kernels``: those kernels at [z_mm] when already built."""
    why = scanner_of(design).not_restorable
    if why is not None:
        raise ValueError(
            f"design: restoration kernels are built for aperture-array stamps; {why} (not built)"
        )
    st = settings or ScanSettings()
    if kernels is None or isinstance(kernels, KernelCache):
        kern = kernels_for(design, [z_mm], st, seed=seed, ghosts=ghosts, kernels=kernels)
    else:
        kern = kernels
    p = scan_pitch(design)
    lat = lattice_of(design)
    n_phases = max(1, int(round(lat.pitch / p)))
    groups = pixel_groups(design, 4 * n_phases)
    smear = st.sensor.exposure_duty * p
    cells = max(1, int(round(kern[0][0].ghost_bin_um / p)))
    own: list[np.ndarray | None] = [None] * n_phases
    ghost: list[np.ndarray | None] = [None] * n_phases
    whites = []
    for g in groups:
        k = kern[g.kernel][0]
        r, dx = _phase_and_offset(g.x_um, p, n_phases)
        dy = g.delay * p - g.y_um  # the row's line offset the delay leaves
        white = st.white_reference * (k.own_etendue + k.ghost_etendue)
        whites.append(white)
        own[r] = _own_grid(k, p, dy, dx, smear) / white
        if k.ghost is not None:
            ghost[r] = _ghost_grid(k, dy, dx, cells * p) / white
    if any(o is None for o in own):
        raise ValueError("design: some output columns have no used pixel")
    return OutputKernel(
        z_mm=float(z_mm),
        pitch_um=p,
        own=_stack_centred(own),
        ghost=None if ghost[0] is None else _stack_centred(ghost),
        ghost_cells=cells,
        white=float(np.mean(whites)),
    )


def _stack_centred(arrays: list[np.ndarray]) -> np.ndarray:
    """Arrays of odd shapes, centred, padded with zeros to one shape and stacked."""
    hy = max(a.shape[0] for a in arrays) // 2
    hx = max(a.shape[1] for a in arrays) // 2
    out = np.zeros((len(arrays), 2 * hy + 1, 2 * hx + 1))
    for i, a in enumerate(arrays):
        oy, ox = hy - a.shape[0] // 2, hx - a.shape[1] // 2
        out[i, oy : oy + a.shape[0], ox : ox + a.shape[1]] = a
    return out


def ghost_background(image: np.ndarray, ok: OutputKernel, surround: float | None = None):
    """The ghost light in a scan, K_ghost * page, computed from the scan itself: the
    ghost kernel reaches millimetres, where the scan and the page agree (the own blur
    keeps local means). Zero without a ghost kernel. ``surround``: the page's
    reflectance outside the scan (None: the scan's edge values, repeated)."""
    img = np.asarray(image, dtype=np.float64)
    if ok.ghost is None or ok.ghost_fraction == 0:
        return np.zeros_like(img)
    s = ok.ghost_cells
    gy, gx = ok.ghost.shape[1] // 2, ok.ghost.shape[2] // 2
    pad_y, pad_x = (gy + 1) * s, (gx + 1) * s
    mode = {"mode": "edge"} if surround is None else {"constant_values": surround}
    padded = np.pad(img, ((pad_y, pad_y + s), (pad_x, pad_x + s)), **mode)
    ny, nx = padded.shape[0] // s, padded.shape[1] // s
    coarse = padded[: ny * s, : nx * s].reshape(ny, s, nx, s).mean(axis=(1, 3))
    out = np.empty_like(img)
    cols = np.arange(img.shape[1])
    # coarse cell i covers padded rows [i s, (i + 1) s): centre at (i + 1/2) s - 1/2
    yy = (np.arange(img.shape[0]) + pad_y + 0.5) / s - 0.5
    for r in range(ok.phases):
        conv = fft_convolve(coarse, ok.ghost[r], mode="same")
        sel = cols[cols % ok.phases == r]
        xx = (sel + pad_x + 0.5) / s - 0.5
        yg, xg = np.meshgrid(yy, xx, indexing="ij")
        out[:, sel] = ndimage.map_coordinates(conv, [yg, xg], order=1, mode="nearest")
    return out
