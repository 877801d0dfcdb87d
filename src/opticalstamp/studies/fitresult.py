"""A fit's result (issue 24): estimates, errors, what was held, the fitted design."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..analysis.responsivity import light_words
from ..design import Design

#: Why a parameter is held at its nominal value (the JSON's and the terminal's words).
HELD = "held at nominal: undetermined from these images"


@dataclass(frozen=True)
class FitResult:
    """A fit's estimates, uncertainties, degeneracies and fitted design.

    ``names``, ``values``, ``errors`` (None: not determined by these images), ``nominal``:
    the free physical parameters (``ref``: offset in um). ``correlation``: theirs.
    ``nuisance``: {image: {name: (value, error)}}. ``starts``: (cost, chi2) of each start.
    ``held``: {name: nominal value} of the parameters the images did not determine, held
    at nominal in ``fitted`` (their reason :data:`HELD`); the rest re-fitted with them held.
    ``held_combinations``: combinations of the free parameters ({name: coefficient}, in
    units of each one's assembly scale) the images did not determine, held at nominal.
    """

    design: Design
    fitted: Design
    names: list[str]
    values: list[float]
    errors: list[float | None]
    nominal: list[float]
    pinned: dict[str, float]
    correlation: np.ndarray
    degeneracies: list[str]
    chi2: float
    dof: int
    error_scale: float
    nuisance: dict
    starts: list[dict]
    theta: np.ndarray = field(repr=False, default=None)
    held: dict[str, float] = field(default_factory=dict)
    held_combinations: list[dict[str, float]] = field(default_factory=list)
    optics: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {
            "design": self.design.name,
            "design_fingerprint": self.design.fingerprint(),
            "fitted_fingerprint": self.fitted.fingerprint(),
            "parameters": {
                n: {"value": v, "error": e, "nominal": m}
                for n, v, e, m in zip(
                    self.names, self.values, self.errors, self.nominal, strict=True
                )
            }
            | {
                n: {"value": v, "error": None, "nominal": v, "held": HELD}
                for n, v in self.held.items()
            },
            "pinned": self.pinned,
            "held": {n: {"value": v, "reason": HELD} for n, v in self.held.items()},
            "held_combinations": [
                {"combination": c, "reason": HELD} for c in self.held_combinations
            ],
            "correlation": {"names": self.names, "matrix": self.correlation.tolist()},
            "degeneracies": self.degeneracies,
            "chi2": self.chi2,
            "dof": self.dof,
            "reduced_chi2": self.chi2 / max(self.dof, 1),
            "error_scale": self.error_scale,
            "nuisance": self.nuisance,
            "starts": self.starts,
            "optics": self.optics | {"warning": fit_optics(self.design, self.optics)},
        }


def fit_optics(design: Design, optics: dict) -> str | None:
    """A warning where the fit's optics (``optics``: :attr:`FitResult.optics`) is not the
    one the other commands pick for this design: a ray-optics fit (the paraxial own path)
    of a design for which ``--optics auto`` takes wave optics
    (:func:`~opticalstamp.analysis.responsivity.resolve_optics`), whose fitted geometry
    absorbs the diffraction blur the model leaves out; or a wave fit whose wave model's
    least squares did not converge. None otherwise."""
    from ..analysis.responsivity import resolve_optics

    if optics.get("engine", "ray") != "ray":
        sc = optics.get("scheme", {})
        if sc and not sc.get("converged"):
            return (
                f"the wave fit did not converge ({sc.get('stopped')}; wave chi2 from "
                f"{' to '.join(f'{c:.1f}' for c in sc.get('wave_chi2', []))}"
                "): the estimates are not the wave model's optimum; a model that cannot "
                "describe the images (free the parameters that differ) is the usual cause"
            )
        return None
    auto = resolve_optics(design, "auto")
    if auto.engine == "wave":
        return (
            "the fit's forward model is ray optics (the paraxial own path), but the other "
            f"commands take wave optics for this design ({auto.reason}): the fitted "
            "parameters absorb the diffraction blur the model leaves out; fit with "
            "--optics wave (or auto) to compare them with the other commands' figures"
        )
    return None


def optics_words(o: dict | None) -> str:
    """A fit's optics in words (its ``optics`` record, fit.json's): which forward model,
    why, and under wave optics how its own least squares converged."""
    o = o or {}
    if o.get("engine", "ray") != "wave":
        why = o.get("reason", "the fit's model before it chose its optics")
        return f"optics: ray, the paraxial own path ({why})"
    sc = o.get("scheme", {})
    state = "converged" if sc.get("converged") else "NOT converged"
    chis = " to ".join(f"{c:.1f}" for c in sc.get("wave_chi2", []))
    return (
        f"optics: wave {light_words(o)}, the wave engine's light in its band "
        f"|s| < {o['band']:.3f} (own path, diffraction, near crosstalk; {o['reason']}); "
        f"the wave model's own least squares from the starts' best minimum, {state} "
        f"({sc.get('stopped')}): wave chi2 {chis} in {sc.get('evaluations')} evaluations, "
        f"{sc.get('wave_runs')} wave runs; errors from the wave model's Jacobian"
    )
