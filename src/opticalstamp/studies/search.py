"""Design search (paper §3): hole sizes and slab thicknesses of a stack for a sensor and a
target resolution, maximising light efficiency and depth of field, with no near ghosts.

Variables: the square hole size of each layer (1 um steps between ``min_hole_um`` and the
largest that leaves ``min_wall_um`` of mask between the staggered rows) and each slab's
thickness (``thickness_step_um`` steps; glass plates and air gaps between ``bounds``);
any of them can be pinned. Constraints: no ghost light within ``near_mm`` of the pixel's
axis at Z = 0 ... 4 mm (the paper's virtual detector), optionally a ghost-fraction bound,
a total stack-thickness budget, and a diffraction spill below ``max_spill``. Objectives:
light efficiency (ratio to the paper's reference lens) and depth of field on the chart at
``dof_dpi`` (default 2/3 of the design's resolution: 200 dpi for 300, 400 for 600).

The optimiser is Optuna's NSGA-II (multi-objective, constraint-aware), seeded, driven by
batches of ``population`` designs that are evaluated in parallel (:mod:`execute`); the
result is the Pareto front of the feasible designs. Seeds belong to the evaluations, so
the front is the same for any number of workers.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ..defaults import SEARCH_BUDGET_MM, SEARCH_GENERATIONS, SEARCH_NEAR_MM, SEARCH_POPULATION
from ..design import (
    Design,
    design_from_dict,
    replace,
    scale_to_dpi,
    stack_params,
    structural_variants,
    with_stack,
)
from ..design.resolution import dof_chart_dpi, nominal_dpi
from ..device import run_device, using_device
from ..io.journal import journal_lock
from ..raytrace.stack import output_pitch
from ..units import pitch_of_dpi
from ..validate import InputError, check_number, check_seed
from .evaluate import SURROGATE, check_figures
from .runner import run_tasks, task_key
from .verify import (
    ESTIMATORS,
    EXACT,
    EXACT_GHOST_RAYS,
    EXACT_LSF_RAYS,
    SURROGATE_ACCURACY,
    check_estimator,
    disagreements,
    evaluate_with,
    exact_figures,
)

#: a base whose output pitch is within this of 25.4 mm / dpi is searched as it is
SAME_RESOLUTION = 0.01


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


def _on_grid(dist, value: float):
    """``value`` at the nearest point of an optuna distribution (int or stepped float)."""
    lo, hi = dist.low, dist.high
    step = getattr(dist, "step", None) or 1
    v = min(max(value, lo), hi)
    v = lo + round((v - lo) / step) * step
    return int(round(v)) if isinstance(lo, int) else float(v)


def _evaluate_payload(payload: dict) -> dict:
    """Worker entry: build the candidate from plain data and evaluate it with the
    payload's estimator (:func:`~opticalstamp.studies.verify.evaluate_with`), its rays on
    the payload's device."""
    base = design_from_dict(payload["base"], "search base")
    d = with_stack(base, holes_um=payload["holes_um"], thicknesses_um=payload["thicknesses_um"])
    with using_device(payload.get("device", "cpu")):
        return evaluate_with(d, payload["options"])


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


CONSTRAINTS = ("near_ghost", "ghost_fraction", "stack_budget", "diffraction_spill")


def _feasible(m: dict, budget_um: float, max_ghost: float | None, max_spill: float) -> list:
    """Constraint values (<= 0 feasible) for NSGA-II."""
    return [
        1.0 if m["near_ghost"] else 0.0,
        (m["ghost_fraction"] - max_ghost) if max_ghost is not None else 0.0,
        (m["stack_um"] - budget_um) / 1000.0,
        m["diffraction_spill"] - max_spill,
    ]


def _optuna_warnings_only(fn):
    """Run ``fn`` with optuna's logging at WARNING (its INFO line per trial is noise) and
    restore the caller's level afterwards: no process-wide setting is left changed."""

    @functools.wraps(fn)
    def run(*args, **kwargs):
        import optuna

        old = optuna.logging.get_verbosity()
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        try:
            return fn(*args, **kwargs)
        finally:
            optuna.logging.set_verbosity(old)

    return run


@_optuna_warnings_only
def search(
    design: Design,
    *,
    dpi: float | None = None,
    dof_dpi: float | None = None,
    budget_mm: float = SEARCH_BUDGET_MM,
    near_mm: float = SEARCH_NEAR_MM,
    max_ghost: float | None = None,
    max_spill: float = 0.25,
    population: int = SEARCH_POPULATION,
    generations: int = SEARCH_GENERATIONS,
    seed: int = 0,
    pinned: dict | None = None,
    space: SearchSpace | None = None,
    ghost_rays: int = 1 << 17,
    warm_start: bool = True,
    workers: int | None = None,
    dask_address: str | None = None,
    journal=None,
    progress: bool = False,
    objective: str = "dof",
    estimator: str = "surrogate",
    device: str | None = None,
) -> SearchResult:
    """NSGA-II search of hole sizes and thicknesses; returns every evaluation and the front.

    ``objective``: the depth maximised with the light, "dof" (the depth of field) or
    "restored-dof" (the depth of field after Wiener restoration with the known blur,
    closed form: designs whose transfer function keeps the chart's frequency alive).
    ``estimator``: "surrogate" (closed form with a uniform ghost background, fast) or
    "trace" (every candidate's ghosts, light, RMTF and depth of field from the exact
    tracer, :func:`~opticalstamp.studies.verify.evaluate_exact`; about 0.3 s a design on
    the CPU, on the GPU with ``--device cuda``).
    ``device``: where the evaluations trace their rays
    (:func:`~opticalstamp.device.run_device`, resolved once here; None: the device of the
    run in progress), handed to the workers in each task's payload.

    ``design`` gives the sensor, the glass, the number and order of slabs and masks and
    the reference gap (scale it to another resolution with
    :func:`~opticalstamp.design.variants.scale_to_dpi`).
    ``pinned``: {"hole1": 48, "slab1": 1000, ...} fixes variables (layers and slabs
    numbered from the object side, :meth:`SearchSpace.names`).
    """
    check_seed(seed)
    import optuna

    dpi = nominal_dpi(design) if dpi is None else float(dpi)
    dof_dpi = dof_chart_dpi(design) if dof_dpi is None else float(dof_dpi)

    if any(m.shape == "circle" for m in design.masks):
        raise ValueError("search: the closed-form evaluation needs square holes")
    budget_um = budget_mm * 1000.0
    sp = space or default_space(design, budget_um)
    pins = dict(pinned or {})
    n_h, n_t = len(design.masks), len(design.slabs)
    names = sp.names(n_h, n_t)
    unknown = set(pins) - set(names)
    if unknown:
        raise InputError(f"pinned: unknown variables {sorted(unknown)} (use {names})")
    for name, value in pins.items():
        j = int(name[4:]) - 1
        lo, hi = sp.hole_bounds_um if name.startswith("hole") else sp.thickness_bounds_um[j]
        check_number(value, f"pinned {name} (--pin {name}=...)", lo, hi)
    t_pins = {k: v for k, v in pins.items() if k.startswith("slab")}
    least = sum(t_pins.get(f"slab{j + 1}", sp.thickness_bounds_um[j][0]) for j in range(n_t))
    if t_pins and least > budget_um:
        raise InputError(
            f"pinned {', '.join(f'{k}={v:g}' for k, v in t_pins.items())}: the thinnest stack "
            f"with these pins is {least:g} um, over the budget of {budget_um:g} um "
            "(--budget-mm): every design would be infeasible"
        )
    if objective not in OBJECTIVES:
        raise InputError(f"objective: must be one of {', '.join(OBJECTIVES)} (got {objective!r})")
    depth = OBJECTIVES[objective]
    check_estimator(estimator)
    options = {"dpi": dof_dpi, "near_mm": near_mm, "ghost_rays": ghost_rays}
    if estimator == "trace":
        options["estimator"] = "trace"
    if depth != "dof_mm":
        options["restored"] = True
    base_json = design.model_dump(mode="json", exclude_none=True)
    where = run_device(device)

    def payload(params: dict) -> dict:
        holes = [float(params[f"hole{j + 1}"]) for j in range(n_h)]
        ts = [float(params[f"slab{j + 1}"]) for j in range(n_t)]
        return {
            "base": base_json,
            "holes_um": holes,
            "thicknesses_um": ts,
            "options": options | {"seed": seed},
            "device": where,
        }

    sampler = optuna.samplers.NSGAIISampler(population_size=population, seed=seed)
    study = optuna.create_study(directions=["maximize", "maximize"], sampler=sampler)
    dists = {}
    for j in range(n_h):
        lo, hi = sp.hole_bounds_um
        dists[f"hole{j + 1}"] = optuna.distributions.IntDistribution(int(lo), int(hi))
    for j in range(n_t):
        lo, hi = sp.thickness_bounds_um[j]
        dists[f"slab{j + 1}"] = optuna.distributions.FloatDistribution(
            lo, hi, step=sp.thickness_step_um
        )
    records = []
    p0 = stack_params(design)
    base_params = {f"hole{j + 1}": v for j, v in enumerate(p0["holes_um"])}
    base_params |= {f"slab{j + 1}": v for j, v in enumerate(p0["thicknesses_um"])}
    if warm_start:  # the base design joins the first generation (NSGA-II breeds from it),
        # at its nearest point of the search's grid (a base off the grid, a half-scale
        # 225-um gap on the 50-um steps, is evaluated exactly for reference below)
        start = {k: _on_grid(dists[k], v) for k, v in base_params.items() if k not in pins}
        study.enqueue_trial(start, skip_if_exists=True)
    with journal_lock(journal):  # one lock for every generation of this run
        # the base design itself, for reference on the front
        ref_payload = payload(base_params)
        ref_key = task_key(ref_payload)
        ref_rec = run_tasks(
            _evaluate_payload,
            [(ref_key, ref_payload)],
            workers=1,
            journal=journal,
            lock=False,
            check=check_figures,
        )[ref_key]
        for gen in range(generations):
            trials = []
            tasks = []
            for _ in range(population):
                t = study.ask({k: v for k, v in dists.items() if k not in pins})
                params = t.params | pins
                p = payload(params)
                trials.append((t, params, task_key(p)))
                tasks.append((task_key(p), p))
            recs = run_tasks(
                _evaluate_payload,
                tasks,
                workers=workers,
                dask_address=dask_address,
                journal=journal,
                progress=progress,
                desc=f"generation {gen + 1}/{generations}",
                lock=False,
                check=check_figures,
            )
            for t, params, key in trials:
                rec = recs.get(key)
                if rec is None or not rec["ok"]:
                    study.tell(t, state=optuna.trial.TrialState.FAIL)
                    records.append(_row(params, rec, None, False, n_h, n_t))
                    continue
                m = rec["result"]
                cons = _feasible(m, budget_um, max_ghost, max_spill)
                for name, c in zip(CONSTRAINTS, cons, strict=True):
                    t.set_constraint(name, c)  # <= 0: satisfied (NSGA-II's constrained domination)
                study.tell(t, [m["efficiency_ratio"], m[depth]])
                records.append(_row(params, rec, m, all(c <= 0 for c in cons), n_h, n_t))
    ok = [r for r in records if r["feasible"]]
    # one entry per distinct design on the front
    uniq = {}
    for r in ok:
        uniq.setdefault((tuple(r["holes_um"]), tuple(r["thicknesses_um"])), r)
    ok = list(uniq.values())
    front = []
    if ok:
        pts = np.array([[r["efficiency_ratio"], r[depth]] for r in ok])
        front = sorted((ok[i] for i in pareto_front(pts)), key=lambda r: -r[depth])
    reference = None
    if ref_rec["ok"]:
        m = ref_rec["result"]
        reference = _row(
            base_params,
            ref_rec,
            m,
            all(c <= 0 for c in _feasible(m, budget_um, max_ghost, max_spill)),
            n_h,
            n_t,
        )
        if ok:
            pts = np.array([[r["efficiency_ratio"], r[depth]] for r in ok])
            p = np.array([reference["efficiency_ratio"], reference[depth]])
            dom = np.all(pts >= p, axis=1) & np.any(pts > p, axis=1)
            reference["dominated_by"] = int(dom.sum())
    return SearchResult(
        design=design,
        base=design.name,
        dpi=dpi,
        seed=seed,
        records=records,
        pareto=front,
        reference=reference,
        meta={
            "estimator": ESTIMATORS[estimator],
            "objective": depth,
            "dof_dpi": dof_dpi,
            "budget_mm": budget_mm,
            "near_mm": near_mm,
            "max_ghost": max_ghost,
            "max_spill": max_spill,
            "population": population,
            "generations": generations,
            "pinned": pins,
            "ghost_rays": ghost_rays,
            "hole_bounds_um": list(sp.hole_bounds_um),
            "thickness_bounds_um": [list(b) for b in sp.thickness_bounds_um],
        },
    )


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


def _row(
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


def search_base(design: Design, dpi: float | None = None) -> Design:
    """The design to search at ``dpi``: itself when ``dpi`` is None (its own resolution)
    or its output pitch is within SAME_RESOLUTION of 25.4 mm / dpi (300 dpi is 84.67 um;
    the paper's sensor gives 84.6 um), else the design scaled to that resolution
    (:func:`~opticalstamp.design.scale_to_dpi`: only when asked)."""
    if dpi is None or abs(pitch_of_dpi(dpi) / output_pitch(design) - 1) < SAME_RESOLUTION:
        return design
    return scale_to_dpi(design, dpi)


def variant_path(path: Path | None, index: int, n_variants: int) -> Path | None:
    """Where variant ``index`` of ``n_variants`` keeps its results: ``path`` itself for a
    single search, ``STEM.vINDEX.SUFFIX`` beside it for several."""
    if path is None or n_variants == 1:
        return path
    return path.with_name(f"{path.stem}.v{index}{path.suffix}")


def journal_of(results_path: Path | None) -> Path | None:
    """The journal of a results file: ``RESULTS.journal.jsonl`` beside it."""
    return (
        None
        if results_path is None
        else results_path.with_name(results_path.name + ".journal.jsonl")
    )


def search_variants(
    design: Design,
    *,
    dpi: float | None = None,
    layers: tuple[int, ...] | None = None,
    stagger: tuple[str, ...] | None = None,
    results_path: Path | None = None,
    **options,
) -> dict[str, SearchResult]:
    """Search the design at ``dpi`` (default: its own resolution) and, with
    ``layers``/``stagger``, its structural variants (numbers of mask layers, staggered or
    one row), one :func:`search` each.

    Parameters
    ----------
    design : the base design (resolved at ``dpi`` by :func:`search_base`)
    layers, stagger : structural variants (:func:`~opticalstamp.design.structural_variants`);
        both None: the base only
    results_path : where the results will be saved; each variant journals beside its own
        :func:`variant_path` (``.journal.jsonl``), so an interrupted study resumes
    options : passed to :func:`search` (budget, constraints, pins, seed, workers, ...)

    Returns
    -------
    dict
        Results by variant name, in the variants' order (merge with :func:`merged_front`).
    """
    base = search_base(design, dpi)
    if layers or stagger:
        bases = structural_variants(
            base, layers=tuple(layers or (len(base.masks),)), stagger=tuple(stagger or ("yes",))
        )
    else:
        bases = {base.name: base}
    out = {}
    for i, (name, b) in enumerate(bases.items()):
        path = variant_path(results_path, i, len(bases))
        out[name] = search(b, journal=journal_of(path), **options)
    return out


def merged_front(results: dict[str, SearchResult]) -> list[dict]:
    """The Pareto front over several searches, each entry tagged with its variant."""
    rows = [r | {"variant": name} for name, res in results.items() for r in res.pareto]
    if not rows:
        return []
    depth = depth_key(next(iter(results.values())))
    pts = np.array([[r["efficiency_ratio"], r[depth]] for r in rows])
    return sorted((rows[i] for i in pareto_front(pts)), key=lambda r: -r[depth])


def _exact_payload(payload: dict) -> dict:
    """Worker entry: the exact tracer's figures of a candidate built from plain data, its
    rays on the payload's device."""
    base = design_from_dict(payload["base"], "search base")
    d = with_stack(base, holes_um=payload["holes_um"], thicknesses_um=payload["thicknesses_um"])
    with using_device(payload.get("device", "cpu")):
        return exact_figures(d, **payload["options"])


def _verified(row: dict, exact: dict | None) -> dict:
    """A record with the exact tracer's figures as its figures of record: the surrogate's
    kept under ``surrogate``, the exact ones under ``exact``, and ``disagrees`` naming the
    figures that differ by more than the surrogate's stated accuracy."""
    if exact is None:
        return row | {"estimator": SURROGATE, "exact": None, "disagrees": None}
    sur = {k: row[k] for k in (*FIGURES, "rmtf_at")}
    out = row | {
        "estimator": EXACT,
        "surrogate": sur,
        "exact": exact,
        "disagrees": disagreements(sur, exact),
    }
    for k in ("efficiency_ratio", "dof_mm", "ghost_fraction", "nearest_ghost_mm", "rmtf_at"):
        out[k] = exact[k]
    return out


def verify_front(
    res: SearchResult,
    *,
    ghost_rays: int = EXACT_GHOST_RAYS,
    lsf_rays: int = EXACT_LSF_RAYS,
    workers: int | None = None,
    dask_address: str | None = None,
    journal: Path | None = None,
    progress: bool = False,
    device: str | None = None,
) -> SearchResult:
    """The search's front and base design re-verified by the exact tracer.

    Each point of the front (and the base design) is traced exactly
    (:func:`~opticalstamp.studies.verify.exact_figures`, the search's seed and chart):
    its exact figures become the figures of record, the surrogate's are kept beside them,
    and ``disagrees`` names the figures where the two differ by more than
    ``SURROGATE_ACCURACY``. ``exact_dominated_by``: how many other points of the front
    dominate it in the exact figures (the surrogate ranked it on the front; 0 where the
    exact tracer agrees). Runs on the search's workers and journal, so it resumes;
    ``device`` as in :func:`search`.
    """
    if res.design is None:
        raise ValueError("verify_front: the search result carries no design")
    base_json = res.design.model_dump(mode="json", exclude_none=True)
    options = {
        "dpi": res.meta["dof_dpi"],
        "near_mm": res.meta["near_mm"],
        "ghost_rays": ghost_rays,
        "lsf_rays": lsf_rays,
        "seed": res.seed,
    }
    rows = list(res.pareto) + ([res.reference] if res.reference else [])
    where = run_device(device)
    tasks = []
    for r in rows:
        p = {
            "base": base_json,
            "holes_um": r["holes_um"],
            "thicknesses_um": r["thicknesses_um"],
            "options": options,
            "exact": True,
            "device": where,
        }
        tasks.append((task_key(p), p))
    recs = run_tasks(
        _exact_payload,
        tasks,
        workers=workers,
        dask_address=dask_address,
        journal=journal,
        progress=progress,
        desc="exact re-verification",
        check=check_figures,
    )

    def exact_of(i: int) -> dict | None:
        rec = recs.get(tasks[i][0])
        return rec["result"] if rec is not None and rec["ok"] else None

    front = [_verified(r, exact_of(i)) for i, r in enumerate(res.pareto)]
    depth = depth_key(res)
    pts = np.array([[r["efficiency_ratio"], r[depth]] for r in front]).reshape(-1, 2)
    for r, p in zip(front, pts, strict=True):
        r["exact_dominated_by"] = int((np.all(pts >= p, axis=1) & np.any(pts > p, axis=1)).sum())
    reference = res.reference
    if reference is not None:
        reference = _verified(reference, exact_of(len(rows) - 1))
    meta = res.meta | {
        "verified_by": EXACT,
        "surrogate_accuracy": dict(SURROGATE_ACCURACY),
        "exact_ghost_rays": ghost_rays,
        "exact_lsf_rays": lsf_rays,
    }
    return dataclasses.replace(res, pareto=front, reference=reference, meta=meta)


def front_designs(results: dict[str, SearchResult], front: list[dict]) -> list[dict]:
    """Every point of ``front`` (rows of :func:`merged_front` or of one search's
    ``pareto``) as a design of its own: ``{"name", "file", "design", "row", "provenance"}``.

    The design is the searched base (of the point's variant) with the point's holes and
    slabs; its name is the base's with ``-pNN`` (NN: the point's rank by depth of field,
    from 01), its description says where it comes from; ``file`` is the name of the file
    it is written to, ``STEM-pNN.toml`` with STEM the base's name as a file stem without
    spaces (:func:`~opticalstamp.io.files.file_stem`: ``paper2016-p01.toml``,
    ``paper2016-600dpi-p01.toml`` for the base ``paper2016 at 600 dpi``; unique, as NN
    is); ``provenance`` lists the search's settings and the point's surrogate and exact
    figures (the lines a design file writes as comments).
    """
    from .. import __version__
    from ..io.files import file_stem

    out = []
    for i, row in enumerate(front, start=1):
        res = results[row["variant"]] if "variant" in row else next(iter(results.values()))
        base = res.design
        name = f"{base.name}-p{i:02d}"
        desc = (
            f"Pareto point {i} of {len(front)} of a design search of {base.name} "
            f"(seed {res.seed}, {res.dpi:g} dpi, depth of field at "
            f"{res.meta['dof_dpi']:g} dpi): holes {row['holes_um']} um (layer 1 first), "
            f"slabs {row['thicknesses_um']} um (object side first)"
        )
        d = with_stack(base, holes_um=row["holes_um"], thicknesses_um=row["thicknesses_um"])
        d = replace(d, name=name, description=desc)
        sur = row.get("surrogate") or {k: row[k] for k in (*FIGURES, "rmtf_at")}
        prov = [
            f"exported by opticalstamp {__version__} search --export-designs",
            f"search: base {base.name} (fingerprint {base.fingerprint()}), seed {res.seed}, "
            f"{res.dpi:g} dpi, {len(res.records)} designs, constraints near_mm "
            f"{res.meta['near_mm']:g}, budget_mm {res.meta['budget_mm']:g}, max_spill "
            f"{res.meta['max_spill']:g}"
            + (f", max_ghost {res.meta['max_ghost']:g}" if res.meta["max_ghost"] else ""),
            f"point {i} of {len(front)}"
            + (f" (variant {row['variant']})" if "variant" in row else ""),
            "surrogate: efficiency {:.5f}, DOF {:.3f} mm, ghost fraction {:.4f}".format(
                sur["efficiency_ratio"], sur["dof_mm"], sur["ghost_fraction"]
            ),
        ]
        if row.get("exact"):
            e = row["exact"]
            prov.append(
                "exact tracer (figure of record): efficiency {:.5f}, DOF {:.3f} mm, ghost "
                "fraction {:.4f}{}".format(
                    e["efficiency_ratio"],
                    e["dof_mm"],
                    e["ghost_fraction"],
                    f"; differs from the surrogate in {', '.join(row['disagrees'])}"
                    if row["disagrees"]
                    else "",
                )
            )
        file = f"{file_stem(base.name)}-p{i:02d}.toml"
        out.append({"name": name, "file": file, "design": d, "row": row, "provenance": prov})
    return out
