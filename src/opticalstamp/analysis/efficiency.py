"""Light efficiency against the paper's reference lens (paper Fig. 13, §5).

The power a used pixel receives from a uniform Lambertian object of radiance L is L G,
with G the pixel's etendue (um^2 sr) through the stack (own path, plus ghost paths if
counted). The reference is a 1:1 lens (f = 10 mm, 2 mm pupil, object and image 20 mm
away, working F-number 2 f / D = 10) in front of an 84.6 um pixel: G_ref = integral over
the pixel of the projected solid angle of the pupil disk. The ratio G / G_ref is the
light efficiency and F_w = 10 / sqrt(ratio) its equivalent working F-number (paper:
1/36, F 60).

The own-path etendue of a design with rectangular holes is the deterministic integral of
:func:`~opticalstamp.analysis.own_etendue.own_etendue` (no sampling error); circular holes
take the tracer's estimate. The ghost light always comes from the tracer.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..defaults import RAYS_LSF, RSE_GHOST, RSE_OWN
from ..design import Design, with_sensitive_area
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import output_pitch
from .colour import LIGHT_RULE, weakest_channel
from .ghosts import GhostResult, analyse_ghosts
from .own_etendue import own_etendue, rectangular_holes
from .responsivity import Optics, pixel_light, pixel_light_channels, resolve_optics
from .spectrum import channels as light_channels


def disk_projected_solid_angle(rho_um, h_um: float, radius_um: float) -> np.ndarray:
    """Projected solid angle (sr) of a disk seen from a point on a parallel plane.

    The point is ``h_um`` below the disk plane and ``rho_um`` off its axis (view factor
    of a disk from a parallel differential area, times pi).
    """
    rho = np.asarray(rho_um, dtype=np.float64)
    a2, h2, r2 = radius_um**2, h_um**2, rho**2
    return np.pi / 2 * (1 - (h2 + r2 - a2) / np.sqrt((h2 + r2 + a2) ** 2 - 4 * a2 * r2))


def reference_etendue(
    pixel_um: float,
    focal_mm: float = 10.0,
    pupil_mm: float = 2.0,
    conjugate_mm: float = 20.0,
    order: int = 16,
) -> float:
    """Etendue (um^2 sr) of a square pixel behind the paper's reference lens (Fig. 13).

    The paper's pixel is its 84.6 um merged pixel; :func:`efficiency` uses the design's own
    output pitch.

    Gauss-Legendre quadrature over the pixel of the pupil's projected solid angle seen
    from the image plane ``conjugate_mm`` behind the lens.
    """
    if min(pixel_um, focal_mm, pupil_mm, conjugate_mm) <= 0:
        raise ValueError("reference lens: pixel, focal length, pupil and conjugate must be > 0")
    t, wt = np.polynomial.legendre.leggauss(order)
    x = t * pixel_um / 2
    rho = np.hypot(x[:, None], x[None, :])
    omega = disk_projected_solid_angle(rho, conjugate_mm * 1000.0, pupil_mm * 500.0)
    return float((wt[:, None] * wt[None, :] * omega).sum() * (pixel_um / 2) ** 2)


def reference_f_number(focal_mm: float = 10.0, pupil_mm: float = 2.0) -> float:
    """Working F-number of a 1:1 lens: 2 f / D (paper: 10)."""
    return 2 * focal_mm / pupil_mm


@dataclass(frozen=True)
class EfficiencyResult:
    """Light efficiency of one used pixel (JSON-ready through :meth:`to_dict`).

    Etendues in um^2 sr. ``etendue_own_um2sr`` comes from ``own_method``: "quadrature"
    (rectangular holes: the exact integral, ``etendue_own_se`` 0) or "trace" (circular
    holes); ``etendue_own_traced_um2sr`` and its SE are the tracer's estimate from the
    ghost analysis either way (the rays that give the ghost split). Every figure built on
    the own path (``etendue_um2sr``, the ratios, ``by_object_radius``, the rows of
    ``sensitive_area`` with their ghost fraction ghost / (own + ghost)) uses
    ``etendue_own_um2sr``.
    """

    design: str
    fingerprint: str
    seed: int
    fresnel: bool
    etendue_um2sr: float  # own + ghost (what a uniform object gives)
    etendue_se: float
    etendue_own_um2sr: float
    etendue_own_se: float
    own_method: str  # "quadrature" (rectangular holes) or "trace"
    etendue_own_traced_um2sr: float
    etendue_own_traced_se: float
    etendue_ghost_um2sr: float
    reference_etendue_um2sr: float
    reference_f_number: float
    ratio: float
    ratio_own: float
    working_f_number: float
    working_f_number_own: float
    by_object_radius: dict  # Z (mm) -> {radius mm -> etendue from object within it}
    sensitive_area: list[dict]
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


def efficiency(
    design: Design,
    *,
    z_mm=(0.0, 1.0, 2.0, 3.0, 4.0),
    object_radii_mm=(1.0, 5.0, 10.0),
    seed: int = 0,
    fresnel: bool = False,
    rse_own: float = RSE_OWN,
    rse_ghost: float = RSE_GHOST,
    area_scales=(1.0, 2.0),
    reference: dict | None = None,
    ghosts: GhostResult | None = None,
    progress: bool = False,
    optics: str | Optics = "ray",
    tracer: PixelTracer | None = None,
    n_rays: int = RAYS_LSF,
) -> EfficiencyResult:
    """Light efficiency of one used pixel (paper Fig. 13), with and without ghost light.

    ``by_object_radius`` shows the dependence on Z: for a uniform object covering only a
    disk of the given radius around the pixel's axis, the etendue collected at each Z
    (own-path light is Z-independent; ghost light arrives from far away and leaves a
    finite object as Z grows). ``area_scales`` scales the sensitive area's sides (2:
    four times the area, the paper's custom-sensor claim). ``ghosts``: the design's
    ghost analysis if the caller has one already (its Z values and pixel are used).

    The own-path etendue (every figure built on it) is the deterministic integral of
    :func:`~opticalstamp.analysis.own_etendue.own_etendue` where every hole is
    rectangular, with the same Fresnel option; the ghost etendue is traced.

    ``optics`` "wave" (or "auto" where the validity rule picks it): all light
    (``etendue_um2sr``, its SE, ``ratio``, ``working_f_number``) is the wave engine's
    in-band light plus the traced light outside its band, and the signal
    (``etendue_own_um2sr``, ``ratio_own``; ``own_method`` "wave (in band)") the wave
    engine's in-band light: the own path with its diffraction and the near crosstalk in
    the band (:func:`~opticalstamp.analysis.responsivity.pixel_light`); ``meta["optics"]``
    holds the breakdown and the ray figures they replace. The object-radius and
    sensitive-area studies stay geometric (ray optics), and say so there. A colour
    scanner (``electronics.illumination`` "rgb"): the light per channel in
    ``meta["optics"]["channels"]`` (:func:`~opticalstamp.analysis.responsivity.
    pixel_light_channels`), the headline the weakest channel's signal
    (:data:`~opticalstamp.analysis.colour.LIGHT_RULE`, ``meta["optics"]["headline"]``).
    ``n_rays``: rays of the traced light beyond the wave band.

    ``tracer``: a :class:`~opticalstamp.raytrace.pixel.PixelTracer` of ``design`` whose
    pilots and kept rays the design's own traces reuse (the ghost analysis where
    ``ghosts`` is None, the traced light of :func:`pixel_light`): rays its other analyses
    traced already are not traced again.
    """
    ref = {"pixel_um": output_pitch(design)} | dict(reference or {})
    g_ref = reference_etendue(**ref)
    f_ref = reference_f_number(ref.get("focal_mm", 10.0), ref.get("pupil_mm", 2.0))
    g = ghosts or analyse_ghosts(
        design,
        z_mm=tuple(z_mm),
        seed=seed,
        fresnel=fresnel,
        rse_own=rse_own,
        rse_ghost=rse_ghost,
        progress=progress,
        tracer=tracer,
    )
    exact = rectangular_holes(design)
    pixel = ("AB".index(g.pixel["row"]), int(g.pixel["k"]))

    def own(d: Design, gd: GhostResult) -> tuple[float, float]:
        """Own-path etendue of ``d`` and its SE: exact, or ``gd``'s traced estimate."""
        if exact:
            return own_etendue(d, pixel=pixel, fresnel=fresnel), 0.0
        return gd.etendue_own_um2sr, gd.etendue_own_se

    g_own, g_own_se = own(design, g)
    tot = g_own + g.etendue_ghost_um2sr
    se = math.hypot(g_own_se, g.etendue_ghost_se)
    by_r = {}
    for zkey, land in g.landing.items():
        h = np.asarray(land["etendue_by_distance_um2sr"])
        edges = (np.arange(h.size) + 1) * land["bin_um"]  # upper edge of each bin
        by_r[zkey] = {
            f"{r:g}": g_own + float(h[edges <= r * 1000.0].sum()) for r in object_radii_mm
        } | {"inf": tot}
    areas = []
    s = design.sensor
    for k in area_scales:
        d = (
            design
            if k == 1.0
            else with_sensitive_area(design, s.sensitive_width_um * k, s.sensitive_height_um * k)
        )
        gk = g if k == 1.0 else analyse_ghosts(d, pixel=pixel, seed=seed, fresnel=fresnel)
        ok = own(d, gk)[0] if k != 1.0 else g_own
        ghost = gk.etendue_ghost_um2sr
        areas.append(
            {
                "area_scale": k * k,
                "sensitive_um": [s.sensitive_width_um * k, s.sensitive_height_um * k],
                "etendue_own_um2sr": ok,
                "etendue_um2sr": ok + ghost,
                "ghost_fraction": ghost / (ok + ghost) if exact and ok > 0 else gk.ghost_fraction,
                "gain_vs_design": _over(ok + ghost, tot),
                "gain_own_vs_design": _over(ok, g_own),
            }
        )
    opt = resolve_optics(design, optics, fresnel=fresnel, channels=True)
    optics_meta = opt.to_dict()
    own_method = "quadrature" if exact else "trace"
    if opt.engine == "wave":
        kw = {"pixel": pixel, "n_rays": n_rays, "seed": seed, "tracer": tracer}
        if len(light_channels(design)) == 1:
            light = pixel_light(design, opt, **kw)
        else:  # a colour scanner: each channel's light, the weakest as the headline
            lights = pixel_light_channels(design, opt, **kw)
            weakest = weakest_channel(lights)
            light = lights[weakest] | {
                "channels": lights,
                "headline": {"channel": weakest, "rule": LIGHT_RULE},
            }
        optics_meta |= light | {
            "ray_etendue_um2sr": tot,
            "ray_etendue_own_um2sr": g_own,
            "ray_ratio": tot / g_ref,
            "ray_ratio_own": g_own / g_ref,
            "geometric": ["by_object_radius", "sensitive_area"],
        }
        # the signal: the own path with its diffraction (and the near crosstalk in the band)
        tot, se = light["etendue_um2sr"], g.etendue_ghost_se
        g_own, g_own_se, own_method = light["wave_in_band_um2sr"], 0.0, "wave (in band)"
    ratio, ratio_own = tot / g_ref, g_own / g_ref
    return EfficiencyResult(
        design=design.name,
        fingerprint=design.fingerprint(),
        seed=seed,
        fresnel=fresnel,
        etendue_um2sr=tot,
        etendue_se=se,
        etendue_own_um2sr=g_own,
        etendue_own_se=g_own_se,
        own_method=own_method,
        etendue_own_traced_um2sr=g.etendue_own_um2sr,
        etendue_own_traced_se=g.etendue_own_se,
        etendue_ghost_um2sr=g.etendue_ghost_um2sr,
        reference_etendue_um2sr=g_ref,
        reference_f_number=f_ref,
        ratio=ratio,
        ratio_own=ratio_own,
        working_f_number=_over(f_ref, math.sqrt(ratio)),
        working_f_number_own=_over(f_ref, math.sqrt(ratio_own)),
        by_object_radius=by_r,
        sensitive_area=areas,
        meta={
            "reference_lens": {
                "focal_mm": 10.0,
                "pupil_mm": 2.0,
                "conjugate_mm": 20.0,
            }
            | ref,
            "optics": optics_meta,
        },
    )


def ratio_text(ratio: float, digits: int = 1) -> str:
    """A light ratio as an engineer writes it: "1/26.3" below 1, "3.2×" from 1 up, "0"
    where no light reaches the pixel (never a division by zero)."""
    if not ratio > 0:
        return "0" if ratio == 0 else "-"
    if ratio < 1:
        return f"1/{1 / ratio:.{digits}f}"
    return f"{ratio:.3g}×"


def _over(a: float, b: float) -> float:
    """a / b, where no light (b = 0) gives inf (a working F-number) or NaN (a gain of no
    light over none): a design through which no light reaches the pixel."""
    if b == 0:
        return float("inf") if a > 0 else float("nan")
    return a / b
