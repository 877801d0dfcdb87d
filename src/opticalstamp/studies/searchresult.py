"""A search's result and its records: every evaluation as a row of parameters and
figures (:data:`FIGURES`), the Pareto front of the feasible ones, the front merged over
structural variants, and the evaluations as an xarray Dataset."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from ..design import Design


@dataclass(frozen=True)
class SearchResult:
    base: str
    dpi: float
    seed: int
    records: list[dict]  # every evaluation: params, metrics, feasible
    pareto: list[dict]
    reference: dict | None  # the base design's own evaluation
    meta: dict = field(default_factory=dict)
    design: Design | None = field(default=None, repr=False)  # the searched base

    def to_dict(self) -> dict:
        target = self.reference["dof_mm"] if self.reference else None
        deep = [
            r
            for r in self.records
            if r["feasible"] and target is not None and r["dof_mm"] >= target
        ]
        thinnest = min(deep, key=lambda r: (r["stack_um"], -r["efficiency_ratio"]), default=None)
        return {
            "base": self.base,
            "dpi": self.dpi,
            "seed": self.seed,
            "pareto": self.pareto,
            "thinnest_with_base_dof": thinnest,
            "reference": self.reference,
            "n_evaluations": len(self.records),
            "n_feasible": sum(r["feasible"] for r in self.records),
            "n_failed": sum(not r["ok"] for r in self.records),
            "meta": self.meta,
        }


def pareto_front(points: np.ndarray) -> np.ndarray:
    """Indices of the non-dominated rows of ``points`` (maximise every column)."""
    keep = []
    for i, p in enumerate(points):
        dominated = np.any(np.all(points >= p, axis=1) & np.any(points > p, axis=1))
        if not dominated:
            keep.append(i)
    return np.array(keep, dtype=np.int64)


#: The figures of a search record (besides its parameters).
FIGURES = (
    "efficiency_ratio",
    "dof_mm",
    "restored_dof_mm",
    "ghost_fraction",
    "nearest_ghost_mm",
    "diffraction_spill",
    "stack_um",
)
#: the depth objective of a search: the depth of field, or the depth of field after
#: Wiener restoration with the known blur (co-design of optics and computation)
OBJECTIVES = MappingProxyType({"dof": "dof_mm", "restored-dof": "restored_dof_mm"})


def depth_key(res) -> str:
    """The record key of a search's depth objective (``dof_mm`` unless it searched for
    the restored depth of field)."""
    return res.meta.get("objective", "dof_mm")


def record_row(
    params: dict, rec: dict | None, m: dict | None, feasible: bool, n_h: int, n_t: int
) -> dict:
    row = {
        "holes_um": [float(params[f"hole{j + 1}"]) for j in range(n_h)],
        "thicknesses_um": [float(params[f"slab{j + 1}"]) for j in range(n_t)],
        "ok": m is not None,
        "feasible": feasible,
        "error": None if rec is None or rec["ok"] else rec.get("error", "not run"),
    }
    row["rmtf_at"] = None if m is None else dict(m["rmtf_at"])
    row["near_ghost"] = None if m is None else bool(m["near_ghost"])
    # the engine that judged it: "ray" or "wave" (records journalled before: ray)
    row["optics"] = None if m is None else m.get("optics", "ray")
    for k in FIGURES:
        v = None if m is None else m.get(k)
        # JSON (the journal) has no infinity: a missing nearest ghost means none at all
        row[k] = (
            float(v)
            if v is not None
            else (math.inf if m is not None and k == "nearest_ghost_mm" else math.nan)
        )
    return row


def search_dataset(res: SearchResult, design: Design, seed: int):
    """Every evaluation of a search as an xarray Dataset (dims: evaluation, layer, slab)."""
    import xarray as xr

    from .. import __version__

    recs = res.records
    front = {(tuple(r["holes_um"]), tuple(r["thicknesses_um"])) for r in res.pareto}
    key = [(tuple(r["holes_um"]), tuple(r["thicknesses_um"])) for r in recs]
    data = {
        "hole_um": (("evaluation", "layer"), np.array([r["holes_um"] for r in recs])),
        "thickness_um": (("evaluation", "slab"), np.array([r["thicknesses_um"] for r in recs])),
        "feasible": ("evaluation", np.array([r["feasible"] for r in recs], dtype=np.int8)),
        "on_front": ("evaluation", np.array([k in front for k in key], dtype=np.int8)),
    }
    for k in FIGURES:
        v = np.array([r[k] for r in recs], dtype=np.float64)
        data[k] = ("evaluation", np.where(np.isfinite(v), v, np.nan))
    return xr.Dataset(
        data,
        coords={"evaluation": np.arange(len(recs))},
        attrs={
            "kind": "opticalstamp search",
            "design": design.name,
            "design_fingerprint": design.fingerprint(),
            "seed": seed,
            "opticalstamp_version": __version__,
            "dpi": res.dpi,
            "reference": res.reference,
            "meta": res.meta,
            "layer_order": "holes and slabs: object side first (layer 1 faces the document)",
        },
    )


def merged_front(results: dict[str, SearchResult]) -> list[dict]:
    """The Pareto front over several searches, each entry tagged with its variant."""
    rows = [r | {"variant": name} for name, res in results.items() for r in res.pareto]
    if not rows:
        return []
    depth = depth_key(next(iter(results.values())))
    pts = np.array([[r["efficiency_ratio"], r[depth]] for r in rows])
    return sorted((rows[i] for i in pareto_front(pts)), key=lambda r: -r[depth])
