"""The report's studies, run in background processes (:mod:`.background`) while its
sections run here: the study of the paper's unstated parameters (in parts), the rod-lens
presets' comparison rows, the compact design search and the tolerance study, each with
the budget of the report's :class:`~opticalstamp.report.work.StudyBudget`."""

from __future__ import annotations

import dataclasses
from types import MappingProxyType

from ..analysis.responsivity import RAY, Optics
from ..design import Design, load_design
from ..raytrace.stack import output_pitch
from ..units import dpi_of_pitch
from .background import study_workers
from .section import NotMeasurable, needs
from .work import StudyBudget, Work

#: parts the parameter study is run in (each a background task): the study is the
#: smallest job, and in two parts it fills two processes beside the search and the
#: tolerance study (one each), so the processes end together
STUDY_PARTS = 2
#: The report's rod-lens contrast curves: the report's chart resolutions that `compare`
#: draws, every 0.25 mm (`compare`: 100/200/300 dpi every 0.125 mm); the same rays, so
#: light and depth of field are `compare`'s (the DOF to 1e-3 mm: bisection from another
#: bracket).
REPORT_ROD_CURVES = MappingProxyType(
    {"dpi": (100.0, 200.0), "heights_mm": tuple(0.25 * i - 1.5 for i in range(13))}
)
#: The report's search and tolerance study by wave optics (:func:`study_budget`): the
#: search's wave estimator costs about six times the ray surrogate a design (1,000
#: tolerance samples of the prototype: 466 CPU-s against 74), so the report searches 40
#: designs (not 240) and draws 50 samples (not 200): 71 CPU-s for both studies against
#: 35 by ray optics at the full budget, the whole report 160 CPU-s against 117
#: (benchmarks/bench_tolerance_optics.py --studies, bench_report.py; docs/search.md).
#: With the estimator of 2026-11-26 (12 orders, 8 refinement steps, at least 2^19 far
#: rays) the same budget costs 117 CPU-s for the search and 82 for the tolerance study
#: (report.json study_elapsed_s, the prototype), the whole report about 300 CPU-s.
WAVE_STUDY_BUDGET = MappingProxyType(
    {"search_population": 10, "search_generations": 4, "tolerance_samples": 50}
)
#: report --spec figures that the tolerance study evaluates -> its name for them
_TOLERANCE_FIGURES = MappingProxyType(
    {"dof": "dof", "light": "efficiency", "ghost_radius": "ghost_radius"}
)


def tolerance_spec(spec: list[tuple[str, str, float]]) -> str | None:
    """The tolerance study's yield spec from a report spec (:func:`parse_report_spec`): its
    bounds on the depth of field, the light and the ghost-free radius; None (no yield:
    no hidden specification) when it bounds none of them."""
    parts = [f"{_TOLERANCE_FIGURES[n]}{op}{v:g}" for n, op, v in spec if n in _TOLERANCE_FIGURES]
    return ",".join(parts) or None


def study_jobs(
    design: Design,
    seed: int,
    fresnel: bool,
    work: Work,
    dpi: float,
    tol_spec: str | None = None,
    optics: Optics = RAY,
) -> dict:
    """The report's studies as background jobs: name -> list of (function, arguments)
    or, for the search and the tolerance study, (function, arguments, cores): the tasks
    whose results make the job (:func:`join_job`), the cores a study spreads over
    (:func:`~.background.study_workers`, also its last argument). The parameter study of the
    paper's unstated parameters only with the paper's sections (``work.paper``); the
    search and the tolerance study evaluate in closed form, which needs square holes.
    ``optics``: the report's resolved optics, which the search judges every candidate
    by and the tolerance study every sample by (with its budget,
    :func:`study_budget`)."""
    if not work.studies:
        return {}
    jobs = {}
    if work.paper:
        parts = [(i, STUDY_PARTS) for i in range(STUDY_PARTS)]
        rays = work.budget.parameter_rays
        jobs["parameter_study"] = [(run_study, (design, seed, fresnel, p, rays)) for p in parts]
    jobs["rodlens"] = [(run_rodlens, (seed, fresnel, dpi, work.budget.rodlens_rays))]
    if all(m.shape != "circle" for m in design.masks):
        budget = study_budget(work.budget, optics)
        # each on its own process and its share of the cores the report leaves idle (the
        # search keeps one pool of processes for all its generations: runner.WorkerPool)
        n = study_workers(sum(map(len, jobs.values())) + 2, 2)
        jobs["search"] = [(run_search, (design, seed, dpi, budget, optics.engine, n), n)]
        jobs["tolerance"] = [(run_tolerance, (design, seed, dpi, tol_spec, budget, optics, n), n)]
    return {name: jobs[name] for name in job_order(jobs, optics)}


def job_order(jobs: dict, optics: Optics = RAY) -> list[str]:
    """The order the report's studies go to its background processes, the longest first
    (:class:`~.background.Background` hands each task to the next process that is free):
    by ray optics the parameter study's parts, the rod-lens rows, the search and the
    tolerance study (the parts end with the search and the tolerance study); by wave
    optics the search and the tolerance study first, each several times longer than by
    ray optics (the wave estimator and the exact wave figures of the search's front:
    :data:`WAVE_STUDY_BUDGET`), so that the parameter study and the rod-lens rows fill
    the other process meanwhile instead of leaving those two alone at the end. The
    order changes no number: every study carries its own seed."""
    first = ("search", "tolerance") if optics.engine == "wave" else ()
    return [n for n in first if n in jobs] + [n for n in jobs if n not in first]


def study_budget(budget: StudyBudget, optics: Optics) -> StudyBudget:
    """The budget of the report's search and tolerance study by ``optics``: by wave
    optics each evaluation (the search's wave estimator) costs about six times a ray
    surrogate's, so the designs searched and the samples drawn are cut to at most
    :data:`WAVE_STUDY_BUDGET` (the report's time: benchmarks/bench_report.py); a
    budget given smaller is kept."""
    if optics.engine != "wave":
        return budget
    caps = {k: min(getattr(budget, k), v) for k, v in WAVE_STUDY_BUDGET.items()}
    return dataclasses.replace(budget, **caps)


def join_job(name: str, results: list):
    """The result of job ``name`` from the results of its tasks."""
    if name == "parameter_study":
        from ..analysis.paper_study import join_parts

        return join_parts(results)
    (result,) = results
    return result


def run_study(
    design: Design, seed: int, fresnel: bool, part: tuple[int, int], n_rays: int
):  # pragma: no cover - a background process
    """Part ``part`` of the study of the paper's unstated parameters (background). The row
    of the design itself is left to :func:`~opticalstamp.analysis.paper_study.with_headline`
    (the report's own analyses of the design, computed meanwhile)."""
    from ..analysis.paper_study import parameter_study

    deferred = {(design.fingerprint(), fresnel)}
    return parameter_study(design, seed=seed, deferred=deferred, part=part, n_rays=n_rays)


def run_rodlens(
    seed: int, fresnel: bool, dof_dpi: float, n_rays: int
):  # pragma: no cover - background
    """The rod-lens presets' comparison rows (the report's "stamp against a rod-lens
    array" section): each preset evaluated as `compare` does (``n_rays`` the contrast
    curves' rays), its depth of field on the report's chart ``dof_dpi``."""
    from ..studies.compare import RODLENS_PRESETS, evaluate_rodlens, labelled

    rows = []
    for name in RODLENS_PRESETS:
        d = load_design(name)
        curves = REPORT_ROD_CURVES | {"dpi": tuple(sorted({*REPORT_ROD_CURVES["dpi"], dof_dpi}))}
        row = evaluate_rodlens(
            d, seed=seed, fresnel=fresnel, dof_dpi=dof_dpi, n_rays=n_rays, **curves
        )
        rows.append(labelled(d, row, seed, fresnel))
    return rows


def run_search(
    design: Design,
    seed: int,
    dof_dpi: float,
    budget: StudyBudget,
    optics: str = "ray",
    workers: int = 1,
):  # pragma: no cover - background
    """The compact design search of a report (the CLI's `search` runs the full budget),
    every candidate judged by ``optics`` (the report's engine, "ray" or "wave"), its
    front re-verified by the exact tracer (by wave optics: the exact wave figures), on
    ``workers`` processes (1: this one; the front does not depend on it)."""
    from ..studies.search import search, verify_front

    dpi = dpi_of_pitch(output_pitch(design))
    res = search(
        design,
        dpi=dpi,
        dof_dpi=dof_dpi,
        population=budget.search_population,
        generations=budget.search_generations,
        seed=seed,
        ghost_rays=budget.search_ghost_rays,
        workers=workers,
        optics=optics,
    )
    return verify_front(
        res,
        ghost_rays=budget.verify_ghost_rays,
        lsf_rays=budget.verify_lsf_rays,
        wave_ghost_rays=budget.verify_ghost_rays,
        wave_lsf_rays=budget.verify_lsf_rays,
        workers=workers,
    )


def run_tolerance(
    design: Design,
    seed: int,
    dpi: float,
    spec: str | None,
    budget: StudyBudget,
    optics: Optics = RAY,
    workers: int = 1,
):  # pragma: no cover - a background process
    """The report's tolerance study (the CLI's `tolerance` runs more samples), every
    sample by the report's resolved ``optics``, on ``workers`` processes (1: this one;
    the figures do not depend on it)."""
    from ..studies.tolerance import tolerance

    return tolerance(
        design,
        samples=budget.tolerance_samples,
        seed=seed,
        dpi=dpi,
        spec=spec,
        workers=workers,
        optics=optics,
    )


def headline_study(study, design: Design, ghosts, rmtf, fresnel: bool):
    """The parameter study with the row that is this design rebuilt from the report's own
    ghost analysis and RMTF (:func:`~opticalstamp.analysis.paper_study.with_headline`);
    not measurable where either is not."""
    from ..analysis.paper_study import with_headline

    missing = needs(ghost=ghosts, RMTF=rmtf)
    if missing is not None:
        return missing
    return with_headline(study, design, ghosts, rmtf.result, fresnel)


def rodlens_section(design: Design, eff, rmtf, rod_rows: list | None, seed: int, fresnel: bool):
    """The report's rod-lens section: the design's row (from the report's own efficiency
    ``eff`` and RMTF section ``rmtf``) before the presets' rows; None where the presets
    were not evaluated."""
    if rod_rows is None:
        return None
    if isinstance(rod_rows, NotMeasurable):
        return rod_rows
    missing = needs(efficiency=eff, RMTF=rmtf)
    if missing is not None:
        return missing
    from ..studies.compare import labelled, relative_to_first, stamp_row

    row = stamp_row(design, eff, rmtf.result)
    gains = [a["gain_own_vs_design"] for a in eff.sensitive_area if a["area_scale"] == 4.0]
    return {
        "rows": relative_to_first([labelled(design, row, seed, fresnel), *rod_rows]),
        "area_gain": gains[0] if gains else None,
    }
