"""Light as it is: the illumination's spectrum times the sensor's quantum efficiency,
sampled at a few wavelengths (issue 23).

A pixel's signal from a document lit with the spectral power S(lambda) is, in
photo-electrons, proportional to

    integral S(lambda) (lambda / h c) QE(lambda) R(lambda) dlambda

where R(lambda) is the pixel's responsivity at that wavelength (um^2 sr; the wave
engine's, with each medium's index at lambda from the catalogue's dispersion) and
lambda / h c turns power into photons. The responsivity under the light is therefore the
average of R(lambda) under the density p(lambda) = S lambda QE / integral(S lambda QE),
and a quadrature with nodes lambda_i and weights w_i (sum 1) turns it into
sum_i w_i R(lambda_i). The nodes and weights are the Gauss rule of p itself (Golub and
Welsch, Math. Comp. 23, 221 (1969), with the recurrence from the discretized Stieltjes
procedure on a 0.5-nm grid; Gautschi, "Orthogonal Polynomials: Computation and
Approximation", 2004): n nodes integrate every polynomial of degree 2n - 1 in lambda
exactly against p, all inside the spectrum, weights positive.

The shapes are **typical, not any part's**: sums of Gaussians with the peaks and widths
that LED datasheets show, and a front-illuminated silicon photodiode's QE; replace them
with your parts' curves (:func:`spectrum_from_density`).

* ``white``: a blue InGaN pump at 450 nm (FWHM 20 nm) and a broad YAG:Ce phosphor
  emission at 560 nm (FWHM 120 nm) at 0.55 of the pump's peak: the two humps of a cool
  white phosphor LED's datasheet spectrum (Y. Ohno, "Spectral design considerations for
  white LED color rendering", Opt. Eng. 44(11), 111302 (2005), models LED spectra by
  such Gaussian-like bands).
* ``red``: AlInGaP, 630 nm, FWHM 18 nm; ``green``: InGaN, 525 nm, FWHM 32 nm;
  ``blue``: InGaN, 465 nm, FWHM 24 nm: the usual peaks and widths of the R, G, B LEDs of
  contact image sensors' light guides.
* Silicon QE: 0.35 at 400 nm rising to 0.70 at 650-700 nm and falling to 0.16 at
  1000 nm: the shape of a front-illuminated silicon photodiode without colour filters
  (as in Hamamatsu's photodiode handbook curves, converted from A/W), interpolated
  monotonically between the tabulated points.

``mono`` is one wavelength (the design's ``wavelength_um``) with weight 1: no QE, no
spectrum, the wave engine's figures at that wavelength exactly.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from ..design import Design
from ..design.electronics import ILLUMINATIONS, LUMA
from ..design.materials import WAVELENGTH_RANGE_UM
from ..validate import InputError

__all__ = [
    "LEDS",
    "Spectrum",
    "channels",
    "grey_light",
    "led_power",
    "mono",
    "silicon_qe",
    "spectrum_from_density",
    "spectrum_of",
]

#: Typical LED spectra: per name the Gaussian bands (peak um, FWHM um, relative height)
#: of the relative spectral power (see the module's docstring for the sources).
LEDS: Mapping[str, tuple[tuple[float, float, float], ...]] = MappingProxyType(
    {
        "white": ((0.450, 0.020, 1.0), (0.560, 0.120, 0.55)),
        "red": ((0.630, 0.018, 1.0),),
        "green": ((0.525, 0.032, 1.0),),
        "blue": ((0.465, 0.024, 1.0),),
    }
)
#: Wavelengths sampled by default for each light.
DEFAULT_POINTS: Mapping[str, int] = MappingProxyType({"white": 7, "red": 3, "green": 3, "blue": 3})
#: The channels of each illumination (LEDs lit in turn give one responsivity each).
CHANNELS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {name: (name,) for name in ILLUMINATIONS if name != "rgb"} | {"rgb": ("red", "green", "blue")}
)
#: A typical front-illuminated silicon photodiode's quantum efficiency (um, electrons
#: per photon), see the module's docstring.
SILICON_QE_TABLE = (
    (0.35, 0.15),
    (0.40, 0.35),
    (0.45, 0.48),
    (0.50, 0.57),
    (0.55, 0.63),
    (0.60, 0.67),
    (0.65, 0.70),
    (0.70, 0.70),
    (0.75, 0.68),
    (0.80, 0.63),
    (0.85, 0.55),
    (0.90, 0.44),
    (0.95, 0.30),
    (1.00, 0.16),
    (1.05, 0.06),
    (1.10, 0.01),
)
#: Step of the grid on which the densities are discretized (um).
GRID_STEP_UM = 0.0005


@dataclass(frozen=True)
class Spectrum:
    """Wavelengths and weights that stand for one channel's light.

    Attributes
    ----------
    name : what the light is ("mono", "white", "red", ...)
    wavelengths_um : (n,) vacuum wavelengths, each in the catalogue's range
    weights : (n,) positive, summing to 1: sum_i w_i R(lambda_i) is the responsivity
        under the light
    """

    name: str
    wavelengths_um: tuple[float, ...]
    weights: tuple[float, ...]

    def __post_init__(self) -> None:
        lam = np.asarray(self.wavelengths_um, dtype=np.float64)
        w = np.asarray(self.weights, dtype=np.float64)
        lo, hi = WAVELENGTH_RANGE_UM
        if lam.ndim != 1 or lam.size == 0 or lam.shape != w.shape:
            raise InputError("spectrum: wavelengths_um and weights must be two lists of one length")
        if not (np.all(np.isfinite(lam)) and lam.min() >= lo and lam.max() <= hi):
            raise InputError(f"spectrum: wavelengths_um must lie in [{lo:g}, {hi:g}] um")
        if not (np.all(np.isfinite(w)) and w.min() > 0 and abs(w.sum() - 1) < 1e-9):
            raise InputError("spectrum: weights must be > 0 and sum to 1")

    @property
    def mean_um(self) -> float:
        """The weighted mean wavelength (um)."""
        return float(np.dot(self.wavelengths_um, self.weights))

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "wavelengths_um": list(self.wavelengths_um),
            "weights": list(self.weights),
        }


def mono(wavelength_um: float) -> Spectrum:
    """One wavelength, weight 1."""
    return Spectrum("mono", (float(wavelength_um),), (1.0,))


def led_power(name: str, wavelength_um) -> np.ndarray:
    """Relative spectral power of the typical LED ``name`` (:data:`LEDS`) at
    ``wavelength_um`` (peak of the strongest band 1)."""
    if name not in LEDS:
        raise InputError(f"spectrum: unknown LED {name!r}; known: {', '.join(LEDS)}")
    lam = np.asarray(wavelength_um, dtype=np.float64)
    out = np.zeros_like(lam)
    for peak, fwhm, height in LEDS[name]:
        sigma = fwhm / (2 * math.sqrt(2 * math.log(2)))
        out = out + height * np.exp(-0.5 * ((lam - peak) / sigma) ** 2)
    return out


def silicon_qe(wavelength_um) -> np.ndarray:
    """A typical silicon photodiode's quantum efficiency (:data:`SILICON_QE_TABLE`,
    monotone cubic interpolation; 0 outside the table)."""
    t = np.asarray(SILICON_QE_TABLE)
    lam = np.asarray(wavelength_um, dtype=np.float64)
    from scipy.interpolate import PchipInterpolator  # here: ~0.6 s to import

    q = PchipInterpolator(t[:, 0], t[:, 1], extrapolate=False)(lam)
    return np.nan_to_num(q, nan=0.0)


def _grid() -> np.ndarray:
    lo, hi = WAVELENGTH_RANGE_UM
    n = int(round((hi - lo) / GRID_STEP_UM))
    return lo + np.arange(n + 1) * ((hi - lo) / n)


def spectrum_from_density(name: str, wavelength_um, density, n: int) -> Spectrum:
    """The n-point Gauss rule of a density given on a fine uniform grid.

    Parameters
    ----------
    name : the light's name
    wavelength_um : (k,) uniform grid (um)
    density : (k,) >= 0, the photo-electron density (power x lambda x QE), any scale
    n : number of wavelengths, 1 <= n

    The density is discretized with the trapezoid rule; the recurrence of its
    orthonormal polynomials comes from the Stieltjes procedure (on the variable scaled
    to [-1, 1]); the nodes are the eigenvalues of the Jacobi matrix and the weights the
    squared first components of its eigenvectors (Golub-Welsch).
    """
    lam = np.asarray(wavelength_um, dtype=np.float64)
    p = np.asarray(density, dtype=np.float64)
    if not (isinstance(n, int) and n >= 1):
        raise InputError(f"spectrum: the number of wavelengths must be an integer >= 1 (got {n!r})")
    w = p * np.gradient(lam)
    w[0] *= 0.5 if lam.size > 1 else 1.0
    w[-1] *= 0.5 if lam.size > 1 else 1.0
    keep = w > 0
    if keep.sum() < n:
        raise InputError(f"spectrum: {name!r} has fewer than {n} wavelengths with light")
    lam, w = lam[keep], w[keep] / w[keep].sum()
    c, h = 0.5 * (lam[0] + lam[-1]), 0.5 * (lam[-1] - lam[0]) or 1.0
    t = (lam - c) / h
    alpha, beta = np.zeros(n), np.zeros(n)
    q_prev, q = np.zeros_like(t), np.ones_like(t)
    norm_prev = 1.0
    for k in range(n):
        norm = float(np.sum(w * q * q))
        alpha[k] = float(np.sum(w * t * q * q)) / norm
        if k > 0:
            beta[k] = norm / norm_prev
        q_prev, q = q, (t - alpha[k]) * q - (beta[k] if k > 0 else 0.0) * q_prev
        norm_prev = norm
    jac = np.diag(alpha) + np.diag(np.sqrt(beta[1:]), 1) + np.diag(np.sqrt(beta[1:]), -1)
    nodes, vec = np.linalg.eigh(jac)
    weights = vec[0] ** 2
    weights = weights / weights.sum()
    return Spectrum(name, tuple(float(x) for x in c + h * nodes), tuple(float(x) for x in weights))


def spectrum_of(name: str, n: int | None = None, *, qe: bool = True) -> Spectrum:
    """The typical LED ``name`` ("white", "red", "green", "blue") times the silicon QE
    (``qe``), in photons, sampled at ``n`` wavelengths (default :data:`DEFAULT_POINTS`)."""
    lam = _grid()
    dens = led_power(name, lam) * lam * (silicon_qe(lam) if qe else 1.0)
    return spectrum_from_density(name, lam, dens, DEFAULT_POINTS[name] if n is None else n)


def channels(
    design: Design, illumination: str | Spectrum | None = None, n: int | None = None
) -> dict[str, Spectrum]:
    """The light's channels for ``design``: one Spectrum per channel.

    Parameters
    ----------
    design : the design (its ``wavelength_um`` for "mono", its ``electronics.illumination``
        where ``illumination`` is None)
    illumination : None, a name ("mono", "white", "red", "green", "blue", "rgb") or a
        :class:`Spectrum` (one channel)
    n : wavelengths per channel (default: :data:`DEFAULT_POINTS`; 1 for "mono")
    """
    if isinstance(illumination, Spectrum):
        return {illumination.name: illumination}
    name = design.electronics.illumination if illumination is None else illumination
    if name not in CHANNELS:
        raise InputError(
            f"spectrum: unknown illumination {name!r}; use one of {', '.join(CHANNELS)}"
        )
    if name == "mono":
        return {"mono": mono(design.wavelength_um)}
    return {ch: spectrum_of(ch, n) for ch in CHANNELS[name]}


def grey_light(design: Design, per_led: int | None = None) -> Spectrum:
    """The light of ``design``'s grey scans: its one channel (as :func:`channels` gives
    it), or for a colour scanner ("rgb") its three LEDs lit together at the luminance
    weights ``LUMA`` of their channels' spectra (each normalised, at ``per_led``
    wavelengths, default each LED's :data:`DEFAULT_POINTS`), so that a grey scan's responsivity is
    sum_c LUMA_c R_c: the grey value that a colour scan of a grey document would give
    (its channels at equal white, mixed as :func:`~opticalstamp.imaging.scan.simulate_scan`
    mixes a colour document), in one exposure."""
    if design.electronics.illumination != "rgb":
        return one_channel(design)
    ch = channels(design, None, per_led)
    lam, w = [], []
    for name, luma in zip(CHANNELS["rgb"], LUMA, strict=True):  # red, green, blue
        lam.extend(ch[name].wavelengths_um)
        w.extend(luma * v for v in ch[name].weights)
    total = sum(w)  # 1 to rounding: LUMA and each channel's weights sum to 1
    return Spectrum("rgb-grey", tuple(lam), tuple(v / total for v in w))


def one_channel(design: Design, spectrum: str | Spectrum | None = None) -> Spectrum:
    """The single channel of ``spectrum`` (default: the design's illumination); a light of
    several channels ("rgb") is refused naming them."""
    ch = channels(design, spectrum)
    if len(ch) > 1:
        name = design.electronics.illumination if spectrum is None else spectrum
        raise InputError(
            f"spectrum: {name!r} has {len(ch)} channels ({', '.join(ch)}), one responsivity "
            "each; pass one of them (spectrum='green') or take them all with "
            "wavespectral.wave_response_channels"
        )
    return next(iter(ch.values()))
