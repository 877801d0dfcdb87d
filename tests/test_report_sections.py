"""The report as sections (issue 22): a section that cannot be measured for a design says
"not measurable: reason" on the page and in report.json, and the rest of the report is
written; a programming error still takes the report down."""

from __future__ import annotations

import json
import re
from dataclasses import replace

import pytest

from opticalstamp.design import load_design
from opticalstamp.report import build
from opticalstamp.report.background import Background
from opticalstamp.report.section import (
    MEASURING_ERRORS,
    NotMeasurable,
    measure,
    needs,
    not_measurable,
)
from opticalstamp.validate import InputError


def _boom(error: BaseException):
    def compute(*args, **kwargs):
        raise error

    return compute


@pytest.mark.parametrize(
    "error",
    [ValueError("an edge too blurred"), ZeroDivisionError("no light"), InputError("bad")],
)
def test_a_measuring_error_is_a_reason(error):
    res = measure(_boom(error))
    assert isinstance(res, NotMeasurable) and res.reason == str(error)
    assert res.to_dict() == {"not_measurable": str(error)}
    assert not_measurable(res.to_dict()) == str(error)
    assert str(res) == f"not measurable: {error}"


@pytest.mark.parametrize(
    "error", [KeyError("x"), TypeError("x"), AttributeError("x"), IndexError("x"), OSError("x")]
)
def test_a_programming_error_is_not_absorbed(error):
    assert not isinstance(error, MEASURING_ERRORS)
    with pytest.raises(type(error)):
        measure(_boom(error))


def test_a_section_needs_the_sections_it_reads():
    assert needs(ghost=1, RMTF=2) is None
    missing = needs(ghost=1, RMTF=NotMeasurable("no edge"))
    assert missing == NotMeasurable("needs the RMTF section (not measurable: no edge)")
    assert measure(lambda: 3) == 3


def test_a_background_job_that_cannot_be_measured_is_a_reason():
    with Background({"study": [(int, ("not a number",))]}) as bg:
        res = measure(bg.result, "study")
    assert isinstance(res, NotMeasurable) and "not a number" in res.reason


def _small(real):
    """The quick report's work with fewer rays: every section still runs."""

    def work(*args, **kwargs):
        w = real(*args, **kwargs)
        return replace(
            w,
            ghost_rays=1 << 17,
            map_rays=1 << 15,
            concept_rays=1 << 15,
            lsf_rays=1 << 16,
            kernel_rays=1 << 15,
        )

    return work


def test_a_section_that_cannot_be_measured_leaves_the_rest_of_the_report(tmp_path, monkeypatch):
    """The RMTF section (a ValueError) and the diffraction section (an ArithmeticError)
    fail: both say why, on the page and in report.json; the scans compute their RMTF
    without the RMTF section's LSFs; the verdict and the paper table leave out what they
    lack; every other section and figure is written."""
    monkeypatch.setattr(build, "report_work", _small(build.report_work))
    monkeypatch.setattr(build, "rmtf_section", _boom(ValueError("no chart is resolved")))
    monkeypatch.setattr(build, "diffraction_section", _boom(ZeroDivisionError("no hole")))
    out = tmp_path / "r"
    data = build.build_report(load_design("paper2016"), out, quick=True, spec="dof>=2")
    saved = json.loads((out / "report.json").read_text())
    for key in ("rmtf", "rmtf_paraxial_own", "rmtf_traced_own", "chart_profiles"):
        assert saved[key] == {"not_measurable": "no chart is resolved"}, key
    assert saved["diffraction"] == {"not_measurable": "no hole"}
    for key in ("ghosts", "spots", "psf", "concepts", "efficiency", "signal", "scans"):
        assert not_measurable(saved[key]) is None, key
    assert saved["restoration"]["study"]["dof"]["wiener"]["dof_mm"] > 0
    assert len(saved["scans"]["profiles"]) == 2  # the computed RMTF traced here instead
    figures = {f["figure"]: f for f in saved["summary"]["figures"]}
    assert figures["dof"]["value"] is None and figures["dof"]["check"]["pass"] is None
    assert figures["light"]["value"] == saved["efficiency"]["ratio_own"]
    rows = {r["statement"]: r for r in saved["paper_vs_model"]}
    assert rows["geometric edge of the 48 µm hole's shadow at Z = 1 mm"]["model"] is None
    assert data["summary"] == saved["summary"]
    page = (out / "index.html").read_text()
    assert (
        "<h2>RMTF and depth of field (paper Eq. 1, Fig. 11)</h2>\n"
        "<p>not measurable: no chart is resolved</p>" in page
    )
    assert "<h2>Diffraction (paper Fig. 6)</h2>\n<p>not measurable: no hole</p>" in page
    for heading in ("Ghost analysis", "Light efficiency", "Simulated scans", "Restoration"):
        assert heading in page, heading
    shown = set(re.findall(r'src="([^"]+)"', page))
    assert shown == set(saved["figures"])  # no figure of a missing section, none left out
    assert not {"rmtf.png", "chart_profiles.png", "diffraction.png"} & shown
    assert {"ghosts.png", "efficiency.png", "scan_bars.png", "restore_text.png"} <= shown
    for name in saved["figures"]:
        assert (out / name).is_file()


def test_a_programming_error_takes_the_report_down(tmp_path, monkeypatch):
    monkeypatch.setattr(build, "ghost_section", _boom(KeyError("landing")))
    with pytest.raises(KeyError):
        build.build_report(load_design("paper2016"), tmp_path / "r", quick=True)
    assert not (tmp_path / "r").exists()
