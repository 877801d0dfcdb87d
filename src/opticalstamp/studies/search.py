"""Design search (paper §3): hole sizes and slab thicknesses of a stack for a sensor and a
target resolution, maximising light efficiency and depth of field, with no near ghosts.

Variables: the square hole size of each layer (1 um steps between ``min_hole_um`` and the
largest that leaves ``min_wall_um`` of mask between the staggered rows) and each slab's
thickness (``thickness_step_um`` steps; glass plates and air gaps between ``bounds``);
any of them can be pinned. Constraints: no ghost light within ``near_mm`` of the pixel's
axis at Z = 0 ... 4 mm (the paper's virtual detector), optionally a ghost-fraction bound,
and a total stack-thickness budget (the diffraction spill is reported, not judged: where
diffraction matters the candidates are judged by wave optics, ``optics``). Objectives:
light efficiency (ratio to the paper's reference lens) and depth of field on the chart at
``dof_dpi`` (default 2/3 of the design's resolution: 200 dpi for 300, 400 for 600).

The optimiser is Optuna's NSGA-II (multi-objective, constraint-aware), seeded, driven by
batches of ``population`` designs that are evaluated in parallel (:mod:`execute`); the
result is the Pareto front of the feasible designs. Seeds belong to the evaluations, so
the front is the same for any number of workers.

This module is the optimisation loop and the study of a design's variants; the space and
its constraints are in :mod:`.searchspace`, the result, its records and the merged front in
:mod:`.searchresult`, the exact re-verification of a front and its export as designs in
:mod:`.front` (their names are importable from here too).
"""

from __future__ import annotations

import functools
from collections import Counter
from pathlib import Path

import numpy as np

from ..analysis.responsivity import OPTICS, resolve_optics
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
from .evaluate import check_figures
from .front import front_designs, verify_front
from .runner import WorkerPool, run_tasks, task_key
from .searchresult import (
    FIGURES,
    OBJECTIVES,
    SearchResult,
    depth_key,
    merged_front,
    pareto_front,
    record_row,
    search_dataset,
)
from .searchspace import (
    CONSTRAINTS,
    SearchSpace,
    constraint_values,
    default_space,
    lateral_scale,
    on_grid,
    rejections,
)
from .verify import ESTIMATORS, check_estimator, evaluate_with
from .waveestimate import WAVE_ACCURACY, WAVE_ESTIMATE

#: a base whose output pitch is within this of 25.4 mm / dpi is searched as it is
SAME_RESOLUTION = 0.01


def _evaluate_payload(payload: dict) -> dict:
    """Worker entry: build the candidate from plain data and evaluate it with the
    payload's estimator (:func:`~opticalstamp.studies.verify.evaluate_with`), its rays on
    the payload's device."""
    base = design_from_dict(payload["base"], "search base")
    d = with_stack(base, holes_um=payload["holes_um"], thicknesses_um=payload["thicknesses_um"])
    with using_device(payload.get("device", "cpu")):
        return evaluate_with(d, payload["options"])


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
    optics: str = "ray",
) -> SearchResult:
    """NSGA-II search of hole sizes and thicknesses; returns every evaluation and the front.

    ``objective``: the depth maximised with the light, "dof" (the depth of field) or
    "restored-dof" (the depth of field after Wiener restoration with the known blur,
    closed form: designs whose transfer function keeps the chart's frequency alive).
    ``estimator``: "surrogate" (closed form with a uniform ghost background, fast) or
    "trace" (every candidate's ghosts, light, RMTF and depth of field from the exact
    tracer, :func:`~opticalstamp.studies.verify.evaluate_exact`; about 0.3 s a design on
    the CPU, on the GPU with ``--device cuda``).
    ``optics``: "ray", "wave" or "auto": the engine that judges each candidate (a
    resolved per candidate, so "auto" follows the measured validity rule design by design,
    :func:`~opticalstamp.analysis.responsivity.resolve_optics`); with wave optics the
    candidate's figures are the wave estimator's
    (:func:`~opticalstamp.studies.waveestimate.evaluate_wave`, or the exact wave figures
    with ``estimator`` "trace"); each record's ``optics`` names the engine.
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
    if optics not in OPTICS:
        raise InputError(f"optics: must be one of {', '.join(OPTICS)} (got {optics!r})")
    if optics == "wave":  # refused here, naming why, rather than in every worker
        resolve_optics(design, "wave")
    options = {"dpi": dof_dpi, "near_mm": near_mm, "ghost_rays": ghost_rays}
    if estimator == "trace":
        options["estimator"] = "trace"
    if optics != "ray":  # absent for ray optics: the tasks' keys of earlier journals hold
        options["optics"] = optics
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
        start = {k: on_grid(dists[k], v) for k, v in base_params.items() if k not in pins}
        study.enqueue_trial(start, skip_if_exists=True)
    # one lock for every generation of this run, and one pool of processes (a pool per
    # generation cost more than the generation on 2 cores: runner.WorkerPool)
    with journal_lock(journal), WorkerPool(workers) as pool:
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
                pool=pool,
                lock=False,
                check=check_figures,
            )
            for t, params, key in trials:
                rec = recs.get(key)
                if rec is None or not rec["ok"]:
                    study.tell(t, state=optuna.trial.TrialState.FAIL)
                    records.append(record_row(params, rec, None, False, n_h, n_t))
                    continue
                m = rec["result"]
                cons = constraint_values(m, budget_um, max_ghost)
                for name, c in zip(CONSTRAINTS, cons, strict=True):
                    t.set_constraint(name, c)  # <= 0: satisfied (NSGA-II's constrained domination)
                study.tell(t, [m["efficiency_ratio"], m[depth]])
                records.append(record_row(params, rec, m, all(c <= 0 for c in cons), n_h, n_t))
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
        reference = record_row(
            base_params,
            ref_rec,
            m,
            all(c <= 0 for c in constraint_values(m, budget_um, max_ghost)),
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
            "optics": optics,
            "optics_used": dict(Counter(r["optics"] for r in records if r["ok"])),
            "wave_estimator": WAVE_ESTIMATE,
            "wave_accuracy": dict(WAVE_ACCURACY),
            "rejected_by": rejections(records, budget_um, max_ghost),
            "population": population,
            "generations": generations,
            "pinned": pins,
            "ghost_rays": ghost_rays,
            "hole_bounds_um": list(sp.hole_bounds_um),
            "thickness_bounds_um": [list(b) for b in sp.thickness_bounds_um],
        },
    )


def search_base(design: Design, dpi: float | None = None) -> Design:
    """The design to search at ``dpi``: itself when ``dpi`` is None (its own resolution)
    or its output pitch is within SAME_RESOLUTION of 25.4 mm / dpi (300 dpi is 84.67 um;
    the paper's sensor gives 84.6 um), else the design with every length scaled to that
    resolution (only when asked): the sensor and the holes by
    :func:`~opticalstamp.design.scale_to_dpi`, and the slabs and the reference gap by
    the same factor (geometric similarity: its aspect ratios, so its ray optics, as at
    its own resolution; the plates kept at 600 dpi left it ghost-heavy and at 1200 dpi
    1 mm of reference gap over 10-um holes leaves no contrast at any height, the holes'
    Fresnel number towards it 0.06). The search space around it follows the resolution
    (:func:`~opticalstamp.studies.searchspace.default_space`)."""
    if dpi is None or abs(pitch_of_dpi(dpi) / output_pitch(design) - 1) < SAME_RESOLUTION:
        return design
    out = scale_to_dpi(design, dpi)
    k = lateral_scale(out) / lateral_scale(design)  # as named: 1/2 from 300 to 600 dpi
    changes: dict[str, object] = {
        f"slabs.{i}.thickness_um": round(sl.thickness_um * k, 3)
        for i, sl in enumerate(design.slabs)
    }
    changes["reference_gap.thickness_um"] = round(design.reference_gap.thickness_um * k, 3)
    return replace(out, changes)


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


#: what the search's modules offer, importable from here as before the split
__all__ = [
    "CONSTRAINTS",
    "FIGURES",
    "OBJECTIVES",
    "SAME_RESOLUTION",
    "SearchResult",
    "SearchSpace",
    "default_space",
    "depth_key",
    "front_designs",
    "journal_of",
    "merged_front",
    "pareto_front",
    "search",
    "search_base",
    "search_dataset",
    "search_variants",
    "variant_path",
    "verify_front",
]
