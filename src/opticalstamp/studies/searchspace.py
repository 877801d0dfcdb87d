"""The search's space and constraints (paper §3): the variables of a stack (each
layer's square hole size, each slab's thickness, object side first), their bounds for a
sensor and a thickness budget, and the constraint values NSGA-II keeps at or below zero
(no near ghost, a ghost-fraction bound, the stack budget, the diffraction spill)."""

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


CONSTRAINTS = ("near_ghost", "ghost_fraction", "stack_budget", "diffraction_spill")


def constraint_values(m: dict, budget_um: float, max_ghost: float | None, max_spill: float) -> list:
    """Constraint values (<= 0 feasible) for NSGA-II."""
    return [
        1.0 if m["near_ghost"] else 0.0,
        (m["ghost_fraction"] - max_ghost) if max_ghost is not None else 0.0,
        (m["stack_um"] - budget_um) / 1000.0,
        m["diffraction_spill"] - max_spill,
    ]
