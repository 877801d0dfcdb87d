"""The search's space and constraints (paper §3): the variables of a stack (each
layer's square hole size, each slab's thickness, object side first), their bounds for a
sensor and a thickness budget (the paper's 300-dpi space scaled to the design's
resolution, spanning its geometric and its Fresnel image: :func:`scaled_slab_bounds`),
and the constraint values NSGA-II keeps at or below zero (no near ghost, a
ghost-fraction bound, the stack budget). The diffraction spill is a
reported figure, not a constraint: where diffraction matters the candidates are judged by
wave optics (:mod:`.waveestimate`), which counts it."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..design import Design


@dataclass(frozen=True)
class SearchSpace:
    hole_bounds_um: tuple[float, float]
    thickness_bounds_um: list[tuple[float, float]]
    thickness_step_um: float
    pinned: dict = field(default_factory=dict)  # "hole1".., "slab1".. -> value

    def names(self, n_holes: int, n_slabs: int) -> list[str]:
        """The variables: ``hole1``.. (layer 1 = object side) and ``slab1``.. (slab 1 = the
        object side's), object side first as every list of the stack."""
        return [f"hole{i + 1}" for i in range(n_holes)] + [f"slab{i + 1}" for i in range(n_slabs)]


#: The paper's search space (section 3) at its 300-dpi line, from which the space at
#: any resolution is scaled (:func:`default_space`): slabs from ``REF_SLAB_MIN_UM`` to
#: ``REF_SLAB_MAX_UM`` (or the budget) in ``REF_SLAB_STEP_UM`` steps, holes from
#: ``REF_MIN_HOLE_UM`` leaving ``REF_MIN_WALL_UM`` of mask between the staggered rows.
REF_SLAB_MIN_UM = 100.0
REF_SLAB_MAX_UM = 2000.0
REF_SLAB_STEP_UM = 50.0
REF_MIN_HOLE_UM = 10.0
REF_MIN_WALL_UM = 10.0


def lateral_scale(design: Design) -> float:
    """k: the design's output pitch over the paper's 300-dpi line's, by the resolutions as
    named (:func:`~opticalstamp.design.resolution.nominal_dpi`: 1 for the prototype, 1/2
    at 600 dpi, 1/4 at 1200)."""
    from ..design.resolution import PAPER_LINE_DPI, nominal_dpi

    return PAPER_LINE_DPI / nominal_dpi(design)


def scaled_slab_bounds(k: float) -> tuple[float, float, float]:
    """(thinnest, thickest, step) of a slab at lateral scale ``k`` (um): the paper's
    300-dpi range carried by both similarities of the stack and spanning them.

    With every lateral length scaled by k (pitch, holes, walls), a slab scaled by k keeps
    its aspect ratios (geometric similarity: the ray optics as at 300 dpi), one scaled by
    k^2 keeps its Fresnel numbers a^2 / (lambda d) (paraxial Fresnel similarity: the
    diffraction as at 300 dpi). The range runs from the thinner image of the paper's
    thinnest slab to the thicker image of its thickest: [min(k, k^2) 100, max(k, k^2)
    2000] um. At higher resolution (k < 1) no slab is thinner, in Fresnel number, than
    the paper's space allows (F <= its largest), nor thicker in aspect ratio (d / a <= its
    largest); at k = 1 it is the paper's range. The step is the paper's 50 um times
    min(k, k^2), so the thin end is resolved as finely as at 300 dpi."""
    if not (k > 0 and math.isfinite(k)):
        raise ValueError(f"k: the lateral scale must be > 0 (got {k})")
    lo_k, hi_k = min(k, k * k), max(k, k * k)
    return REF_SLAB_MIN_UM * lo_k, REF_SLAB_MAX_UM * hi_k, REF_SLAB_STEP_UM * lo_k


def default_space(
    design: Design,
    budget_um: float,
    min_hole_um: float | None = None,
    min_wall_um: float | None = None,
    thickness_step_um: float | None = None,
) -> SearchSpace:
    """The search space of ``design``'s stack: the paper's 300-dpi space scaled to the
    design's resolution (:func:`lateral_scale` k). Holes: 1 um steps from k times 10 um
    to the largest that leaves k times 10 um of mask between the staggered rows (or
    ``min_hole_um``, ``min_wall_um``). Slabs: :func:`scaled_slab_bounds` (step
    ``thickness_step_um`` where given), the thickest at most the budget. At 300 dpi it
    is the paper's space: 10 um to pitch - 10 um holes, 100-2000 um slabs in 50 um."""
    k = lateral_scale(design)
    lo, hi_free, step = scaled_slab_bounds(k)
    step = step if thickness_step_um is None else float(thickness_step_um)
    min_hole = REF_MIN_HOLE_UM * k if min_hole_um is None else float(min_hole_um)
    min_wall = REF_MIN_WALL_UM * k if min_wall_um is None else float(min_wall_um)
    s = design.sensor
    dx = s.row_b_offset_x_um % s.row_pitch_um if s.rows == 2 else s.row_pitch_um
    dx = min(dx, s.row_pitch_um - dx) if s.rows == 2 else s.row_pitch_um
    hole_max = min(dx, s.row_pitch_um) - min_wall
    lo = max(step, lo)
    hi = lo + math.floor((min(budget_um, hi_free) - lo) / step + 1e-9) * step
    bounds = [(lo, hi) for _ in design.slabs]
    hole_lo = float(max(1, math.ceil(min_hole - 1e-9)))
    return SearchSpace((hole_lo, float(math.floor(hole_max))), bounds, step)


def on_grid(dist, value: float):
    """``value`` at the nearest point of an optuna distribution (int or stepped float)."""
    lo, hi = dist.low, dist.high
    step = getattr(dist, "step", None) or 1
    v = min(max(value, lo), hi)
    v = lo + round((v - lo) / step) * step
    return int(round(v)) if isinstance(lo, int) else float(v)


CONSTRAINTS = ("near_ghost", "ghost_fraction", "stack_budget")


def constraint_values(m: dict, budget_um: float, max_ghost: float | None) -> list:
    """Constraint values (<= 0 feasible) for NSGA-II, in the order of :data:`CONSTRAINTS`."""
    return [
        1.0 if m["near_ghost"] else 0.0,
        (m["ghost_fraction"] - max_ghost) if max_ghost is not None else 0.0,
        (m["stack_um"] - budget_um) / 1000.0,
    ]


def rejections(records: list[dict], budget_um: float, max_ghost: float | None) -> dict:
    """How many evaluated designs each constraint rejected (a design can break several),
    and how many could not be evaluated (``failed``): {name: count} over
    :data:`CONSTRAINTS` and "failed"."""
    out = dict.fromkeys(CONSTRAINTS, 0) | {"failed": 0}
    for r in records:
        if not r["ok"]:
            out["failed"] += 1
            continue
        m = {
            "near_ghost": r["near_ghost"],
            "ghost_fraction": r["ghost_fraction"],
            "stack_um": r["stack_um"],
        }
        for name, c in zip(CONSTRAINTS, constraint_values(m, budget_um, max_ghost), strict=True):
            out[name] += c > 0
    return out


def rejection_text(
    counts: dict, n: int, *, near_mm: float, budget_mm: float, max_ghost: float | None
) -> str:
    """Why no design met every constraint: each constraint that rejected any of the ``n``
    evaluated designs with its count (from :func:`rejections`; a design can break
    several), the options that relax them, and the evaluations that failed."""
    what = {
        "near_ghost": f"ghost light within --near-mm {near_mm:g} of the pixel",
        "ghost_fraction": f"ghost fraction over --max-ghost {max_ghost:g}"
        if max_ghost is not None
        else "ghost fraction",
        "stack_budget": f"stack over --budget-mm {budget_mm:g}",
    }
    parts = [f"{what[k]}: {counts.get(k, 0)}" for k in CONSTRAINTS if counts.get(k, 0)]
    if counts.get("failed"):
        parts.append(f"evaluation failed: {counts['failed']}")
    bound = "; ".join(parts) if parts else "none rejected by a constraint"
    return (
        f"no design met every constraint: of {n} evaluated, rejected by {bound} "
        "(a design can break several); relax a constraint or a --pin"
    )
