"""When ray optics holds: the measured validity rule behind ``--optics auto`` (issue 23).

The tracer's figures (geometric optics) go wrong where the holes are small against the
gaps: the wave engine (:mod:`.wave`) then gives the pixel's light, spot and RMTF. The rule
here decides, from the design's geometry alone (no tracing, no wave run: about a
millisecond), whether the ray figures can be trusted within stated tolerances.

**The predictor** is the own path's Fresnel number P = G_1 / (4 lambda)
(:func:`own_fresnel_number`): G_1 is the paraxial own path's etendue along one axis (um,
the smaller of x and y), so G_1 / lambda is the number of coherent modes the chain of the
pixel and its own holes carries; for two equal apertures of side 2a a reduced distance d
apart P is their Fresnel number a^2 / (lambda d). Of the candidates measured (the least
layer Fresnel number, the least inside the stack, their harmonic mean, the object-side
mask over the reference gap, the own path's) it orders the study's errors best (Spearman
-0.85 for the light, -0.91 for the RMTF; the least layer Fresnel number -0.82 / -0.80)
and sends the fewest designs to wave needlessly (6 of the 9 whose ray figures were within
both tolerances, against 7 or 8 of 9): the least Fresnel number is usually the reference
gap's, and the gap moves the errors little (gap 0.5/1/2 mm: light +9.7 % each, RMTF
0.094/0.094/0.047).

**The bound** on each error is an upper envelope a P^-p of the study
(``scripts/wave_validity.py``: 36 designs whose least layer Fresnel numbers run from 0.07
to 19 and P from 0.04 to 12; the table in ``docs/wave-validity.json``, the figure and
its reading in ``docs/wave-validity.md``): the tightest power law on or above every
design's error plus two standard errors (:func:`fit_envelope`; the ray side pooled over
4 seeds of 2^18 rays a row, the standard errors from their spread), times
``ENVELOPE_MARGIN`` = 1.2 for a fresh run's own noise and the heights between the
study's samples. The errors (:func:`ray_errors`): the light, |wave / ray - 1| of the
in-band light, the ray light being the paraxial own-path etendue (the separable wave
path's own geometric limit, so that the error is diffraction's alone) plus the traced
near ghosts in the band; the RMTF, the largest |wave - ray| on the design's depth-of-field
chart at Z = 0-3 mm (0.5 mm steps). ``auto`` picks wave where either bound exceeds its
tolerance.

**Default tolerances.** Light 5 %: the size of the losses the default model already
leaves out (each of the prototype's two air-glass interfaces reflects 4.3 % at normal
incidence, ((n - 1) / (n + 1))^2 at n = 1.52; ``--fresnel`` is off by default), so a
smaller ray error would not be the largest one left. RMTF 0.05: on the prototype the
RMTF falls by about 0.21 per mm near the 0.3 threshold (2.5-3 mm), so 0.05 is about
0.25 mm of depth of field (9 % of its 2.7 mm), 2.5 times the 0.02 to which the fast
surrogate is held against the trace.
With them ray optics holds for P >= 3.1 (the RMTF bound; the light bound alone: P >=
2.3): the prototype scaled to 150 dpi (holes and pixels twice as wide) over plates half
as thick (P = 5.3), or to 100 dpi over its own plates (P = 6.0). The prototype itself
(P = 0.66) is off by +9.7 % in light and 0.094 in RMTF: wave.

Not covered: circular holes on a CPU (their 2-D maps take minutes a height there:
ray, with the predicted error said and ``--optics wave`` named; where the run's device
is a GPU with CuPy the rule applies to them, their Fresnel number the circle's radius's),
rod-lens arrays (no masks: ray), the far ghost
light (outside any wave band; the tracer's on both sides), a spectrum (one wavelength,
the design's), designs outside the study's range of P (the bound is extrapolated: it
keeps falling above P = 12 and exceeds 1 below 0.04).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from scipy.optimize import linprog

from ..design import Design
from ..design.variants import square_holes
from ..validate import InputError
from .paraxial import paraxial_etendue, paraxial_etendue_1d
from .wavebase import CIRCLE_MAPS, fresnel_numbers, rectangular

#: The engines ``choose_optics`` takes.
OPTICS = ("ray", "wave", "auto")
#: Default tolerances on the ray figures' error (see the module docstring).
DEFAULT_LIGHT_TOL = 0.05
DEFAULT_RMTF_TOL = 0.05
#: The predictor the rule uses (a key of :func:`design_predictors`).
CHOSEN = "fresnel_own"
#: The envelope is the tightest power law over the study's errors times this margin.
ENVELOPE_MARGIN = 1.2
#: The RMTF error is the largest difference at heights up to this (mm).
RMTF_Z_MAX_MM = 3.0


@dataclass(frozen=True)
class Envelope:
    """An upper bound on an error as a power of the predictor P: ``a * P**-p``."""

    a: float
    p: float

    def bound(self, predictor):
        """The bound at ``predictor`` (float or array)."""
        with np.errstate(divide="ignore"):  # P = 0 (no own path): no bound, inf
            return self.a * np.asarray(predictor, dtype=np.float64) ** -self.p

    def predictor_for(self, tolerance: float) -> float:
        """The predictor above which the bound is below ``tolerance``."""
        return float((self.a / tolerance) ** (1.0 / self.p))

    def to_dict(self) -> dict:
        return {"a": self.a, "p": self.p}

    def __str__(self) -> str:
        return f"{self.a:.4g} P^-{self.p:.3g}"


def fit_envelope(predictor, error, *, margin: float = 1.0) -> Envelope:
    """The tightest power law a P^-p over every point (P_i, |error_i|), times ``margin``.

    Tightest: the line log a - p log P in log-log axes that lies on or above every
    point with the least mean height above them (a linear programme in log a and p,
    p >= 0). Points with no error (0) set no bound.
    """
    x = np.log(np.asarray(predictor, dtype=np.float64))
    e = np.abs(np.asarray(error, dtype=np.float64))
    ok = np.isfinite(x) & (e > 0)
    x, y = x[ok], np.log(e[ok])
    if x.size < 2:
        raise ValueError("fit_envelope: at least two points with an error are needed")
    # variables (log a, p): minimise sum(log a - p x) s.t. log a - p x_i >= y_i
    res = linprog(
        c=[x.size, -x.sum()],
        A_ub=np.stack([-np.ones_like(x), x], axis=1),
        b_ub=-y,
        bounds=[(None, None), (0.0, None)],
        method="highs",
    )
    if not res.success:
        raise ValueError(f"fit_envelope: {res.message}")
    log_a, p = res.x
    return Envelope(float(np.exp(log_a) * margin), float(p))


def ray_errors(comparison, design: Design, z_max_mm: float = RMTF_Z_MAX_MM) -> dict:
    """The ray figures' errors the rule bounds, from ``design``'s
    :class:`~opticalstamp.analysis.wavecompare.WaveRayComparison`.

    ``light``: wave / ray - 1 of the light in the band, the ray light being the own
    path's paraxial etendue (:func:`~opticalstamp.analysis.paraxial.paraxial_etendue`,
    no Monte Carlo noise) plus the traced near ghosts in the band. The separable wave
    path is paraxial and tends to the paraxial etendue as lambda -> 0, so against it the
    error is diffraction's alone; the exact etendue (what ``efficiency`` reports) is
    smaller by the non-paraxial part of refraction, which an exact wave computation
    shares (0.05 % on the prototype, 1.6 % on the study's thinnest stack at 100 dpi).
    ``light_exact``: against the exact own etendue plus the near ghosts;
    ``light_traced``: against the traced in-band light; circular holes have only this
    one, and it is ``light`` for them. ``rmtf``: the largest |wave - ray| on the
    depth-of-field chart at the comparison's heights up to ``z_max_mm``.
    """
    c = comparison
    wave, near = c.wave["light_um2sr"], c.ray["near_um2sr"]
    out = {"light_traced": c.difference["light"], "light_exact": None}
    if c.own_exact_um2sr is not None:
        out["light_exact"] = wave / (c.own_exact_um2sr + near) - 1
    out["light"] = (
        wave / (paraxial_etendue(design) + near) - 1 if rectangular(design) else out["light_traced"]
    )
    z = np.asarray(c.z_mm, dtype=np.float64)
    d = np.abs(np.asarray(c.difference["rmtf"], dtype=np.float64))[z <= z_max_mm + 1e-9]
    out["rmtf"] = float(d.max())
    return out


#: The rule's envelopes, fitted by ``scripts/wave_validity.py`` (full run of 2026-11-25:
#: 36 designs, the ray side pooled over 4 seeds of 2^18 rays a row, Z = 0-5 mm in 0.5 mm
#: steps; ``docs/wave-validity.json``, ``predictors.fresnel_own``) over each error plus
#: two standard errors, margin included, a rounded up to 3 digits: the bounds on
#: |light wave / ray - 1| and on max |RMTF wave - ray| (Z 0-3 mm) against P.
ENVELOPES = MappingProxyType({"light": Envelope(0.113, 0.977), "rmtf": Envelope(0.149, 0.958)})


def design_predictors(design: Design, wavelength_um: float | None = None) -> dict:
    """Candidate predictors of the ray figures' error, from the design's geometry alone.

    Returns a dict: ``fresnel_min`` (the least Fresnel number a^2 / (lambda d) of
    :func:`~opticalstamp.analysis.wavebase.fresnel_numbers`, the reference gap
    included), ``fresnel_min_stack`` (the same inside the stack), ``fresnel_harmonic``
    (their harmonic mean, the gap included), ``fresnel_gap`` (the object-side mask
    over the reference gap; inf without a gap), ``fresnel_own`` (the own path's
    Fresnel number, :func:`own_fresnel_number`) and ``fresnel_own_gap`` (the smaller
    of the last two).
    """
    lam = design.wavelength_um if wavelength_um is None else float(wavelength_um)
    fr = fresnel_numbers(design, lam)
    f_all = np.array([f["fresnel_number"] for f in fr])
    gap = [f["fresnel_number"] for f in fr if f["towards"] == "reference plane"]
    f_stack = np.array([f["fresnel_number"] for f in fr if f["towards"] != "reference plane"])
    own = own_fresnel_number(design, lam)
    f_gap = gap[0] if gap else math.inf
    return {
        "fresnel_min": float(f_all.min()),
        "fresnel_min_stack": float(f_stack.min()),
        "fresnel_harmonic": float(f_all.size / (1.0 / f_all).sum()),
        "fresnel_gap": float(f_gap),
        "fresnel_own": own,
        "fresnel_own_gap": float(min(own, f_gap)),
    }


def own_fresnel_number(design: Design, wavelength_um: float | None = None) -> float:
    """The own path's Fresnel number: G_1 / (4 lambda), G_1 the paraxial own path's
    etendue along one axis (um; the smaller of x and y), a Z-independent closed form
    (:func:`~opticalstamp.analysis.paraxial.paraxial_etendue_1d`).

    G_1 / lambda is the number of coherent modes the own path carries along the axis;
    for two equal apertures of side 2a a reduced distance d apart G_1 = 4 a^2 / d, so
    the figure is then their Fresnel number a^2 / (lambda d). Circular holes count as
    their circumscribed squares.
    """
    lam = design.wavelength_um if wavelength_um is None else float(wavelength_um)
    sq = square_holes(design)
    g = min(paraxial_etendue_1d(sq, 0), paraxial_etendue_1d(sq, 1))
    return float(g / (4.0 * lam))


@dataclass(frozen=True)
class OpticsChoice:
    """Which engine gives a design's figures, and why.

    Attributes
    ----------
    engine : "ray" or "wave"
    fresnel_min : the least layer Fresnel number a^2 / (lambda d), the reference gap
        included (nan for a design without masks)
    predictor : the own path's Fresnel number P the rule reads (:func:`own_fresnel_number`)
    predicted_error : the rule's bounds on the ray figures' error at P: ``light``
        (|wave / ray - 1|) and ``rmtf`` (max |wave - ray|, Z 0-3 mm)
    tolerance : ``light`` and ``rmtf``, the tolerances the bounds were held to
    reason : why, in words ("asked for" where the engine was named)
    """

    engine: str
    fresnel_min: float
    predictor: float
    predicted_error: dict = field(default_factory=dict)
    tolerance: dict = field(default_factory=dict)
    reason: str = ""

    def to_dict(self) -> dict:
        return {
            "engine": self.engine,
            "fresnel_min": self.fresnel_min,
            "predictor": self.predictor,
            "predicted_error": dict(self.predicted_error),
            "tolerance": dict(self.tolerance),
            "reason": self.reason,
        }


def ray_holds_above(light_tol: float = DEFAULT_LIGHT_TOL, rmtf_tol: float = DEFAULT_RMTF_TOL):
    """The own-path Fresnel number above which both bounds are within the tolerances."""
    return max(
        ENVELOPES["light"].predictor_for(light_tol), ENVELOPES["rmtf"].predictor_for(rmtf_tol)
    )


def _tolerance(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: must be a number > 0 (got {value!r})") from None
    if not (v > 0 and math.isfinite(v)):
        raise InputError(f"{name}: must be a number > 0 (got {value!r})")
    return v


def choose_optics(
    design,
    *,
    optics: str = "auto",
    light_tol: float = DEFAULT_LIGHT_TOL,
    rmtf_tol: float = DEFAULT_RMTF_TOL,
) -> OpticsChoice:
    """The engine for ``design``: ``optics`` "ray" or "wave" as asked, "auto" by the rule.

    ``auto`` picks wave where the predicted ray error (:data:`ENVELOPES` at the own
    path's Fresnel number) exceeds ``light_tol`` (relative light) or ``rmtf_tol`` (RMTF on
    the depth-of-field chart), and ray elsewhere; ray also, saying so, where the wave
    engine cannot do the design (a rod-lens array) or would take minutes a height
    (circular holes on a CPU: :data:`~.wavebase.CIRCLE_MAPS`). No tracing, no wave
    run: the predictor is a closed form of the geometry.

    Raises
    ------
    InputError
        ``optics`` not one of ray, wave, auto; a tolerance not a number > 0.
    """
    if optics not in OPTICS:
        raise InputError(f"optics: must be one of {', '.join(OPTICS)} (got {optics!r})")
    tol = {"light": _tolerance(light_tol, "light_tol"), "rmtf": _tolerance(rmtf_tol, "rmtf_tol")}
    if not isinstance(design, Design):  # a rod-lens array: no masks, no wave engine
        reason = (
            "asked for"
            if optics != "auto"
            else ("a rod-lens array: the wave engine models aperture stacks only; ray")
        )
        return OpticsChoice(
            "wave" if optics == "wave" else "ray", math.nan, math.nan, {}, tol, reason
        )
    fmin = min(f["fresnel_number"] for f in fresnel_numbers(design))
    p = own_fresnel_number(design)
    err = {k: float(ENVELOPES[k].bound(p)) for k in ("light", "rmtf")}
    if optics != "auto":
        return OpticsChoice(optics, fmin, p, err, tol, "asked for")
    over = [k for k in ("light", "rmtf") if err[k] > tol[k]]
    said = (
        f"the own path's Fresnel number {p:.2f} bounds the ray figures' error at "
        f"{err['light']:.1%} in light and {err['rmtf']:.3f} in RMTF"
    )
    if not over:
        reason = (
            f"{said}, within the tolerances ({tol['light']:.1%}, {tol['rmtf']:.3f}): "
            "ray optics holds"
        )
        return OpticsChoice("ray", fmin, p, err, tol, reason)
    names = {"light": f"light ({tol['light']:.1%})", "rmtf": f"RMTF ({tol['rmtf']:.3f})"}
    beyond = " and ".join(names[k] for k in over)
    if not rectangular(design) and not _maps_on_gpu():
        reason = f"{said}, beyond the tolerance for {beyond}; {CIRCLE_MAPS}: ray, with that error"
        return OpticsChoice("ray", fmin, p, err, tol, reason)
    return OpticsChoice(
        "wave", fmin, p, err, tol, f"{said}, beyond the tolerance for {beyond}: wave"
    )


def validity_lines(choice: OpticsChoice) -> list[str]:
    """The choice as lines of text for the terminal."""
    out = [f"optics: {choice.engine} ({choice.reason})"]
    if math.isfinite(choice.predictor):
        t = choice.tolerance
        e = choice.predicted_error
        out.append(
            f"  validity rule (docs/wave-validity.md): own-path Fresnel number "
            f"{choice.predictor:.2f} (least layer Fresnel number {choice.fresnel_min:.2f}); "
            f"ray error at most {e['light']:.1%} in light, {e['rmtf']:.3f} in RMTF; "
            f"tolerances {t['light']:.1%}, {t['rmtf']:.3f}: ray holds above "
            f"{ray_holds_above(t['light'], t['rmtf']):.2f}"
        )
    return out


def _maps_on_gpu() -> bool:
    """Whether the 2-D path's maps run on a GPU in this run (:mod:`.wave2dmaps`)."""
    from .wave2dmaps import maps_on_gpu

    return maps_on_gpu()
