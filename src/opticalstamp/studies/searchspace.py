"""The search's space and constraints (paper §3): the variables of a stack (each
layer's square hole size, each slab's thickness, object side first), their bounds for a
sensor and a thickness budget, and the constraint values NSGA-II keeps at or below zero
(no near ghost, a ghost-fraction bound, the stack budget). The diffraction spill is a
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


def default_space(
    design: Design,
    budget_um: float,
    min_hole_um: float = 10.0,
    min_wall_um: float = 10.0,
    thickness_step_um: float = 50.0,
) -> SearchSpace:
    s = design.sensor
    dx = s.row_b_offset_x_um % s.row_pitch_um if s.rows == 2 else s.row_pitch_um
    dx = min(dx, s.row_pitch_um - dx) if s.rows == 2 else s.row_pitch_um
    hole_max = min(dx, s.row_pitch_um) - min_wall_um
    lo = max(thickness_step_um, 100.0)
    hi = lo + math.floor((min(budget_um, 2000.0) - lo) / thickness_step_um) * thickness_step_um
    bounds = [(lo, hi) for _ in design.slabs]
    return SearchSpace((min_hole_um, float(math.floor(hole_max))), bounds, thickness_step_um)


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
