"""Scalar Fresnel diffraction by the holes of a layer (paper Fig. 6).

A point source a (reduced, air-equivalent) distance R1 in front of an aperture, the
observation plane R2 behind it (a thickness t of index n counts as t / n with the vacuum
wavelength). In the Fresnel (paraxial) approximation, with 1/L = 1/R1 + 1/R2, the field
behind a slit |xi| <= w/2 relative to the unobstructed field is

    U/U0 = (1 - i)/2 * {[C(t2) - C(t1)] + i [S(t2) - S(t1)]},
    t = sqrt(2 / (lambda L)) (xi - xi0),  xi0 = L (x_s / R1 + x / R2),

with C, S the Fresnel integrals: exact ground truth for slits and (separable) rectangles.
A circular hole of radius a uses the radial Fresnel integral (Gauss-Legendre on [0, a]):

    U/U0 = (2 pi / (i lambda L)) exp(i pi rho0^2 / (lambda L))
           * integral_0^a exp(i pi rho^2 / (lambda L)) J0(2 pi rho rho0 / (lambda L)) rho drho

with rho0 = L r / R2; on the axis |U/U0|^2 = 4 sin^2(pi a^2 / (2 lambda L)).
The geometric shadow edge is at x_g = (w / 2) (R1 + R2) / R1 (paper: 32 um for a 48 um
slit, Z = 1 mm, R1 = 2 mm, R2 = 0.66 mm). The power through the aperture is I0 times
the geometric image's size, so the fraction outside x_g is 1 - (mean of I/I0 inside).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import lru_cache

import numpy as np
from scipy import special

from ..design import Design

DEFAULT_WAVELENGTHS_UM = (0.4, 0.7)


def _lengths(r1_um: float, r2_um: float, wavelength_um: float) -> float:
    if r1_um <= 0 or r2_um <= 0:
        raise ValueError("distances R1 and R2 must be > 0")
    if wavelength_um <= 0:
        raise ValueError("wavelength must be > 0")
    return 1.0 / (1.0 / r1_um + 1.0 / r2_um)


def slit_field(
    x_um, slit_um: float, r1_um: float, r2_um: float, wavelength_um: float, x_source_um: float = 0.0
) -> np.ndarray:
    """Complex field U/U0 behind a slit of width ``slit_um`` (exact Fresnel integrals)."""
    big_l = _lengths(r1_um, r2_um, wavelength_um)
    x = np.asarray(x_um, dtype=np.float64)
    xi0 = big_l * (x_source_um / r1_um + x / r2_um)
    k = np.sqrt(2.0 / (wavelength_um * big_l))
    s1, c1 = special.fresnel(k * (-slit_um / 2 - xi0))
    s2, c2 = special.fresnel(k * (slit_um / 2 - xi0))
    return (1 - 1j) / 2 * ((c2 - c1) + 1j * (s2 - s1))


def slit_intensity(x_um, slit_um, r1_um, r2_um, wavelength_um, x_source_um=0.0) -> np.ndarray:
    """I/I0 behind a slit: 1 far inside the geometric image, 1/4 at its edge (Fig. 6b)."""
    return np.abs(slit_field(x_um, slit_um, r1_um, r2_um, wavelength_um, x_source_um)) ** 2


def geometric_edge(width_um: float, r1_um: float, r2_um: float) -> float:
    """Half width (um) of the aperture's geometric shadow on the observation plane.

    A source in the aperture's plane (``r1_um`` = 0: a document touching a design's top
    mask) casts no shadow: the edge is at infinity.
    """
    if r1_um == 0:
        return float("inf")
    return width_um / 2 * (r1_um + r2_um) / r1_um


def _inside_mean_1d(width_um, r1_um, r2_um, wavelength_um, half_um, n=4001) -> float:
    x = np.linspace(-half_um, half_um, n)
    i = slit_intensity(x, width_um, r1_um, r2_um, wavelength_um)
    from scipy.integrate import simpson

    return float(simpson(i, x=x) / (2 * geometric_edge(width_um, r1_um, r2_um)))


@lru_cache(maxsize=8)
def _gauss_legendre(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [-1, 1] (an eigenvalue solve, ~0.5 s at the
    orders used: computed once per order), read-only."""
    t, w = np.polynomial.legendre.leggauss(order)
    t.flags.writeable = w.flags.writeable = False
    return t, w


def circle_field(
    r_um, diameter_um: float, r1_um: float, r2_um: float, wavelength_um: float, order: int = 400
) -> np.ndarray:
    """Complex field U/U0 at radius r behind a circular hole (radial Fresnel integral)."""
    big_l = _lengths(r1_um, r2_um, wavelength_um)
    a = diameter_um / 2
    t, wt = _gauss_legendre(order)
    rho = (t + 1) * a / 2
    wt = wt * a / 2
    r = np.asarray(r_um, dtype=np.float64)
    rho0 = big_l * r / r2_um
    q = np.pi / (wavelength_um * big_l)
    kern = np.exp(1j * q * rho**2) * rho * wt
    j0 = special.j0(2 * q * rho0[..., None] * rho)
    integral = (j0 * kern).sum(axis=-1)
    return 2 * q / 1j * np.exp(1j * q * rho0**2) * integral


def circle_intensity(r_um, diameter_um, r1_um, r2_um, wavelength_um) -> np.ndarray:
    return np.abs(circle_field(r_um, diameter_um, r1_um, r2_um, wavelength_um)) ** 2


def fraction_outside(
    shape: str,
    size_um: float,
    r1_um: float,
    r2_um: float,
    wavelength_um: float,
    half_um: float | None = None,
) -> float:
    """Fraction of the power through a hole landing outside a region on the next plane.

    The region is the hole's geometric shadow (default) or, with ``half_um``, a square
    of that half width (circle: a disk of that radius) centred on the axis (e.g. the next
    layer's hole). ``shape``: "slit", "square" (separable) or "circle".

    A source in the aperture's plane (``r1_um`` = 0) is the limit the formula tends to:
    the hole does not bound its light, nothing lies outside the (infinite) shadow and
    all of it lies outside any finite region.
    """
    if shape not in ("slit", "square", "rectangle", "circle"):
        raise ValueError(f"shape must be slit, square or circle (got {shape!r})")
    if r1_um == 0 and r2_um > 0 and wavelength_um > 0:
        return 0.0 if half_um is None else 1.0
    xg = geometric_edge(size_um, r1_um, r2_um)
    h = xg if half_um is None else half_um
    if shape == "slit":
        return 1.0 - _inside_mean_1d(size_um, r1_um, r2_um, wavelength_um, h)
    if shape in ("square", "rectangle"):
        return 1.0 - _inside_mean_1d(size_um, r1_um, r2_um, wavelength_um, h) ** 2
    if shape == "circle":
        r = np.linspace(0, h, 1201)
        i = circle_intensity(r, size_um, r1_um, r2_um, wavelength_um)
        from scipy.integrate import simpson

        return float(1.0 - simpson(i * 2 * np.pi * r, x=r) / (np.pi * xg * xg))


@dataclass(frozen=True)
class SlitResult:
    """Paper Fig. 6: a slit between a point source and the next layer."""

    slit_um: float
    z_mm: float
    r1_um: float
    r2_um: float
    wavelengths_um: list[float]
    geometric_edge_um: float
    fraction_outside: dict[str, float]  # keyed by wavelength in um ("0.4")
    x_um: np.ndarray
    intensity: dict[str, np.ndarray]  # I/I0 per wavelength
    fresnel_number: dict[str, float]  # (w/2)^2 / (lambda L)
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["x_um"] = self.x_um.tolist()
        d["intensity"] = {k: v.tolist() for k, v in self.intensity.items()}
        return d


def _wkey(w: float) -> str:
    return f"{w:g}"


def slit_case(
    *,
    slit_um: float = 48.0,
    z_mm: float = 1.0,
    gap_um: float = 1000.0,
    r2_um: float = 1000.0 / 1.52,
    wavelengths_um=DEFAULT_WAVELENGTHS_UM,
    n_points: int = 801,
) -> SlitResult:
    """The paper's Fig. 6 model: source Z above the reference plane, slit at layer 1.

    R1 = Z + gap (air-equivalent distance from the source to the slit), R2 the
    air-equivalent distance from the slit to the next layer (1.0 mm glass / 1.52).
    """
    if slit_um <= 0 or z_mm < 0 or gap_um < 0:
        raise ValueError("slit width must be > 0, Z and gap >= 0")
    r1 = z_mm * 1000.0 + gap_um
    if r1 <= 0:
        raise ValueError(
            "Z = 0 with a gap of 0 puts the point source in the slit (R1 = 0): it casts no "
            "geometric shadow, so there is no edge to diffract around; give Z > 0 or a gap > 0"
        )
    xg = geometric_edge(slit_um, r1, r2_um)
    x = np.linspace(-2 * xg, 2 * xg, n_points)
    ws = [float(w) for w in wavelengths_um]
    inten, frac, nf = {}, {}, {}
    for w in ws:
        inten[_wkey(w)] = slit_intensity(x, slit_um, r1, r2_um, w)
        frac[_wkey(w)] = fraction_outside("slit", slit_um, r1, r2_um, w)
        nf[_wkey(w)] = (slit_um / 2) ** 2 / (w * _lengths(r1, r2_um, w))
    return SlitResult(slit_um, z_mm, r1, r2_um, ws, xg, frac, x, inten, nf)


def diffraction_budget(
    design: Design,
    *,
    z_mm: float = 1.0,
    wavelengths_um=DEFAULT_WAVELENGTHS_UM,
    warn_fraction: float = 0.25,
) -> dict:
    """How much light each hole diffracts outside the next aperture, layer by layer.

    An on-axis point source Z above the reference plane; for each mask from the object
    side down, the field behind its hole is observed on the next mask (or the pixel's
    sensitive area after the last one). Reported per wavelength: the diffracted fraction
    outside the hole's geometric shadow, and the fractions outside the next aperture
    with diffraction and geometrically (their difference is what diffraction costs or
    gives). A warning is raised where the spill outside the shadow exceeds
    ``warn_fraction`` (the paper warns about going beyond 300 dpi).
    """
    # planes from the object downward: reduced distance from the source, aperture
    red_from_top = []
    red = z_mm * 1000.0 / design.index(design.object_medium)
    gap = design.reference_gap
    red += gap.thickness_um / design.index(gap.medium)
    for sl in reversed(design.slabs):
        if sl.mask_top is not None:
            red_from_top.append((red, sl.mask_top))
        red += sl.thickness_um / design.index(sl.medium)
    s = design.sensor
    sensor_plane = red
    layers = []
    warnings = []
    for i, (r_src, m) in enumerate(red_from_top):
        if i + 1 < len(red_from_top):
            r_next, nxt = red_from_top[i + 1]
            next_name = nxt.name or f"mask {i + 1}"
            next_half = min(nxt.hole_width_um, nxt.hole_height_um) / 2
        else:
            r_next, next_name = sensor_plane, "sensor pixel"
            next_half = min(s.sensitive_width_um, s.sensitive_height_um) / 2
        r2 = r_next - r_src
        size = min(m.hole_width_um, m.hole_height_um)
        shape = "circle" if m.shape == "circle" else "square"
        row = {
            "layer": m.name or f"mask {i}",
            "next": next_name,
            "hole_um": size,
            "shape": shape,
            "r1_um": r_src,
            "r2_um": r2,
            "geometric_edge_um": geometric_edge(size, r_src, r2),
            "next_half_um": next_half,
            "outside_shadow": {},
            "outside_next": {},
            "outside_next_geometric": 0.0,
            "fresnel_number": {},
        }
        # uniform geometric image (square or disk) of half width x_g: area outside
        row["outside_next_geometric"] = 1.0 - min(next_half / row["geometric_edge_um"], 1.0) ** 2
        for w in wavelengths_um:
            k = _wkey(float(w))
            row["outside_shadow"][k] = fraction_outside(shape, size, r_src, r2, w)
            row["outside_next"][k] = fraction_outside(shape, size, r_src, r2, w, next_half)
            row["fresnel_number"][k] = (
                float("inf") if r_src == 0 else (size / 2) ** 2 / (w * _lengths(r_src, r2, w))
            )
            if row["outside_shadow"][k] > warn_fraction:
                warnings.append(
                    f"{row['layer']}: {row['outside_shadow'][k]:.0%} of the light through "
                    f"its {size:g} um holes is diffracted outside their geometric shadow at "
                    f"{w:g} um (Fresnel number {row['fresnel_number'][k]:.2f}); diffraction "
                    "will blur this design"
                )
        layers.append(row)
    return {
        "z_mm": z_mm,
        "wavelengths_um": [float(w) for w in wavelengths_um],
        "warn_fraction": warn_fraction,
        "layers": layers,
        "warnings": warnings,
    }


def geometric_optics_warnings(design: Design, warn_fraction: float = 0.25) -> list[str]:
    """Warnings for holes so small that diffraction, not geometry, sets the blur.

    The per-layer budget of :func:`diffraction_budget` at the design's wavelength and
    Z = 0: a layer whose holes diffract more than ``warn_fraction`` of their light outside
    the geometric shadow is outside the ray model's validity: its ray figures (light,
    spots, RMTF) are off, in either direction (diffraction both spreads the light and
    brings more of it through small holes: docs/wave.md), and the wave engine's hold.
    """
    b = diffraction_budget(
        design, z_mm=0.0, wavelengths_um=(design.wavelength_um,), warn_fraction=warn_fraction
    )
    return [
        w + " (geometric optics does not hold there: the ray figures are off, either way; "
        "--optics auto, the default, or wave gives the wave engine's)"
        for w in b["warnings"]
    ]


def design_slit_case(
    design: Design, *, z_mm: float = 1.0, wavelengths_um=DEFAULT_WAVELENGTHS_UM
) -> SlitResult:
    """Paper Fig. 6 for this design: its object-side mask as the slit.

    The slit is that mask's hole (the smaller side), R1 the air-equivalent distance from a
    source Z above the reference plane (through the reference gap), R2 the air-equivalent
    distance to the next mask, or to the sensor for a one-mask stack; the same geometry as
    the first row of :func:`diffraction_budget`.
    """
    row = diffraction_budget(design, z_mm=z_mm, wavelengths_um=wavelengths_um)["layers"][0]
    r_obj = z_mm * 1000.0 / design.index(design.object_medium)
    return slit_case(
        slit_um=row["hole_um"],
        z_mm=z_mm,
        gap_um=row["r1_um"] - r_obj,
        r2_um=row["r2_um"],
        wavelengths_um=wavelengths_um,
    )
