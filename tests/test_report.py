"""`opticalstamp report`, the main job: every section, every figure, provenance."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
from PIL import Image
from tests.passcount import assert_each_pixel_traced_once, spy_and_count
from typer.testing import CliRunner

from opticalstamp.cli.common import app
from opticalstamp.design import load_design
from opticalstamp.report import build
from opticalstamp.report.work import StudyBudget

#: the background search and tolerance study's budget, by either optics: 8 designs over two
#: generations (the prototype among the first, a front to verify and plot), 4 samples (the
#: report's own budgets: 240 / 200 by ray optics, 40 / 50 by wave optics); what the test
#: checks of them is that they run, are written, plotted and shown
SMALL_STUDIES = {"search_population": 4, "search_generations": 2, "tolerance_samples": 4}


def _small(real):
    """The full report's work (every section, its heights, both sensitive
    areas, scans with OCR, the background studies) with fewer rays, smaller study budgets,
    the RMTF every 0.5 mm (the quick report's grid: 10 heights, not 19) and the charts
    scanned at 600 dpi (the report's 1200: four times the pixels to scan,
    restore and read, for the same code): what a section computes is the same, on fewer
    samples."""

    def work(*args, **kwargs):
        w = real(*args, **kwargs)
        assert not w.reduced and w.studies and w.ocr  # the full report's shape
        budget = StudyBudget(
            **SMALL_STUDIES,
            search_ghost_rays=1 << 14,
            verify_ghost_rays=1 << 16,
            verify_lsf_rays=1 << 16,
            parameter_rays=1 << 16,
            rodlens_rays=1 << 18,
        )
        return replace(
            w,
            ghost_rays=1 << 19,
            concept_rays=1 << 17,
            lsf_rays=1 << 19,
            lsf_z_mm=tuple(0.5 * i for i in range(10)),  # the RMTF every 0.5 mm, as quick
            kernel_rays=1 << 18,
            wave_rays=1 << 18,
            wave_z_step_mm=0.5,  # the ray-vs-wave section every 0.5 mm (10 heights)
            scan_dpi=600.0,
            budget=budget,
        )

    return work


#: the spec the report's verdict is judged against: met by the prototype's depth of field
#: and ghost-free radius, not by its light
SPEC = "dof>=2.2,ghost_radius>=5,light>=0.05"


def test_the_study_budgets_defaults_are_the_studies_own():
    """The report's parameter study and rod-lens rows trace as many rays as the functions
    and `compare` do by default (the budget only moves the figure into the work)."""
    import inspect

    from opticalstamp.analysis.paper_study import parameter_study
    from opticalstamp.analysis.rodlens import RAYS_CONTRAST

    rays = inspect.signature(parameter_study).parameters["n_rays"].default
    assert StudyBudget().parameter_rays == rays and StudyBudget().rodlens_rays == RAYS_CONTRAST


@pytest.fixture(scope="module")
def full_report(tmp_path_factory):
    """One full report of the prototype (the small work above) against :data:`SPEC`, its
    JSON on stdout: run once for the tests of its sections and of its verdict (each had
    run a report of its own, the verdict's a quick one: what the verdict is checked for,
    its figures taken from the report's own sections and judged against the spec, is the
    same for either); with its launches spied on and its passes counted (each pixel
    traced once, below)."""
    out = tmp_path_factory.mktemp("full") / "rep"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(build, "report_work", _small(build.report_work))
        seen, works, passes = spy_and_count(mp)
        args = ["report", "--design", "paper2016", "--out", str(out), "--rays", "262144"]
        res = CliRunner().invoke(app, [*args, "--spec", SPEC, "--json"])
    assert res.exit_code == 0, res.output
    return out, res, (seen, works, passes)


def test_the_report_traces_each_pixel_once(full_report):
    """Every traced analysis of a used pixel in the full report (every section, both
    sensitive areas, scans with OCR; the background studies trace in processes of
    their own) draws its rays from one tracer: counted by the tracer and by a spy."""
    out, _, (seen, works, passes) = full_report
    assert json.loads((out / "report.json").read_text())["optics"]["engine"] == "wave"
    assert len(works) == 1 and not works[0].reduced
    assert_each_pixel_traced_once(load_design("paper2016"), seen, works[0], passes)


def test_report_writes_every_section(full_report):
    out, _, _ = full_report
    d = json.loads((out / "report.json").read_text())
    for key in (
        "ghosts",
        "spots",
        "psf",
        "concepts",
        "rmtf",
        "rmtf_paraxial_own",
        "chart_profiles",
        "efficiency",
        "diffraction",
        "parameter_study",
        "scans",
        "search",
        "tolerance",
        "rodlens",
        "stack",
        "summary",
        "restoration",
        "ray_vs_wave",
    ):
        assert key in d, key
    # restoration with the known blur: every method carries the depth of field beyond the
    # raw scan's and below the ceiling, the transfer function's zero; in the verdict too
    st = d["restoration"]["study"]
    raw = st["dof"]["raw"]["dof_mm"]
    assert all(
        raw < st["dof"][m]["dof_mm"] < st["transfer_zero_mm"] for m in ("wiener", "rl", "tv")
    )
    verdict = {f["figure"]: f["value"] for f in d["summary"]["figures"]}
    assert verdict["restored_dof"] == st["dof"]["wiener"]["dof_mm"]
    if d["scans"]["ocr"]:  # tesseract present
        assert {o["version"] for o in d["restoration"]["ocr"]} >= {"raw", "wiener"}
    assert d["provenance"]["design"] == "paper2016" and d["provenance"]["seed"] == 0
    assert "opticalstamp_version" in d["provenance"]
    page = (out / "index.html").read_text()
    for heading in (
        "Ghost analysis",
        "Spots on the object plane",
        "PSFs on the sensor",
        "RMTF and depth of field",
        "Light efficiency",
        "Diffraction",
        "unstated parameters",
        "Simulated scans",
        "Design search",
        "Tolerancing",
        "The stamp against a rod-lens array",
        "The design as built",
        "Verdict",
        "Restoration with the known blur",
    ):
        assert heading in page, heading
    figures = [
        "ghosts",
        "spots",
        "psf_x0",
        "psf_half_pitch",
        "rmtf",
        "chart_profiles",
        "efficiency",
        "diffraction",
        "study",
        "scan_text",
        "scan_bars",
        "scan_profiles",
        "scan_lines",
        "scan_tilt",
        "restore_curves",
        "restore_text",
        "pareto",
        "tolerance",
        "rodlens_contrast",
        "rodlens_light",
        "stack",
    ]
    for name in figures:
        assert f'src="{name}.png"' in page
        with Image.open(out / f"{name}.png") as im:
            assert im.size[0] > 300 and im.size[1] > 150
    rows = d["rodlens"]["rows"]  # the design first, from the report's own analyses
    assert [r["name"] for r in rows] == ["paper2016", "sla-1row-12deg", "sla-2row-20deg"]
    assert rows[0]["light_vs_f10"] == d["efficiency"]["ratio_own"]
    assert rows[0]["dof_mm"] == [0.0, d["rmtf"]["dof_mm"]["200"]]
    assert "fits <b>sla-1row-12deg</b>" in page  # the paper's ~1/100


def test_report_verdict_against_a_spec(full_report, tmp_path):
    from edges import assert_clean_refusal, run

    out, res, _ = full_report
    s = json.loads(res.stdout)["summary"]
    fig = {f["figure"]: f for f in s["figures"]}
    d = json.loads((out / "report.json").read_text())
    assert fig["dof"]["value"] == d["rmtf"]["dof_mm"]["200"] and fig["dof"]["check"]["pass"]
    assert fig["ghost_radius"]["value"] * 1000 == min(
        v["nearest_um"] for v in d["ghosts"]["landing"].values()
    )
    assert fig["light"]["check"]["pass"] is False and s["meets_spec"] is False
    assert fig["dof"]["paper"] == 3.5  # the prototype: the paper's figure beside the model's
    assert "Does not meet the spec" in (out / "index.html").read_text()
    bad = tmp_path / "bad"
    assert_clean_refusal(run(["report", "--quick", "--out", bad, "--spec", "dof>2"]), "--spec")
    assert not bad.exists()
