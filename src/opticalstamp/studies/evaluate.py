"""Cheap, complete evaluation of one design for the search and the tolerancing.

- Own-path etendue and RMTF: the paraxial closed form (rectangular holes; 0.05 % above
  the exact etendue for the prototype, docs/metrics.md), with misregistration.
- Ghost light: the exact tracer with importance sampling (``ghost_rays`` rays): ghost
  etendue, and the nearest ghost light on the object plane at each Z (the *near-ghost*
  check of the paper's virtual detector, §3).
- RMTF with ghost light: ghost light arrives from millimetres away, a uniform background
  that adds half its etendue to every pixel of a 50 % bar chart (exact for a far
  background; a test checks RMTF(Z = 0, coarse chart) = 1 - ghost fraction).
- Diffraction: the worst per-layer spill outside the holes' geometric shadows.

Every quantity is a plain float in a dict (JSON-ready), so evaluations can run on any
worker and be journalled; :func:`check_figures` states the rules those figures keep, by
which a study's journal is read back (a record that breaks them is evaluated again).
"""

from __future__ import annotations

import math

import numpy as np

from ..analysis.diffraction import diffraction_budget
from ..analysis.efficiency import reference_etendue
from ..analysis.ghosts import analyse_ghosts
from ..analysis.lsf import FoldedLSF
from ..analysis.paraxial import paraxial_etendue, paraxial_folded_lsf
from ..analysis.rmtf import DEFAULT_Z_MM, depth_of_field, period_of_dpi, rmtf_curves
from ..defaults import WINDOW_UM
from ..design import Design
from ..design.resolution import dof_chart_dpi
from ..raytrace.stack import output_pitch
from ..validate import InputError, check_number

GHOST_Z_MM = (0.0, 1.0, 2.0, 3.0, 4.0)
#: the heights (mm) of an evaluation's ``rmtf_at`` unless its options name others
RMTF_Z_MM = (1.0, 2.0, 3.0)
#: the RMTF curve of an evaluation runs on past ``z_mm`` until it crosses the threshold,
#: up to this height (mm): beyond it the depth of field is reported as open-ended
Z_LIMIT_MM = 20.0
#: how :func:`evaluate_design` estimates, recorded with every figure of merit it makes
SURROGATE = (
    "surrogate: paraxial closed-form own path + uniform ghost background (sampled ghost "
    "etendue), no Fresnel losses"
)


def extended_z(zs: np.ndarray) -> np.ndarray:
    """The Z grid ``zs`` (from 0, even steps) run on to twice its length, at most to
    ``Z_LIMIT_MM``, in the same step: for an RMTF that has not crossed its threshold yet."""
    step = zs[1] - zs[0]
    return np.round(np.arange(0.0, min(Z_LIMIT_MM, 2 * zs[-1]) + step / 2, step), 9)


def rmtf_with_background(
    design: Design,
    dpi: float,
    z_mm,
    ghost_um2sr: float,
    window_um: float = WINDOW_UM,
    shift_step_um: float = 2.0,
) -> np.ndarray:
    """Max-over-shifts RMTF vs Z: paraxial own path plus a uniform ghost background."""
    per = period_of_dpi(dpi)
    lsf = paraxial_folded_lsf(design, z_mm=z_mm, periods_um=[per])
    h = lsf.h[0] + ghost_um2sr / lsf.h[0].shape[-1]  # the background spread over a period
    lsf = FoldedLSF(lsf.z_mm, lsf.periods_um, lsf.rows, [h], "paraxial", 0, True, False)
    return rmtf_curves(lsf, design, window_um=window_um, shift_step_um=shift_step_um)["max"][0]


def diffraction_spill(design: Design, wavelength_um: float | None = None) -> float:
    """The largest share of a layer's diffracted light outside its geometric shadow, at
    ``wavelength_um`` (default: the design's), closed form."""
    if wavelength_um is None:
        wavelength_um = design.wavelength_um
    diff = diffraction_budget(design, wavelengths_um=(wavelength_um,))
    return max(row["outside_shadow"][f"{wavelength_um:g}"] for row in diff["layers"])


def evaluate_design(
    design: Design,
    *,
    dpi: float | None = None,
    z_mm=DEFAULT_Z_MM,
    rmtf_z_mm=RMTF_Z_MM,
    dof_threshold: float = 0.3,
    near_mm: float = 1.0,
    ghost_rays: int = 1 << 17,
    seed: int = 0,
    wavelength_um: float | None = None,
    restored: bool = False,
) -> dict:
    """Efficiency, depth of field, RMTF at chosen Z, ghosts and diffraction of a design;
    with ``restored``, also the depth of field after Wiener restoration with the known
    blur (``restored_dof_mm``, closed form:
    :func:`~opticalstamp.studies.restoration.restored_dof_closed_form`; else None).

    The estimator is the *surrogate* (recorded in the result as ``"estimator"``): the own
    path in paraxial closed form, ghost light as a uniform background from a sampled
    ghost etendue, no Fresnel losses; diffraction at ``wavelength_um`` (default: the
    design's wavelength).
    """
    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    if wavelength_um is None:
        wavelength_um = design.wavelength_um
    zs = np.asarray(z_mm, dtype=np.float64)
    own = paraxial_etendue(design)
    g = analyse_ghosts(design, z_mm=GHOST_Z_MM, n_rays=ghost_rays, seed=seed)
    ghost = g.etendue_ghost_um2sr
    nearest = [v["nearest_um"] for v in g.landing.values() if v["nearest_um"] is not None]
    near = min(nearest) / 1000.0 if nearest else math.inf
    curve = rmtf_with_background(design, dpi, zs, ghost)
    while curve.min() >= dof_threshold and zs[-1] < Z_LIMIT_MM:
        # the depth of field is a crossing, not the end of the range: go on in the same step
        zs = extended_z(zs)
        curve = rmtf_with_background(design, dpi, zs, ghost)
    at = {f"{z:g}": float(np.interp(z, zs, curve)) for z in rmtf_z_mm}
    spill = diffraction_spill(design, wavelength_um)
    tot = own + ghost
    restored_dof = None
    if restored:
        from .restoration import restored_dof_closed_form

        restored_dof = restored_dof_closed_form(
            design, dpi=dpi, ghost_fraction=ghost / tot if tot > 0 else 0.0
        )["dof_mm"]
    return {
        "estimator": SURROGATE,
        "restored_dof_mm": restored_dof,
        "etendue_own_um2sr": own,
        "etendue_ghost_um2sr": ghost,
        "ghost_fraction": ghost / tot if tot > 0 else 0.0,
        # useful light: the own path (ghost light is crosstalk, not signal)
        "efficiency_ratio": own / reference_etendue(output_pitch(design)),
        "efficiency_ratio_total": tot / reference_etendue(output_pitch(design)),
        "dof_mm": depth_of_field(zs, curve, dof_threshold),
        "dof_open_ended": bool(curve.min() >= dof_threshold),
        "rmtf_at": at,
        "nearest_ghost_mm": near,
        "near_ghost": near < near_mm,
        "diffraction_spill": spill,
        "stack_um": float(sum(sl.thickness_um for sl in design.slabs)),
    }


#: figures of every evaluation: light, depth and thickness, finite and >= 0 (stack > 0)
_AMOUNTS = (
    "etendue_own_um2sr",
    "etendue_ghost_um2sr",
    "efficiency_ratio",
    "efficiency_ratio_total",
    "dof_mm",
)
#: how far a fraction may pass 1 by rounding
_ROUNDING = 1e-9


def _figure(res: dict, key: str, lo: float, hi: float | None = None, **kw) -> str | None:
    """Why ``res[key]`` is not a finite number in [lo, hi] (None: it is)."""
    if key not in res:
        return f"{key}: missing"
    try:
        check_number(res[key], key, lo, hi, **kw)
    except InputError as err:
        return str(err)
    return None


def check_figures(payload: dict, result: dict) -> str | None:
    """The rules an evaluation's figures keep, as the journal reads them back.

    ``result`` is what :func:`evaluate_design`, :func:`~opticalstamp.studies.verify.
    evaluate_exact` or (``payload["exact"]``) :func:`~opticalstamp.studies.verify.
    exact_figures` returns, after JSON (infinities and NaN written as null). The rules:
    etendues, efficiency ratios and the depth of field are finite numbers >= 0, the stack
    > 0; the ghost fraction and each RMTF in [0, 1], with an RMTF at every height of
    ``payload["options"]["rmtf_z_mm"]`` (default :data:`RMTF_Z_MM`); the nearest ghost
    light >= 0 or null (none lands); ``near_ghost`` and ``dof_open_ended`` true or false;
    an evaluation's (not ``exact``) diffraction spill >= 0 and its restored depth of
    field null or >= 0, a number where the options asked for it (``restored``);
    ``rmtf_se_max`` >= 0 where present. Booleans are not numbers.

    Returns
    -------
    str or None
        None where every rule holds, else the first rule broken, naming the figure and
        the value (``"dof_mm: must be >= 0 (got -1.0)"``).
    """
    if not isinstance(result, dict):
        return f"the result is not a JSON object (got {type(result).__name__})"
    opts = payload.get("options") if isinstance(payload, dict) else None
    opts = opts if isinstance(opts, dict) else {}
    for key in _AMOUNTS:
        why = _figure(result, key, 0.0)
        if why:
            return why
    why = _figure(result, "stack_um", 0.0, lo_open=True) or _figure(
        result, "ghost_fraction", 0.0, 1.0 + _ROUNDING
    )
    if why:
        return why
    for key in ("near_ghost", "dof_open_ended"):
        if type(result.get(key)) is not bool:
            return f"{key}: must be true or false (got {result.get(key, 'nothing')!r})"
    if "nearest_ghost_mm" not in result:
        return "nearest_ghost_mm: missing"
    if result["nearest_ghost_mm"] is not None:  # null: no ghost light lands (infinity)
        why = _figure(result, "nearest_ghost_mm", 0.0)
        if why and result["nearest_ghost_mm"] != math.inf:
            return why
    rm = result.get("rmtf_at")
    if not isinstance(rm, dict):
        return f"rmtf_at: must be an object of RMTF by height (got {rm!r})"
    heights = opts.get("rmtf_z_mm", RMTF_Z_MM)
    try:
        wanted = [f"{float(z):g}" for z in heights]
    except (TypeError, ValueError):
        return f"options.rmtf_z_mm: must be a list of heights (got {heights!r})"
    for z in wanted:
        if z not in rm:
            return f"rmtf_at: no RMTF at Z = {z} mm"
    for z in rm:
        why = _figure(rm, z, 0.0, 1.0 + _ROUNDING)
        if why:
            return f"rmtf_at.{why}"
    if "rmtf_se_max" in result:
        why = _figure(result, "rmtf_se_max", 0.0)
        if why:
            return why
    if isinstance(payload, dict) and payload.get("exact") is True:
        # the exact tracer's figures (verify_front): no spill, no restoration
        return None
    why = _figure(result, "diffraction_spill", 0.0)
    if why:
        return why
    if "restored_dof_mm" not in result:
        return "restored_dof_mm: missing"
    if result["restored_dof_mm"] is not None or opts.get("restored"):
        return _figure(result, "restored_dof_mm", 0.0)
    return None
