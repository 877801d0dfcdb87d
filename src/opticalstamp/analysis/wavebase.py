"""The wave engine's building blocks: sampling, the stack along one axis, 1-D operators.

Shared by the separable path (:mod:`.wave`, whose docstring states the model and the
normalisation) and the 2-D path (:mod:`.wave2d`). Lengths in um; s = n sin(theta) is the
invariant transverse direction, f = s / lambda the spatial frequency (1/um).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import fft as sfft
from scipy import special

from ..design import Design
from ..raytrace.stack import lattice_of
from ..validate import InputError
from .arrays import fft_workers

#: Diffraction orders lambda / w of the smallest hole added to the own path's slopes to
#: make the default band (see :func:`wave_sampling`).
ORDERS = 12.0
#: The band never exceeds this fraction of the smallest index (paraxial validity; grazing
#: light is the tracer's).
BAND_CAP = 0.35
#: Grid steps per Nyquist step of the band (dx = lambda / (2 OVERSAMPLE B)); 3 or more:
#: a field of band B times a mask low-passed to 2B has band 3B (see :func:`mask_field`).
OVERSAMPLE = 3.0
#: Domain margin beyond the band's reach, in units of lambda / B (the tails of
#: band-limited fields).
MARGIN = 32.0
#: Gauss-Legendre nodes across the sensitive width w per unit of 2 B w / lambda (the
#: oscillations of the band-limited source integrand), and extra nodes.
SOURCE_DENSITY = 1.0
SOURCE_EXTRA = 8
#: Relative power left out when the modes are compressed, and below which a sequence of
#: rows is pruned.
MODE_TOL = 1e-10
PRUNE_TOL = 1e-10


#: Why ``auto`` keeps ray optics for circular (any non-rectangular) holes on a CPU: the
#: analyses that need a pixel's 2-D maps take them from the 2-D path (
#: :mod:`.wave2dmaps`), which the user asks for with ``--optics wave``.
CIRCLE_MAPS = (
    "circular holes (any that are not rectangles): the wave engine's 2-D maps (spots, scan "
    "kernels, the report's ray-vs-wave section) take the 2-D path, about 4 min for the "
    "stack and 1-2 min a height per wavelength on 2 CPU cores (the circular prototype), "
    "so auto keeps ray optics on a CPU; --optics wave computes them (seconds on a CUDA "
    "GPU with CuPy, where auto follows the validity rule)"
)


def pixel_record(design: Design, pixel: tuple[int, int]) -> dict:
    """A wave response's record of its used pixel: row (A/B), k and its centre (um)."""
    px, py = (float(v) for v in lattice_of(design).centers(*pixel))
    return {"row": "AB"[pixel[0]], "k": pixel[1], "x_um": px, "y_um": py}


@dataclass(frozen=True)
class WaveSampling:
    """How the wave engine samples one design (all lengths um).

    Attributes
    ----------
    wavelength_um : vacuum wavelength
    band : B, the largest |s_x| and |s_y| (s = n sin theta) the engine propagates
    step_um : grid step in x and y
    margin_um : room left beyond the reach of the band on every side of each domain
    source_points : Gauss-Legendre nodes across the sensitive width and height
    mode_tol, prune_tol : relative power dropped by mode compression and by pruning
    min_points : the stack's and the object side's grids hold at least these many points
        (0: what the design needs). A grid that changes size changes the periodic domain
        and the band's frequency bins: the figures jump by about 1e-6 of the light where
        a design's length crosses such a step. A fit holds its grids at its nominal
        design's sizes (:meth:`held`), so that its model is smooth in the parameters.
    """

    wavelength_um: float
    band: float
    step_um: float
    margin_um: float
    source_points: tuple[int, int]
    mode_tol: float = MODE_TOL
    prune_tol: float = PRUNE_TOL
    min_points: tuple[int, int] = (0, 0)

    def held(self, stack_points: int, object_points: int) -> WaveSampling:
        """This sampling with every stack grid at least ``stack_points`` and every object
        grid at least ``object_points`` points (FFT-friendly lengths)."""
        return replace(
            self,
            min_points=(
                sfft.next_fast_len(int(stack_points)),
                sfft.next_fast_len(int(object_points)),
            ),
        )

    def refined(self, step: float = 1.0, margin: float = 1.0, points: float = 1.0):
        """This sampling with the step divided by ``step``, the margin and the source
        points multiplied (a convergence check)."""
        nx, ny = self.source_points
        return replace(
            self,
            step_um=self.step_um / step,
            margin_um=self.margin_um * margin,
            source_points=(math.ceil(nx * points), math.ceil(ny * points)),
        )


@dataclass(frozen=True)
class Plane:
    """The stack along one axis in the paraxial model.

    Attributes
    ----------
    source : (lo, hi) of the sensitive area along the axis, from the pixel's axis (um)
    heights : (m,) reduced height (sum of t / n, um) of each mask above the sensor
    holes : per mask, per row, (k, 2) array of hole intervals [lo, hi] along the axis
        (um, from the pixel's axis), every hole of the lattice near the pixel
    top : reduced height of the reference plane (Z = 0)
    n_obj : index of the object medium
    """

    source: tuple[float, float]
    heights: np.ndarray
    holes: list[list[np.ndarray]]
    top: float
    n_obj: float

    def reduced(self, z_mm: float) -> float:
        """Reduced height of the object plane z_mm above the reference plane (um)."""
        return self.top + z_mm * 1000.0 / self.n_obj


def rectangular(design: Design) -> bool:
    """Whether every mask of ``design`` has rectangular (or square) holes."""
    return all(m.shape != "circle" for m in design.masks)


def stack_axes(
    design: Design,
    pixel: tuple[int, int] = (0, 0),
    reach_um: float = 2000.0,
    *,
    bounds: bool = False,
):
    """The stack's two axes (x, y) as :class:`Plane`, holes within ``reach_um`` of the
    pixel's axis (whole rows of the lattice in y).

    Parameters
    ----------
    design : Design with rectangular holes (any holes with ``bounds``)
    pixel : (row, k) of the used pixel
    reach_um : holes whose centre lies farther along x are left out
    bounds : take each hole's bounding box (a circle's square): for the rules that a
        box bounds (the own path's slopes, mirror symmetry), not for propagation
    """
    if not (bounds or rectangular(design)):
        raise ValueError("the separable wave path needs rectangular holes (use wave2d)")
    lat = lattice_of(design)
    row, k = pixel
    if not (0 <= row < lat.n_rows and lat.k_lo <= k <= lat.k_hi):
        raise InputError(f"pixel: no used pixel ({row}, {k})")
    px, py = (float(v) for v in lat.centers(row, k))
    s = design.sensor
    heights, red, hx, hy = [], 0.0, [], []
    for sl in design.slabs:
        red += sl.thickness_um / design.index(sl.medium)
        m = sl.mask_top
        if m is None:
            continue
        heights.append(red)
        rows_x, rows_y = [], []
        for r in range(lat.n_rows):
            cx = lat.row_x[r] + m.offset_x_um - px
            ks = np.arange(lat.k_lo, lat.k_hi + 1)
            ks = ks[np.abs(cx + ks * lat.pitch) <= reach_um + lat.pitch]
            c = cx + ks * lat.pitch
            w, h = m.hole_width_um / 2, m.hole_height_um / 2
            rows_x.append(np.stack([c - w, c + w], axis=1))
            cy = lat.row_y[r] + m.offset_y_um - py
            rows_y.append(np.array([[cy - h, cy + h]]))
        hx.append(rows_x)
        hy.append(rows_y)
    gap = design.reference_gap
    top = red + gap.thickness_um / design.index(gap.medium)
    n_obj = design.index(design.object_medium)
    hw, hh = s.sensitive_width_um / 2, s.sensitive_height_um / 2
    heights = np.array(heights)
    return (
        Plane((-hw, hw), heights, hx, top, n_obj),
        Plane((-hh, hh), heights, hy, top, n_obj),
    )


def min_index(design: Design) -> float:
    """Smallest index on the way up: slabs, reference gap, object medium."""
    media = [sl.medium for sl in design.slabs]
    media += [design.reference_gap.medium, design.object_medium]
    return min(design.index(m) for m in media)


def own_slope(design: Design) -> float:
    """The largest |s_x| or |s_y| of the paraxial own path (rays through the sensitive
    area and every own hole): min over pairs of planes of (h_i + h_j + |o_i - o_j|) /
    d_ij, over both axes (the larger). A circular hole counts as its bounding square (an
    upper bound)."""
    out = 0.0
    for ax in stack_axes(design, reach_um=0.0, bounds=True):
        d = np.concatenate([[0.0], ax.heights])
        lo = [ax.source[0]] + [rows[0][np.argmin(np.abs(rows[0].mean(1)))][0] for rows in ax.holes]
        hi = [ax.source[1]] + [rows[0][np.argmin(np.abs(rows[0].mean(1)))][1] for rows in ax.holes]
        lo, hi = np.array(lo), np.array(hi)
        i, j = np.triu_indices(d.size, 1)
        s = (np.maximum(hi[i] - lo[j], hi[j] - lo[i])) / (d[j] - d[i])
        out = max(out, float(s.min()))
    return out


def fresnel_numbers(design: Design, wavelength_um: float | None = None) -> list[dict]:
    """Fresnel number a^2 / (lambda d) of each mask's holes over the gap below it (to
    the next mask or the sensor) and of the object-side mask over the reference gap.

    a is half the hole's smaller side (radius of a circle), d the reduced distance
    (sum t / n, um). Returns one dict per gap: ``layer``, ``towards``, ``hole_um``,
    ``distance_um`` (reduced), ``fresnel_number``.
    """
    lam = design.wavelength_um if wavelength_um is None else float(wavelength_um)
    out, red, below, below_name = [], 0.0, 0.0, "sensor"
    for i, sl in enumerate(design.slabs):
        red += sl.thickness_um / design.index(sl.medium)
        m = sl.mask_top
        if m is None:
            continue
        size = min(m.hole_width_um, m.hole_height_um)
        name = m.name or f"mask {i}"
        d = red - below
        out.append(
            {
                "layer": name,
                "towards": below_name,
                "hole_um": size,
                "distance_um": d,
                "fresnel_number": (size / 2) ** 2 / (lam * d),
            }
        )
        below, below_name, last = red, name, (name, size)
    gap = design.reference_gap
    d = gap.thickness_um / design.index(gap.medium)
    if d > 0:
        name, size = last
        out.append(
            {
                "layer": name,
                "towards": "reference plane",
                "hole_um": size,
                "distance_um": d,
                "fresnel_number": (size / 2) ** 2 / (lam * d),
            }
        )
    return out


def wave_sampling(
    design: Design,
    *,
    wavelength_um: float | None = None,
    band: float | None = None,
    orders: float = ORDERS,
    oversample: float = OVERSAMPLE,
) -> WaveSampling:
    """The sampling of the wave engine, chosen from the design.

    Band: B = s_own + ``orders`` lambda / w_min (s_own the largest slope of the paraxial
    own path, :func:`own_slope`; w_min the smallest hole side), at most ``BAND_CAP`` times
    the smallest index. It holds the own path with its diffraction out to ``orders``
    orders of the smallest hole, and the near crosstalk through neighbouring holes that
    lies in it; light outside it is counted as lost to the band (``WaveResponse.budget``).
    Step: lambda / (2 ``oversample`` B), so the intensity is sampled above its Nyquist
    rate. Margin: MARGIN lambda / B (the tails of band-limited fields).
    Source points: Gauss-Legendre nodes, SOURCE_DENSITY per oscillation 2 B w / lambda
    of the integrand across the sensitive width w, plus SOURCE_EXTRA.
    """
    lam = design.wavelength_um if wavelength_um is None else float(wavelength_um)
    if not lam > 0:
        raise InputError(f"wavelength_um: must be > 0 (got {lam})")
    if band is None:
        w_min = min(min(m.hole_width_um, m.hole_height_um) for m in design.masks)
        band = own_slope(design) + orders * lam / w_min
        band = min(band, BAND_CAP * min_index(design))
    if not 0 < band < min_index(design):
        raise InputError(f"band: must be in (0, {min_index(design):g}) (got {band})")
    s = design.sensor
    pts = tuple(
        int(math.ceil(SOURCE_DENSITY * 2 * band * w / lam)) + SOURCE_EXTRA
        for w in (s.sensitive_width_um, s.sensitive_height_um)
    )
    return WaveSampling(lam, float(band), lam / (2 * oversample * band), MARGIN * lam / band, pts)


# -- 1-D building blocks -------------------------------------------------------------------
def mask_field(x_um: np.ndarray, holes: np.ndarray, band: float, wavelength_um: float):
    """A mask's transmission low-passed exactly to |lambda nu| <= 2 band, on the grid
    ``x_um`` (uniform, periodic): shape of ``x_um``.

    The Fourier coefficients of the periodic mask (holes ``holes`` (k, 2), disjoint
    intervals, cut to the grid's period) are w sinc(w nu) exp(-2 pi i nu c) summed over
    the holes. A field u of band B times the mask has, inside the band, exactly the
    spectrum of u times this low-passed mask (mask frequencies beyond 2B cannot reach
    the band), and the product has band 3B, which a grid step <= lambda / (6B) holds
    without aliasing: the in-band result does not depend on where the edges fall on the
    grid. sum |u|^2 M dx is then the exact power through the mask (its integrand has
    band 4B < 1 / dx).
    """
    n = x_um.size
    dx = x_um[1] - x_um[0]
    nu = sfft.fftfreq(n, dx)
    keep = np.abs(wavelength_um * nu) <= 2 * band
    a = np.zeros(n, dtype=np.complex128)
    lo = x_um[0] - dx / 2  # one period [lo, lo + n dx): a hole beyond it is cut there
    h = np.clip(np.asarray(holes, dtype=np.float64).reshape(-1, 2), lo, lo + n * dx)
    h = h[h[:, 1] > h[:, 0]]
    if h.size:
        w = h[:, 1] - h[:, 0]
        c = 0.5 * (h[:, 1] + h[:, 0]) - x_um[0]
        nk = nu[keep][:, None]
        a[keep] = (w * np.sinc(w * nk) * np.exp(-2j * np.pi * nk * c)).sum(axis=1)
    return sfft.ifft(a, workers=fft_workers()).real / dx


def in_band(f: np.ndarray, wavelength_um: float, band: float) -> np.ndarray:
    """Whether the frequencies ``f`` (1/um) lie in the band, |lambda f| < band (a bin
    on the edge to within 1e-9 is out, whatever the rounding: the edge falls on a bin
    whenever the grid has a multiple of 6 points)."""
    return np.abs(wavelength_um * f) < band * (1 - 1e-9)


def kernel(n: int, step_um: float, wavelength_um: float, d_um: float, band: float):
    """Paraxial transfer function over the reduced distance ``d_um`` with the band
    |lambda f| < band (0 outside), on the FFT frequencies of an ``n``-point grid: (n,)."""
    f = sfft.fftfreq(n, step_um)
    h = np.exp(-1j * np.pi * wavelength_um * d_um * f * f)
    return np.where(in_band(f, wavelength_um, band), h, 0.0)


def propagate(u: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Field(s) ``u`` (n, ...) through the transfer function ``h`` (n,) (axis 0)."""
    hh = h.reshape((-1,) + (1,) * (u.ndim - 1))
    return sfft.ifft(sfft.fft(u, axis=0, workers=fft_workers()) * hh, axis=0, workers=fft_workers())


def point_sources(
    x_um: np.ndarray,
    x0_um: np.ndarray,
    weights: np.ndarray,
    wavelength_um: float,
    d_um: float,
    band: float,
) -> np.ndarray:
    """Band-limited points at ``x0_um`` with a flat spectrum over |lambda f| < band
    (amplitude sqrt(weights)), propagated over the reduced distance ``d_um`` > 0 with the
    paraxial propagator, on the grid ``x_um``: (n, n_points), exactly (Fresnel integrals).

    u(x) = sqrt(w) integral_{-F}^{F} exp(2 pi i f (x - x0) - i pi lambda d f^2) df,
    F = band / lambda; integral |u|^2 dx = w 2 band / lambda. Closed form rather than a
    DFT: a flat spectrum cut at the band edge puts full-strength light at the cone's edge
    x0 +- d band, whose ripples a DFT would place to within lambda d / (grid length).
    """
    lam = wavelength_um
    xi = np.asarray(x_um, dtype=np.float64)[:, None] - np.asarray(x0_um)[None, :]
    fc = xi / (lam * d_um)
    k = np.sqrt(2 * lam * d_um)
    lim = band / lam
    s2, c2 = special.fresnel(k * (lim - fc))
    s1, c1 = special.fresnel(k * (-lim - fc))
    u = ((c2 - c1) - 1j * (s2 - s1)) / k * np.exp(1j * np.pi * xi * xi / (lam * d_um))
    return u * np.sqrt(weights)[None, :]


def gauss_legendre(lo: float, hi: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of the n-point Gauss-Legendre rule on [lo, hi]."""
    t, w = np.polynomial.legendre.leggauss(n)
    return lo + (t + 1) * (hi - lo) / 2, w * (hi - lo) / 2


def grid(lo: float, hi: float, step: float, min_points: int = 0) -> np.ndarray:
    """A uniform grid of FFT-friendly length (at least ``min_points``) covering [lo, hi],
    centred on it."""
    n = max(sfft.next_fast_len(int(math.ceil((hi - lo) / step)) + 1), int(min_points))
    mid = 0.5 * (lo + hi)
    return mid + (np.arange(n) - n // 2) * step


def stack_grid(source: tuple[float, float], top_um: float, smp: WaveSampling) -> np.ndarray:
    """The grid of one axis inside the stack: the sensitive interval ``source`` widened by
    the band's reach ``top_um`` * B up to the object-side mask (reduced height
    ``top_um``) and the margin; in-band light from the pixel never leaves it, so the
    FFT's periodic copies never overlap (the band-limited ASM condition holds)."""
    reach = top_um * smp.band + smp.margin_um
    return grid(source[0] - reach, source[1] + reach, smp.step_um, smp.min_points[0])


def object_grid(x: np.ndarray, d_um: float, smp: WaveSampling) -> tuple[np.ndarray, int]:
    """The stack grid ``x`` widened by the reach d_um * B (d_um the reduced distance from
    the object-side mask to the farthest object plane) and the margin, on the same
    points: (grid, index of x[0] in it)."""
    reach = d_um * smp.band + smp.margin_um
    xf = grid(x[0] - reach, x[-1] + reach, smp.step_um, smp.min_points[1])
    off = int(round((x[0] - xf[0]) / smp.step_um))
    return x[0] + (np.arange(xf.size) - off) * smp.step_um, off


def grid_points(
    design: Design, z_max_mm: float, smp: WaveSampling, pixel: tuple[int, int] = (0, 0)
) -> tuple[int, int]:
    """The points of the largest stack grid and of the largest object grid (up to the
    object plane ``z_max_mm``) that a run of ``design``'s ``pixel`` at ``smp`` makes
    (:func:`stack_grid`, :func:`object_grid`; each hole's box: any hole shape)."""
    planes = stack_axes(design, pixel, bounds=True)
    st = [stack_grid(pl.source, pl.heights[-1], smp) for pl in planes]
    ob = [
        object_grid(x, pl.reduced(float(z_max_mm)) - pl.heights[-1], smp)[0]
        for x, pl in zip(st, planes, strict=True)
    ]
    return max(x.size for x in st), max(x.size for x in ob)


def fwhm_of(x: np.ndarray, profile: np.ndarray) -> float:
    """Full width at half maximum of ``profile`` on ``x`` (:func:`~opticalstamp.analysis.
    spots.fwhm`, the spots' own rule: outermost crossings, linear interpolation)."""
    from .spots import fwhm

    return fwhm(profile, x)


def band_integral(x: np.ndarray, g: np.ndarray, a: float, b: float) -> np.ndarray:
    """Exact integral over [a, b] of band-limited periodic samples ``g`` (..., n) on the
    uniform grid ``x`` (the intensity's band 2B is below the grid's Nyquist rate 3B)."""
    n = x.size
    nu = sfft.fftfreq(n, x[1] - x[0])
    c = sfft.fft(g, axis=-1, workers=fft_workers()) / n
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.exp(2j * np.pi * nu * (b - x[0])) - np.exp(2j * np.pi * nu * (a - x[0]))
        k = np.where(nu == 0, b - a, k / (2j * np.pi * nu))
    return c @ k


def response_summary(r) -> dict:
    """The plain-data summary that both wave responses (separable and 2-D) share: design,
    pixel, Z, light, central-cell share and the FWHM of each line-spread function."""
    return {
        "design": r.design,
        "fingerprint": r.fingerprint,
        "pixel": r.pixel,
        "z_mm": r.z_mm.tolist(),
        "etendue_um2sr": r.etendue_um2sr.tolist(),
        "center_cell_fraction": r.center_cell_fraction.tolist(),
        "fwhm_x_um": [fwhm_of(r.x_um, p) for p in r.lsf_x],
        "fwhm_y_um": [fwhm_of(r.y_um, p) for p in r.lsf_y],
    }
