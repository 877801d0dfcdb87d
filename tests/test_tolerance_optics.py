"""The tolerance study and the report's background studies follow the design's optics
(issue 23): resolved once for the nominal design, every sample by that engine."""

from __future__ import annotations

import dataclasses
import functools
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from opticalstamp.analysis.responsivity import resolve_optics
from opticalstamp.cli import app
from opticalstamp.design import design_toml, load_design, replace, stack_params, with_stack
from opticalstamp.report.html.studies import search_html, tolerance_html
from opticalstamp.report.studies import (
    WAVE_STUDY_BUDGET,
    run_search,
    run_tolerance,
    study_budget,
    study_jobs,
)
from opticalstamp.report.work import StudyBudget, report_work
from opticalstamp.studies.evaluate import evaluate_design
from opticalstamp.studies.tolerance import tolerance, tolerance_dataset
from opticalstamp.studies.waveestimate import (
    EXACT_WAVE,
    WAVE_ESTIMATE,
    evaluate_wave,
    wave_disagreements,
)
from opticalstamp.validate import InputError

runner = CliRunner()
#: only the hole sizes err (fewer evaluations: three errors in the sensitivity table)
HOLES_ONLY = {"misregistration_um": 0.0, "hole_um": 1.5, "thickness_um": 0.0, "tilt_deg": 0.0}
NONE = {k: 0.0 for k in HOLES_ONLY}
Z = (1.0, 2.0)
RAYS = 1 << 14


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


@pytest.fixture(scope="module")
def rgb(paper):
    """The prototype lit by R/G/B LEDs in turn: auto picks ray optics for it (the wave
    engine does not feed the analyses three channels yet)."""
    return replace(paper, {"electronics.illumination": "rgb"}, name="paper2016-rgb")


def _direct(design, errors, dpi, seed):
    """A perturbed design's wave figures computed directly: the holes changed by hand
    (nothing else errs here) and the wave estimator called on it."""
    p = stack_params(design)
    holes = [h + errors.get(f"hole{i + 1}", 0.0) for i, h in enumerate(p["holes_um"])]
    d = with_stack(design, holes_um=holes)
    return d, evaluate_wave(d, dpi=dpi, rmtf_z_mm=Z, ghost_rays=RAYS, seed=seed)


def _same(a: dict, b: dict) -> None:
    for k in ("efficiency_ratio", "ghost_fraction", "dof_mm", "etendue_own_um2sr"):
        assert a[k] == pytest.approx(b[k], rel=1e-6, abs=1e-9), k
    assert a["rmtf_at"] == pytest.approx(b["rmtf_at"], rel=1e-6, abs=1e-9)


def test_wave_samples_are_the_wave_figures_of_the_perturbed_designs(paper):
    res = tolerance(
        paper, samples=2, sigmas=HOLES_ONLY, z_mm=Z, seed=3, ghost_rays=RAYS, workers=1,
        optics="wave", spec="dof>=2.3",
    )  # fmt: skip
    assert res.meta["optics"]["engine"] == "wave" and res.meta["estimator"] == WAVE_ESTIMATE
    directs = []
    for e, s in zip(res.errors, res.samples, strict=True):
        assert s["optics"] == "wave"
        d, direct = _direct(paper, e, res.dpi, 3)
        _same(s, direct)
        directs.append(direct)
        # and not the ray figures: at the prototype's Fresnel numbers (0.66-1.1) the wave
        # light is several per cent above the ray surrogate's
        ray = evaluate_design(d, dpi=res.dpi, rmtf_z_mm=Z, ghost_rays=RAYS, seed=3)
        assert s["efficiency_ratio"] / ray["efficiency_ratio"] - 1 > 0.03
    dof = np.array([x["dof_mm"] for x in directs])
    assert res.percentiles()["dof_mm"]["p50"] == pytest.approx(np.median(dof), rel=1e-6)
    assert res.yield_fraction == np.mean(dof >= 2.3)
    # the sensitivity table from wave figures too: hole1 at +-1 sigma, directly
    _, nominal = _direct(paper, {}, res.dpi, 3)
    _same(res.nominal, nominal)
    row = next(r for r in res.sensitivity if r["error"] == "hole1")
    plus = _direct(paper, {"hole1": 1.5}, res.dpi, 3)[1]
    minus = _direct(paper, {"hole1": -1.5}, res.dpi, 3)[1]
    e0 = nominal["efficiency_ratio"]
    want = np.mean([abs(x["efficiency_ratio"] - e0) for x in (plus, minus)])
    assert row["d_efficiency_ratio"] == pytest.approx(want, rel=1e-6)
    # the nominal verified by the exact wave figures, judged by the wave estimator's accuracy
    ex = res.meta["nominal_exact"]
    assert ex["estimator"] == EXACT_WAVE and ex["optics"] == "wave"
    assert res.meta["nominal_disagrees"] == wave_disagreements(res.nominal, ex)
    # the optics travels with the result: JSON and both datasets
    assert res.to_dict()["meta"]["optics"]["engine"] == "wave"
    assert res.to_dataset().attrs["optics"] == "wave"
    attrs = tolerance_dataset(res, paper).attrs
    assert attrs["optics"] == "wave" and attrs["optics_asked"] == "wave"


def test_auto_picks_as_resolve_optics_does(paper, rgb):
    for d, engine in ((paper, "wave"), (rgb, "ray")):
        want = resolve_optics(d, "auto")
        assert want.engine == engine  # both engines are exercised
        res = tolerance(
            d, samples=1, sigmas=NONE, z_mm=Z, ghost_rays=RAYS, workers=1, optics="auto",
            verify=False,
        )  # fmt: skip
        assert res.meta["optics"] == want.to_dict()
        assert res.nominal["optics"] == res.samples[0]["optics"] == engine
    # ray optics asked for: the surrogate's figures, as before
    r = tolerance(paper, samples=1, sigmas=NONE, z_mm=Z, ghost_rays=RAYS, workers=1, verify=False)
    assert r.meta["optics"]["engine"] == "ray" and r.samples[0]["optics"] == "ray"
    _same(r.nominal, evaluate_design(paper, dpi=r.dpi, rmtf_z_mm=Z, ghost_rays=RAYS))
    with pytest.raises(InputError, match="optics: 'wave' is not available"):
        tolerance(rgb, samples=1, optics="wave")
    with pytest.raises(InputError, match="optics: must be one of ray, wave, auto"):
        tolerance(paper, samples=1, optics="rays")


def test_cli_optics(tmp_path, rgb):
    res = runner.invoke(app, ["tolerance", "--optics", "sound", "--samples", "1"])
    assert res.exit_code == 2 and "--optics: must be one of ray, wave, auto" in res.output
    f = tmp_path / "rgb.toml"
    f.write_text(design_toml(rgb))
    res = runner.invoke(app, ["tolerance", "--design", str(f), "--optics", "wave"])
    assert res.exit_code == 2 and "--optics: 'wave' is not available" in res.output
    args = ["tolerance", "--samples", "1", "--workers", "1", "--z", "1,2", "--hole-um", "0",
            "--misregistration-um", "0", "--thickness-um", "0", "--tilt-deg", "0"]  # fmt: skip
    res = runner.invoke(app, [*args, "--optics", "ray"])
    assert res.exit_code == 0, res.output
    assert "optics: ray (geometric; asked for); every sample by the same optics" in res.output
    assert "nominal by the exact tracer" in res.output
    res = runner.invoke(app, [*args, "--json"])  # the default: auto, wave for the prototype
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["meta"]["optics"] == resolve_optics(load_design("paper2016"), "auto").to_dict()
    assert data["meta"]["nominal_exact"]["estimator"] == EXACT_WAVE


def test_report_studies_follow_the_report_optics(paper, monkeypatch):
    """The report's search and tolerance jobs get the report's optics, and run by it.
    The tolerance job's study with only the holes erring, on 2^14 ghost rays (three
    sensitivity rows, not thirteen: 16 -> 6 s measured); what is checked, the optics
    of every figure and the page's words, is the same for any sigmas."""
    import opticalstamp.studies.tolerance as tolerance_module

    few = functools.partial(tolerance_module.tolerance, sigmas=HOLES_ONLY, ghost_rays=RAYS)
    monkeypatch.setattr(tolerance_module, "tolerance", few)  # run_tolerance imports it
    wave = resolve_optics(paper, "auto")
    work = report_work(False, 1 << 16, None, False)
    jobs = study_jobs(paper, 0, False, work, 200.0, None, optics=wave)
    (fn, args, _), (tfn, targs, _) = jobs["search"][0], jobs["tolerance"][0]
    assert fn is run_search and args[4] == "wave"  # then the processes (on this machine's
    assert tfn is run_tolerance and targs[5] is wave  # idle cores, test_report_background)
    budget = study_budget(work.budget, wave)
    assert args[3] == targs[4] == budget
    assert {k: getattr(budget, k) for k in WAVE_STUDY_BUDGET} == dict(WAVE_STUDY_BUDGET)
    # a budget given below the wave caps is kept (by either optics), one above is cut
    small = dataclasses.replace(
        work.budget, search_population=4, search_generations=2, tolerance_samples=8
    )
    assert study_budget(small, wave) == small == study_budget(small, resolve_optics(paper, "ray"))
    mixed = dataclasses.replace(work.budget, search_population=4)
    assert study_budget(mixed, wave).search_population == 4
    assert study_budget(mixed, wave).tolerance_samples == WAVE_STUDY_BUDGET["tolerance_samples"]
    ray = resolve_optics(paper, "ray")
    (_, rargs, _), (_, rtargs, _) = (
        study_jobs(paper, 0, False, work, 200.0, None, optics=ray)[k][0]
        for k in ("search", "tolerance")
    )  # fmt: skip
    assert rargs[4] == "ray" and rtargs[5] is ray and rargs[3] == work.budget
    # the jobs themselves, on a tiny budget: every figure by the report's optics
    tiny = StudyBudget(
        search_population=4, search_generations=1, search_ghost_rays=RAYS,
        verify_ghost_rays=1 << 16, verify_lsf_rays=1 << 16, tolerance_samples=1,
    )  # fmt: skip
    t = run_tolerance(paper, 0, 200.0, None, tiny, wave)
    assert t.meta["optics"]["engine"] == "wave" and t.samples[0]["optics"] == "wave"
    s = run_search(paper, 0, 200.0, tiny, "wave")
    assert s.meta["optics"] == "wave" and set(s.meta["optics_used"]) == {"wave"}
    assert s.reference["estimator"] == EXACT_WAVE
    assert all(p["estimator"] == EXACT_WAVE for p in s.pareto)
    # and the page says which optics gave them
    page = search_html(s.to_dict(), t.to_dict())
    assert "every candidate by\nwave optics (the report's)" in page
    assert "wave optics, the report's, for every\nsample" in page
    assert "by the exact wave figures" in page
    assert "the wave estimator" in tolerance_html(t.to_dict())
