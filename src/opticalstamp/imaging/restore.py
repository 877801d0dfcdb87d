"""Restoration: a scan deconvolved with the scanner's own known blur.

The forward model (:mod:`opticalstamp.imaging.outputkernel`): g = A f + b + n on the
output grid, A the own-path blur of R column phases (output column c read through
kernel K_{c mod R}), b the ghost light (computed from the scan), n the sensor noise plus
the model's error (the page's detail finer than an output cell).

All three methods solve on a padded FFT grid and handle the R phases exactly. In the
Fourier domain (DFT length N along x, N a multiple of R) masking the columns of phase r
mixes frequency k with k + q N / R:

    G[k] = sum_q B_q[k - q N / R] F[k - q N / R],  B_q = (1/R) sum_r w^(-q r) K_r^,

w = exp(2 pi i / R), so the normal equations (A^H A + D) F = A^H G decouple into R x R
systems over the frequency groups {k0 + t N / R} (R = 1: a division). With equal
kernels B_q = 0 for q != 0 and this is the ordinary shift-invariant deconvolution.

Methods
-------
wiener : F = (A^H A + sigma^2 / S)^-1 A^H G, with sigma^2 the noise variance per pixel
    (sensor noise at mid-grey from the design's electronics, plus the model error
    squared) and S(nu) = c / (|nu|^2 + nu0^2) the power spectrum of a page (documents are
    close to 1/f^2), c set so that a page's variance is ``prior_variance``. Nothing is
    tuned per image.
rl : Richardson-Lucy, f <- f A^T(g / (A f + b)) / A^T 1, from a flat start, a fixed
    number of iterations (30).
tv : total variation by ADMM, min 1/(2 sigma^2) |A f + b - g|^2 + |grad f|_1 / beta,
    beta the mean gradient magnitude of a page (measured on the text chart),
    rho = 1 / beta ... the f-step is the same R x R solve with D = rho |grad^|^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from ..design import Design
from .heightmap import check_heights
from .heightmap import sample as sample_height
from .kernels import KernelCache
from .outputkernel import OutputKernel, ghost_background, output_kernel
from .scan import ScanSettings, kernels_for, prepare_kernels, scan_levels, scan_pitch
from .sensor import SensorModel

METHODS = ("wiener", "rl", "tv")
#: rms error of the output-grid model on text (docs/restore.md: the page's detail finer
#: than an output cell, aliased): it adds to the sensor noise in the regularisation
MODEL_ERROR = 0.01
#: variance of a page's reflectance (text: ink cover ~12 %: 0.12 x 0.88)
PRIOR_VARIANCE = 0.1
#: the page spectrum's corner (cycles per output pixel): 1/f^2 above it
PRIOR_CORNER = 0.01
#: mean |grad f| per output pixel of a page (the 8-pt text chart at 300 dpi)
TV_SCALE = 0.06
RL_ITERATIONS = 30
TV_ITERATIONS = 60
GREY = 0.5  # the grey level at which the sensor noise is taken


def noise_sigma(sensor: SensorModel, white_etendue_um2sr: float, model_error: float) -> float:
    """Noise per output pixel (in units of white) at mid-grey, the model error added in
    quadrature: shot noise, dark shot noise, read noise and quantisation of the design's
    electronics."""
    white = sensor.electrons_per_um2sr * white_etendue_um2sr
    var_e = GREY * white + sensor.dark_e + sensor.read_noise_e**2 + sensor.gain_e_per_dn**2 / 12
    return float(np.sqrt(var_e / white**2 + model_error**2))


#: rows' kernels that differ by less than this (relative to the largest value) are one
#: kernel: the merged image is shift-invariant to far below the model error, and real
#: FFTs in single precision do (the prototype's rows: 1e-4 to 5e-4)
STATIONARY_TOLERANCE = 2e-3


@dataclass(frozen=True)
class Grid:
    """The padded FFT grid of one restoration: the image sits at [py:py+h, px:px+w];
    ``real``: real FFTs (one kernel), else complex ones (R coupled phases)."""

    shape: tuple[int, int]
    py: int
    px: int
    h: int
    w: int
    phases: int
    real: bool = False

    @property
    def nu(self) -> tuple[np.ndarray, np.ndarray]:
        """Frequencies (cycles per pixel) of the grid's spectra (half a spectrum in x for
        real FFTs)."""
        ny, nx = self.shape
        fx = sfft.rfftfreq(nx) if self.real else sfft.fftfreq(nx)
        return sfft.fftfreq(ny)[:, None], fx[None, :]

    def spectrum_mean(self, a: np.ndarray) -> float:
        """The mean of a symmetric spectrum ``a`` (on :attr:`nu`) over the whole DFT grid."""
        if not self.real:
            return float(a.mean())
        nx = self.shape[1]
        w = np.full(a.shape[1], 2.0)
        w[0] = 1.0
        if nx % 2 == 0:
            w[-1] = 1.0
        return float((a * w).sum() / (self.shape[0] * nx))


def _grid(shape: tuple[int, int], ok: OutputKernel, stationary: bool = False) -> Grid:
    hy, hx = ok.own.shape[1] // 2, ok.own.shape[2] // 2
    r = 1 if stationary else ok.phases
    py = 2 * hy + 8
    px = ok.phases * int(np.ceil((2 * hx + 8) / ok.phases))  # keeps each column's phase
    ny = sfft.next_fast_len(shape[0] + 2 * py, real=stationary)
    nx = shape[1] + 2 * px
    while True:
        nx = sfft.next_fast_len(nx, real=stationary)
        if nx % r == 0:
            break
        nx += 1
    return Grid((ny, nx), py, px, shape[0], shape[1], r, stationary)


class _Blur:
    """The own blur A on a padded grid, in the Fourier domain, with its adjoint and the
    solver of the normal equations (see the module's docstring)."""

    def __init__(self, ok: OutputKernel, grid: Grid):
        self.grid = grid
        ny, nx = grid.shape
        hy, hx = ok.own.shape[1] // 2, ok.own.shape[2] // 2
        kernels = ok.own.mean(axis=0, keepdims=True) if grid.real else ok.own
        kft = []
        for k in kernels:
            z = np.zeros((ny, nx), np.float32 if grid.real else np.float64)
            z[: 2 * hy + 1, : 2 * hx + 1] = k
            z = np.roll(z, (-hy, -hx), axis=(0, 1))
            kft.append(self.fft(z))
        if grid.real:
            self.b = kft[0][None]
        else:  # B_q = (1/R) sum_r w^(-q r) K_r^
            r_ = len(kft)
            w = np.exp(-2j * np.pi * np.outer(np.arange(r_), np.arange(r_)) / r_)
            self.b = np.einsum("qr,ryx->qyx", w, np.asarray(kft)) / r_

    @property
    def own(self) -> float:
        """The own light's share: the kernels' sum (mean over phases)."""
        return float(self.b[0, 0, 0].real)

    def fft(self, x: np.ndarray) -> np.ndarray:
        if self.grid.real:
            return sfft.rfft2(np.asarray(x, np.float32), workers=-1)
        return sfft.fft2(x, workers=-1)

    def ifft(self, x: np.ndarray) -> np.ndarray:
        if self.grid.real:
            return sfft.irfft2(x, s=self.grid.shape, workers=-1)
        return sfft.ifft2(x, workers=-1).real

    def fwd(self, f_ft: np.ndarray) -> np.ndarray:
        """G = A F."""
        b = self.b
        r_, nx = b.shape[0], f_ft.shape[-1]
        out = b[0] * f_ft
        for q in range(1, r_):
            out += np.roll(b[q] * f_ft, q * nx // r_, axis=-1)
        return out

    def adj(self, y_ft: np.ndarray) -> np.ndarray:
        """A^H Y."""
        b = self.b
        r_, nx = b.shape[0], y_ft.shape[-1]
        out = np.conj(b[0]) * y_ft
        for q in range(1, r_):
            out += np.conj(b[q]) * np.roll(y_ft, -q * nx // r_, axis=-1)
        return out

    def group_matrix(self) -> np.ndarray:
        """(ny, N/R, R, R): A[s, t] = B_{(s - t) mod R}[k_t] of each frequency group
        {k0 + t N/R}."""
        r_, ny, nx = self.b.shape
        m = nx // r_
        bg = self.b.reshape(r_, ny, r_, m)  # (q, ny, t, k0)
        a = np.empty((ny, m, r_, r_), np.complex128)
        for s in range(r_):
            for t in range(r_):
                a[:, :, s, t] = bg[(s - t) % r_, :, t, :]
        return a

    def normal(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The groups' A and A^H A + diag(d)."""
        r_ = self.b.shape[0]
        a = self.group_matrix()
        n = np.empty_like(a)
        for i in range(r_):  # explicit sums: einsum is slow on these small matrices
            for j in range(r_):
                n[..., i, j] = sum(np.conj(a[..., s, i]) * a[..., s, j] for s in range(r_))
        dg = _groups(np.broadcast_to(d, self.b.shape[1:]), r_)
        for i in range(r_):
            n[..., i, i] += dg[..., i]
        return a, n

    def solver(self, d: np.ndarray):
        """rhs -> F solving (A^H A + diag(d)) F = rhs, group by group of R coupled
        frequencies; the groups' inverses are formed once (closed form for R = 2)."""
        r_ = self.b.shape[0]
        if r_ == 1:
            inv = (1.0 / (np.abs(self.b[0]) ** 2 + d)).astype(self.b.real.dtype)
            return lambda rhs: rhs * inv
        _, n = self.normal(d)
        if r_ == 2:
            det = n[..., 0, 0] * n[..., 1, 1] - n[..., 0, 1] * n[..., 1, 0]
            i00, i01 = n[..., 1, 1] / det, -n[..., 0, 1] / det
            i10, i11 = -n[..., 1, 0] / det, n[..., 0, 0] / det

            def solve2(rhs: np.ndarray) -> np.ndarray:
                g = _groups(rhs, 2)
                x0 = i00 * g[..., 0] + i01 * g[..., 1]
                x1 = i10 * g[..., 0] + i11 * g[..., 1]
                return _ungroup(np.stack([x0, x1], axis=-1))

            return solve2
        inv = np.linalg.inv(n)
        return lambda rhs: _ungroup(np.einsum("ykab,ykb->yka", inv, _groups(rhs, r_)))


def _groups(x: np.ndarray, r_: int) -> np.ndarray:
    """(ny, nx) -> (ny, N/R, R): the frequencies of each group."""
    ny, nx = x.shape
    return np.moveaxis(x.reshape(ny, r_, nx // r_), 1, 2)


def _ungroup(x: np.ndarray) -> np.ndarray:
    ny, m, r_ = x.shape
    return np.moveaxis(x, 2, 1).reshape(ny, m * r_)


def _operator(shape: tuple[int, int], ok: OutputKernel) -> _Blur:
    stationary = ok.phases == 1 or ok.row_difference <= STATIONARY_TOLERANCE
    return _Blur(ok, _grid(shape, ok, stationary))


def wiener_noise_gain(
    ok: OutputKernel, shape: tuple[int, int], sigma: float, prior_variance: float = PRIOR_VARIANCE
) -> float:
    """The Wiener restoration's noise gain on white noise, closed form: the rms of the
    restored noise over the rms of the scan's, sqrt(sum |W|^2 / N) over the DFT grid,
    W = (A^H A + D)^-1 A^H of each frequency group."""
    op = _operator(shape, ok)
    d = sigma**2 / prior_spectrum(op.grid, prior_variance)
    if op.b.shape[0] == 1:
        b2 = np.abs(op.b[0]).astype(np.float64) ** 2
        return float(np.sqrt(op.grid.spectrum_mean(b2 / (b2 + d) ** 2)))
    a, n = op.normal(d)
    w = np.linalg.solve(n, np.conj(np.swapaxes(a, -1, -2)))
    return float(np.sqrt((np.abs(w) ** 2).sum() / np.prod(op.grid.shape)))


def _pad(img: np.ndarray, grid: Grid) -> np.ndarray:
    ny, nx = grid.shape
    return np.pad(
        img,
        ((grid.py, ny - grid.h - grid.py), (grid.px, nx - grid.w - grid.px)),
        mode="reflect" if min(img.shape) > 1 else "edge",
    )


def _crop(a: np.ndarray, grid: Grid) -> np.ndarray:
    return a[grid.py : grid.py + grid.h, grid.px : grid.px + grid.w]


def blur(page: np.ndarray, ok: OutputKernel) -> np.ndarray:
    """The forward model's own-path blur A f of a page on the output grid (reflect-padded
    at the edges; no ghost light, no noise): what :func:`restore` inverts. The rows'
    kernels are kept apart here, whatever their difference."""
    f = np.asarray(page, dtype=np.float64)
    op = _Blur(ok, _grid(f.shape, ok, ok.phases == 1))
    return _crop(op.ifft(op.fwd(op.fft(_pad(f, op.grid)))), op.grid).astype(np.float64)


def prior_spectrum(grid: Grid, variance: float = PRIOR_VARIANCE, corner: float = PRIOR_CORNER):
    """S(nu) = c / (|nu|^2 + nu0^2), per pixel, c such that its mean over the DFT grid
    (the variance of a page of this prior) is ``variance``."""
    vy, vx = grid.nu
    shape = 1.0 / (vy**2 + vx**2 + corner**2)
    return variance * shape / grid.spectrum_mean(shape)


@dataclass(frozen=True)
class Restored:
    """A restored image and what it took."""

    image: np.ndarray
    method: str
    z_mm: float
    sigma: float
    meta: dict


def restore(
    image: np.ndarray,
    ok: OutputKernel,
    *,
    method: str = "wiener",
    sigma: float,
    iterations: int | None = None,
    surround: float | None = None,
    prior_variance: float = PRIOR_VARIANCE,
    tv_scale: float = TV_SCALE,
) -> Restored:
    """Restore a shading-corrected scan (grey, [line, column], white = 1) made through the
    blur ``ok``; ``sigma``: the noise per pixel (:func:`noise_sigma`).

    The ghost light is removed as a background computed from the scan
    (:func:`~opticalstamp.imaging.outputkernel.ghost_background`, with ``surround`` the
    reflectance around the page, None: the scan's edges repeated); the own blur is
    deconvolved on a reflect-padded grid, with one kernel where the rows' differ by less
    than :data:`STATIONARY_TOLERANCE` (real FFTs, single precision) and each row's kernel
    solved exactly otherwise. The result is not clipped (overshoot shows).
    """
    g = np.asarray(image, dtype=np.float64)
    if g.ndim != 2:
        raise ValueError(f"image: must be 2-D grey (got shape {g.shape})")
    if not np.all(np.isfinite(g)):
        raise ValueError("image: has non-finite values")
    if method not in METHODS:
        raise ValueError(f"method: must be one of {', '.join(METHODS)} (got {method!r})")
    if not sigma > 0:
        raise ValueError(f"sigma: must be > 0 (got {sigma})")
    bkg = ghost_background(g, ok, surround)
    op = _operator(g.shape, ok)
    grid = op.grid
    n_it = iterations
    if method == "wiener":
        d = sigma**2 / prior_spectrum(grid, prior_variance)
        f = op.ifft(op.solver(d)(op.adj(op.fft(_pad(g - bkg, grid)))))
        n_it = 0
    elif method == "rl":
        n_it = RL_ITERATIONS if iterations is None else iterations
        f = _richardson_lucy(_pad(g, grid), _pad(bkg, grid), op, n_it)
    else:
        n_it = TV_ITERATIONS if iterations is None else iterations
        f = _tv_admm(_pad(g - bkg, grid), op, sigma, tv_scale, n_it)
    meta = {
        "method": method,
        "z_mm": ok.z_mm,
        "sigma": sigma,
        "iterations": n_it,
        "phases": ok.phases,
        "row_difference": ok.row_difference,
        "shift_invariant": grid.real,
        "ghost_fraction": ok.ghost_fraction,
        "prior_variance": prior_variance,
        "prior_corner": PRIOR_CORNER,
        "tv_scale": tv_scale,
        "surround": surround,
    }
    return Restored(_crop(f, grid).astype(np.float64), method, ok.z_mm, sigma, meta)


def _richardson_lucy(g: np.ndarray, bkg: np.ndarray, op: _Blur, n_it: int) -> np.ndarray:
    dtype = np.float32 if op.grid.real else np.float64
    g = np.maximum(g, 1e-6).astype(dtype)
    bkg = bkg.astype(dtype)
    norm = np.maximum(op.ifft(op.adj(op.fft(np.ones_like(g)))), 1e-12)
    f = np.full_like(g, max(float((g - bkg).mean()) / op.own, 1e-3))
    for _ in range(n_it):
        est = op.ifft(op.fwd(op.fft(f))) + bkg
        ratio = g / np.maximum(est, 1e-9)
        f = f * op.ifft(op.adj(op.fft(ratio))) / norm
    return f


def _tv_admm(g: np.ndarray, op: _Blur, sigma: float, tv_scale: float, n_it: int) -> np.ndarray:
    """min 1/(2 sigma^2) |A f - g|^2 + |grad f|_1 / beta (isotropic), by ADMM on
    z = grad f; each f-step the R x R Fourier solve."""
    lam = sigma**2 / tv_scale  # weight of |grad f|_1 against 1/2 |A f - g|^2
    rho = 4 * lam / max(tv_scale, 1e-6)
    vy, vx = op.grid.nu
    dtype = np.complex64 if op.grid.real else np.complex128
    dy = (np.exp(2j * np.pi * vy) - 1).astype(dtype)  # forward differences
    dx = (np.exp(2j * np.pi * vx) - 1).astype(dtype)
    d = rho * (np.abs(dy) ** 2 + np.abs(dx) ** 2)
    ahg = op.adj(op.fft(g))
    solve = op.solver(d + 1e-9)
    f_ft = solve(ahg)
    zy = op.ifft(dy * f_ft)
    zx = op.ifft(dx * f_ft)
    uy, ux = np.zeros_like(zy), np.zeros_like(zx)
    for _ in range(n_it):
        rhs = ahg + rho * (np.conj(dy) * op.fft(zy - uy) + np.conj(dx) * op.fft(zx - ux))
        f_ft = solve(rhs)
        gy = op.ifft(dy * f_ft)
        gx = op.ifft(dx * f_ft)
        vy_, vx_ = gy + uy, gx + ux
        mag = np.sqrt(vy_**2 + vx_**2)
        shrink = np.maximum(1 - (lam / rho) / np.maximum(mag, 1e-12), 0)
        zy, zx = vy_ * shrink, vx_ * shrink
        uy += gy - zy
        ux += gx - zx
    return op.ifft(f_ft)


def restore_scan(
    image: np.ndarray,
    design: Design,
    *,
    z_mm: float | None = None,
    height_map: np.ndarray | None = None,
    method: str = "wiener",
    settings: ScanSettings | None = None,
    seed: int = 0,
    model_error: float = MODEL_ERROR,
    iterations: int | None = None,
    ghosts: bool = True,
    kernels: KernelCache | None = None,
) -> Restored:
    """Restore a grey scan of ``design`` (shading corrected, white = 1) made at the float
    height ``z_mm`` or over ``height_map`` (mm, any resolution, covering the scan), with
    the kernels :func:`~opticalstamp.imaging.scan.simulate_scan` uses for ``settings`` and
    ``seed``; the noise from the settings' sensor and ``model_error``.

    A height map: the scan is restored with the kernels of every level (``settings``'
    Z step) and each pixel takes the restorations of the two levels around its height,
    weighted linearly, as the scan simulation blends its kernels (a spatially varying
    kernel, piecewise).

    ``kernels``: the scan kernels built beforehand
    (:func:`~opticalstamp.imaging.scan.prepare_kernels`, e.g. those the scan was simulated
    with) for these heights, settings and seed; None builds them here. The result is the
    same either way; kernels that do not fit raise ValueError.
    """
    st = settings or ScanSettings()
    g = np.asarray(image, dtype=np.float64)
    if g.ndim != 2 or min(g.shape) < 4:
        raise ValueError(
            f"image: must be a 2-D grey scan, 4 pixels a side at least (got {g.shape})"
        )
    if (z_mm is None) == (height_map is None):
        raise ValueError("z_mm: give a float height or a height map (one of them)")
    check_heights(z_mm, height_map)
    if height_map is not None:
        hm = np.asarray(height_map, dtype=np.float64)
    levels = scan_levels(z_mm, height_map, st.z_step_mm)
    kern = kernels_for(design, levels, st, seed=seed, ghosts=ghosts, kernels=kernels)
    out = np.zeros_like(g)
    metas = []
    if height_map is not None:
        p = scan_pitch(design)
        h_mm, w_mm = g.shape[0] * p / 1000, g.shape[1] * p / 1000
        centres_y = (np.arange(g.shape[0]) + 0.5) * p
        centres_x = (np.arange(g.shape[1]) + 0.5) * p
        z_loc = sample_height(hm, h_mm, w_mm, centres_y, centres_x)
    for il, zl in enumerate(levels):
        ok = output_kernel(
            design, zl, settings=st, seed=seed, ghosts=ghosts, kernels=[[row[il]] for row in kern]
        )
        sigma = noise_sigma(st.sensor, ok.white, model_error)
        if height_map is None:
            wts = None
        else:
            wts = np.clip(1 - np.abs(z_loc - zl) / st.z_step_mm, 0, 1)
            if not wts.any():
                continue
        r = restore(
            g,
            ok,
            method=method,
            sigma=sigma,
            iterations=iterations,
            surround=st.surround,
        )
        out += r.image if wts is None else r.image * wts
        metas.append(r.meta)
    meta = dict(metas[0]) | {
        "z_mm": z_mm,
        "height_map": height_map is not None,
        "levels_mm": levels,
        "model_error": model_error,
        "seed": seed,
        "design": design.name,
        "design_fingerprint": design.fingerprint(),
        "settings": st.model_dump(mode="json"),
    }
    return Restored(
        out, method, float("nan") if z_mm is None else float(z_mm), metas[0]["sigma"], meta
    )


#: heights tried by :func:`estimate_height` (mm)
HEIGHT_GRID_MM = tuple(round(0.25 * i, 2) for i in range(0, 25))
#: the score half a millimetre either side of the best must be this much worse (relative)
#: for an estimate; less: the image cannot tell the heights apart
MIN_SCORE_CONTRAST = 0.02
#: the best score's rms distance to black-or-white above which the page is not a
#: black-and-white document and the criterion does not apply
MAX_BINARY_RMS = 0.2
#: the estimate works on the most detailed square of this many pixels a side at most
HEIGHT_CROP_PX = 384


@dataclass(frozen=True)
class HeightEstimate:
    """The float height of a scan from its restorations, or a refusal with the reason."""

    z_mm: float | None
    refused: str | None
    z_grid_mm: list[float]
    score: list[float]  # mean squared distance of the restored page to black or white
    contrast: float  # the score 0.5 mm either side of the best, relative, less 1


def _detailed_crop(g: np.ndarray, n: int) -> np.ndarray:
    """The n x n square (or the whole image) with the most variance."""
    if g.shape[0] <= n and g.shape[1] <= n:
        return g
    from scipy import ndimage

    h, w = min(n, g.shape[0]), min(n, g.shape[1])
    var = ndimage.uniform_filter(g**2, (h, w)) - ndimage.uniform_filter(g, (h, w)) ** 2
    lim = var[h // 2 : g.shape[0] - (h - h // 2) + 1, w // 2 : g.shape[1] - (w - w // 2) + 1]
    y, x = np.unravel_index(int(np.argmax(lim)), lim.shape)
    return g[y : y + h, x : x + w]


def estimate_height(
    image: np.ndarray,
    design: Design,
    *,
    z_grid_mm=HEIGHT_GRID_MM,
    settings: ScanSettings | None = None,
    seed: int = 0,
    model_error: float = MODEL_ERROR,
) -> HeightEstimate:
    """The float height of a scan of a black-and-white document (text, line art), found
    as the height whose Wiener restoration is closest to a black-and-white page: the mean
    squared distance of each restored pixel to 0 or 1 is least at the right height (too
    low: still blurred, grey; too high: over-sharpened, ringing and noise). The best
    height of the grid is refined by a parabola through its neighbours.

    Refused (``refused`` says why), rather than guessed, where the best lies at an end of
    the grid, where the score half a millimetre either side is less than
    :data:`MIN_SCORE_CONTRAST` worse (too little detail: a blank or smooth page), or where
    even the best restoration is far from black and white (a photograph: the criterion
    does not apply). Accuracy on the prototype's simulated scans: docs/restore.md.
    """
    st = settings or ScanSettings()
    g = np.asarray(image, dtype=np.float64)
    if g.ndim != 2 or min(g.shape) < 16:
        raise ValueError(
            f"image: must be a 2-D grey scan, 16 pixels a side at least (got {g.shape})"
        )
    if not np.all(np.isfinite(g)):
        raise ValueError("image: has non-finite values")
    zs = [float(z) for z in z_grid_mm]
    if len(zs) < 5 or np.any(np.diff(zs) <= 0):
        raise ValueError("z_grid_mm: needs 5 increasing heights at least")
    part = _detailed_crop(g, HEIGHT_CROP_PX)
    cache = prepare_kernels(design, z_mm=zs, settings=st, seed=seed)
    score = []
    for z in zs:
        ok = output_kernel(design, z, settings=st, seed=seed, kernels=cache)
        sigma = noise_sigma(st.sensor, ok.white, model_error)
        f = restore(part, ok, method="wiener", sigma=sigma, surround=st.surround).image
        m = f[8:-8, 8:-8] if min(f.shape) > 32 else f
        score.append(float(np.mean(np.minimum(np.abs(m), np.abs(m - 1)) ** 2)))
    sc = np.asarray(score)
    i = int(np.argmin(sc))
    step = zs[1] - zs[0]
    k = max(1, int(round(0.5 / step)))
    sides = [sc[j] for j in (i - k, i + k) if 0 <= j < sc.size]
    contrast = float(min(sides) / sc[i] - 1) if sc[i] > 0 else 0.0
    refused = None
    if i in (0, sc.size - 1):
        refused = f"the best height is an end of the range tried ({zs[i]:g} mm)"
    elif np.sqrt(sc[i]) > MAX_BINARY_RMS:
        refused = (
            f"not a black-and-white page (the best restoration is {np.sqrt(sc[i]):.2f} rms "
            "from black or white): the criterion does not apply"
        )
    elif contrast < MIN_SCORE_CONTRAST:
        refused = (
            f"weak evidence: the heights 0.5 mm either side score only {contrast:.1%} worse "
            "(too little fine detail to tell them apart)"
        )
    z_hat = None
    if refused is None:
        a, b, c = sc[i - 1], sc[i], sc[i + 1]
        den = a - 2 * b + c
        z_hat = float(zs[i] + (0.5 * (a - c) / den * (zs[i + 1] - zs[i]) if den > 0 else 0.0))
    return HeightEstimate(z_hat, refused, zs, score, contrast)
