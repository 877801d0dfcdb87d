"""The exact tracer's figures of a design, to re-verify what the surrogate ranked.

The search and the tolerancing rank designs with the surrogate of :mod:`.evaluate`
(paraxial own path, ghost light as a uniform background). Here the same figures come from
the exact tracer: own and ghost etendue by importance sampling, the RMTF traced with the
ghost light where it lands, the depth of field at the first crossing. The exact figure is
the figure of record; a surrogate figure that differs from it by more than the surrogate's
measured accuracy (``SURROGATE_ACCURACY``) is flagged.

``SURROGATE_ACCURACY`` is measured by ``benchmarks/surrogate_accuracy.py`` on random
feasible designs (docs/search.md): the 95th percentile of |surrogate - exact|.
"""

from __future__ import annotations

import math
from types import MappingProxyType

import numpy as np

from ..analysis.efficiency import reference_etendue
from ..analysis.ghosts import analyse_ghosts
from ..analysis.rmtf import DEFAULT_Z_MM, rmtf
from ..design import Design
from ..design.resolution import dof_chart_dpi
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import output_pitch
from ..validate import InputError
from .evaluate import GHOST_Z_MM, SURROGATE, Z_LIMIT_MM, evaluate_design, extended_z

#: how :func:`exact_figures` estimates, recorded with every figure it makes
EXACT = (
    "exact tracer: traced own and ghost etendue (importance sampling), traced RMTF with the "
    "ghost light where it lands, no Fresnel losses"
)
#: Rays of the exact figures: the ghost analysis and each pixel row's folded LSF.
EXACT_GHOST_RAYS = 1 << 20
EXACT_LSF_RAYS = 1 << 19
#: How far the surrogate may be from the exact tracer: the 95th percentile of |surrogate -
#: exact| over 40 random feasible designs of the prototype's 300-dpi search space (seed 0;
#: benchmarks/surrogate_accuracy.py, docs/search.md), in two regimes of the exact ghost
#: fraction, below and from ``GHOST_REGIME`` (where ghost light lands 1-3 mm away the
#: uniform background of the surrogate misjudges the contrast): depth of field in mm,
#: RMTF and ghost fraction in absolute units, the light as a relative error.
GHOST_REGIME = 0.2
SURROGATE_ACCURACY = MappingProxyType(
    {
        "dof_mm": 0.35,
        "rmtf": 0.07,
        "dof_mm_high_ghost": 2.05,
        "rmtf_high_ghost": 0.30,
        "efficiency_ratio": 0.015,
        "ghost_fraction": 0.022,
    }
)


def exact_figures(
    design: Design,
    *,
    dpi: float | None = None,
    z_mm=DEFAULT_Z_MM,
    rmtf_z_mm=(1.0, 2.0, 3.0),
    dof_threshold: float = 0.3,
    near_mm: float = 1.0,
    ghost_rays: int = EXACT_GHOST_RAYS,
    lsf_rays: int = EXACT_LSF_RAYS,
    seed: int = 0,
) -> dict:
    """The figures of :func:`~opticalstamp.studies.evaluate.evaluate_design` from the exact
    tracer (``"estimator"``: ``EXACT``); the diffraction spill, a closed form, is not
    estimated and is left out.

    The RMTF runs over ``z_mm`` and on, in the grid's step, until it falls below the
    threshold or reaches 20 mm, so the depth of field is a crossing, not the end of the
    range (``dof_open_ended`` says when it is).
    """
    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    tracer = PixelTracer(design, replay=True)
    g = analyse_ghosts(design, z_mm=GHOST_Z_MM, n_rays=ghost_rays, seed=seed, tracer=tracer)
    zs = np.asarray(z_mm, dtype=np.float64)
    key = f"{dpi:g}"
    while True:
        r = rmtf(
            design,
            dpi=(dpi,),
            z_mm=zs,
            n_rays=lsf_rays,
            seed=seed,
            dof_dpi=dpi,
            dof_threshold=dof_threshold,
            tracer=tracer,
        )
        curve = np.asarray(r.rmtf_max[key])
        if curve.min() < dof_threshold or zs[-1] >= Z_LIMIT_MM:
            break
        zs = extended_z(zs)
    nearest = [v["nearest_um"] for v in g.landing.values() if v["nearest_um"] is not None]
    near = min(nearest) / 1000.0 if nearest else math.inf
    own, ghost = g.etendue_own_um2sr, g.etendue_ghost_um2sr
    ref = reference_etendue(output_pitch(design))
    return {
        "estimator": EXACT,
        "etendue_own_um2sr": own,
        "etendue_ghost_um2sr": ghost,
        "ghost_fraction": g.ghost_fraction,
        "efficiency_ratio": own / ref,
        "efficiency_ratio_total": (own + ghost) / ref,
        "dof_mm": r.dof_mm[key],  # the crossing on a finer step (rmtf's refinement)
        "dof_open_ended": bool(curve.min() >= dof_threshold),
        "rmtf_at": {f"{z:g}": float(np.interp(z, zs, curve)) for z in rmtf_z_mm},
        "rmtf_se_max": float(max(r.rmtf_max_se[key])),
        "nearest_ghost_mm": near,
        "near_ghost": near < near_mm,
        "stack_um": float(sum(sl.thickness_um for sl in design.slabs)),
    }


def evaluate_exact(
    design: Design,
    *,
    dpi: float | None = None,
    rmtf_z_mm=(1.0, 2.0, 3.0),
    near_mm: float = 1.0,
    seed: int = 0,
    restored: bool = False,
    ghost_rays: int = EXACT_GHOST_RAYS,
    lsf_rays: int = EXACT_LSF_RAYS,
    wavelength_um: float | None = None,
) -> dict:
    """Every figure of :func:`~opticalstamp.studies.evaluate.evaluate_design` with the
    exact tracer in place of the surrogate (the estimator of ``search --estimator trace``
    and ``tolerance --estimator trace``): ghosts, light, RMTF and depth of field traced
    (:func:`exact_figures`), the diffraction spill in closed form, and with ``restored``
    the restored depth of field in closed form at the traced ghost fraction."""
    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    from .evaluate import diffraction_spill

    out = exact_figures(
        design,
        dpi=dpi,
        rmtf_z_mm=rmtf_z_mm,
        near_mm=near_mm,
        ghost_rays=ghost_rays,
        lsf_rays=lsf_rays,
        seed=seed,
    )
    out["diffraction_spill"] = diffraction_spill(design, wavelength_um)
    out["restored_dof_mm"] = None
    if restored:
        from .restoration import restored_dof_closed_form

        out["restored_dof_mm"] = restored_dof_closed_form(
            design, dpi=dpi, ghost_fraction=out["ghost_fraction"]
        )["dof_mm"]
    return out


#: how a search or a tolerance study evaluates each design: name -> what it is
ESTIMATORS = MappingProxyType({"surrogate": SURROGATE, "trace": EXACT})


def check_estimator(name: str) -> str:
    """``name`` if it is one of :data:`ESTIMATORS`; else InputError naming the field."""
    if name not in ESTIMATORS:
        raise InputError(f"estimator: must be one of {', '.join(ESTIMATORS)} (got {name!r})")
    return name


def evaluate_with(design: Design, options: dict) -> dict:
    """A design's figures by the estimator ``options["estimator"]`` (default surrogate)
    and the optics ``options["optics"]`` (default "ray"): with ray optics
    :func:`~opticalstamp.studies.evaluate.evaluate_design`, or :func:`evaluate_exact` for
    "trace" (with its own ray counts: the surrogate's ``ghost_rays`` is dropped); where
    ``optics`` is "wave", or "auto" and the validity rule picks wave optics for this
    design (:func:`~opticalstamp.analysis.responsivity.resolve_optics`), the wave
    estimator (:func:`~opticalstamp.studies.waveestimate.evaluate_wave`) or, for "trace",
    the exact wave figures (:func:`~opticalstamp.studies.waveestimate.exact_wave_figures`,
    with the diffraction spill and the restored depth of field beside them). The result's
    ``"optics"`` names the engine that gave it; the other options go to the evaluation."""
    opts = dict(options)
    trace = check_estimator(opts.pop("estimator", "surrogate")) == "trace"
    optics = opts.pop("optics", "ray")
    if optics != "ray":
        from ..analysis.responsivity import resolve_optics

        if resolve_optics(design, optics).engine == "wave":
            return _wave_figures(design, opts, trace)
    if trace:
        opts.pop("ghost_rays", None)
        return evaluate_exact(design, **opts) | {"optics": "ray"}
    return evaluate_design(design, **opts) | {"optics": "ray"}


def _wave_figures(design: Design, opts: dict, trace: bool) -> dict:
    """:func:`evaluate_with` by wave optics."""
    from .evaluate import diffraction_spill
    from .waveestimate import evaluate_wave, exact_wave_figures

    if not trace:
        return evaluate_wave(design, **opts)
    restored = opts.pop("restored", False)
    wavelength = opts.pop("wavelength_um", None)
    opts.pop("ghost_rays", None)
    out = exact_wave_figures(design, **opts)
    out["diffraction_spill"] = diffraction_spill(design, wavelength)
    out["restored_dof_mm"] = None
    if restored:
        from .restoration import restored_dof_closed_form

        out["restored_dof_mm"] = restored_dof_closed_form(
            design, dpi=opts.get("dpi", 200.0), ghost_fraction=out["ghost_fraction"]
        )["dof_mm"]
    return out


def disagreements(surrogate: dict, exact: dict, accuracy=SURROGATE_ACCURACY) -> list[str]:
    """The figures where the surrogate is further from the exact tracer than its stated
    accuracy (``SURROGATE_ACCURACY``, in the regime of the exact ghost fraction): "dof_mm",
    "efficiency_ratio", "ghost_fraction", "rmtf@Z"; and "near_ghost"
    where the exact tracer finds ghost light near the pixel that the surrogate's fewer
    rays missed (the design breaks the search's near-ghost constraint)."""
    out = []
    if exact.get("near_ghost") and not surrogate.get("near_ghost", False):
        out.append("near_ghost")
    high = "_high_ghost" if exact["ghost_fraction"] >= GHOST_REGIME else ""
    if abs(surrogate["dof_mm"] - exact["dof_mm"]) > accuracy["dof_mm" + high]:
        out.append("dof_mm")
    e_s, e_x = surrogate["efficiency_ratio"], exact["efficiency_ratio"]
    if e_x > 0:
        rel = abs(e_s / e_x - 1)
    else:  # the exact tracer found no own-path light: any the surrogate gives is off
        rel = 0.0 if e_s == 0 else math.inf
    if rel > accuracy["efficiency_ratio"]:
        out.append("efficiency_ratio")
    if abs(surrogate["ghost_fraction"] - exact["ghost_fraction"]) > accuracy["ghost_fraction"]:
        out.append("ghost_fraction")
    for z, v in surrogate.get("rmtf_at", {}).items():
        if z in exact["rmtf_at"] and abs(v - exact["rmtf_at"][z]) > accuracy["rmtf" + high]:
            out.append(f"rmtf@{z}")
    return out
