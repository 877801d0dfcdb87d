"""`report --quick` on every stamp preset and on a 600-dpi design (issue 21): no section
takes the report down with it, and the depth of field is judged at the design's own
resolution and says so."""

from __future__ import annotations

import json

import pytest

from opticalstamp.analysis.wavebase import fresnel_numbers
from opticalstamp.design import load_design, preset_names, scale_to_dpi, with_stack
from opticalstamp.design.resolution import dof_chart_dpi, output_pitch_um
from opticalstamp.report.build import build_report
from opticalstamp.report.section import not_measurable
from opticalstamp.units import dpi_of_pitch


def half_scale_prototype():
    """The prototype with every length halved: a 600-dpi stamp."""
    d = scale_to_dpi(load_design("paper2016"), 600)
    return with_stack(d, thicknesses_um=(500, 200, 225), name="paper2016-half")


def stamp_presets():
    return [n for n in preset_names() if not n.startswith("sla-") and n != "paper2016"]


@pytest.mark.parametrize("name", [*stamp_presets(), "half"])
def test_quick_report_on_every_design(name, tmp_path):
    d = half_scale_prototype() if name == "half" else load_design(name)
    data = build_report(d, tmp_path / "r", quick=True)
    assert (tmp_path / "r" / "index.html").is_file()
    saved = json.loads((tmp_path / "r" / "report.json").read_text())
    assert saved["rmtf"]["dof_dpi"] == dof_chart_dpi(d) == data["summary"]["dof_dpi"]
    page = (tmp_path / "r" / "index.html").read_text()
    assert f"{dof_chart_dpi(d):g}-dpi chart" in page
    if name == "half":
        assert dof_chart_dpi(d) == 400.0
        # the paper's statements only for the paper's own design
        assert "the paper's statement" not in page
    # the scans' charts at least twice the design's resolution (a 600-dpi design's
    # 400-dpi bars 3 chart pixels wide, not 1.5), the page saying at which
    raster = max(600.0, float(round(2 * dpi_of_pitch(output_pitch_um(d)))))
    assert saved["scans"]["raster_dpi"] == raster == (1200.0 if name == "half" else 600.0)
    assert f"Built-in charts at {raster:g} dpi" in page
    for row in saved["scans"]["sfr"]:  # measured, or said why not
        assert "not_measurable" in row or row["mtf50_cy_per_mm"] is not None
    # ray vs wave optics (issue 23) on every design (square holes), its verdict in the box
    rw = saved["ray_vs_wave"]
    assert not_measurable(rw) is None, rw
    v = rw["verdict"]
    assert v["fresnel_min"] == pytest.approx(min(f["fresnel_number"] for f in fresnel_numbers(d)))
    assert saved["summary"]["optics"] == v["text"]
    if name == "half":  # the 600-dpi copy: wave light +20.7 % over the rays' (docs/wave.md)
        assert v["fresnel_min"] < 0.3
        assert v["light_difference"] == pytest.approx(
            rw["wave"]["light_um2sr"] / rw["ray"]["light_um2sr"] - 1, rel=1e-12
        )
        assert v["light_difference"] > 0.15 and v["holds"] == "wave"
        # the headline figures come from the engine that holds (--optics auto, issue 23)
        assert saved["optics"]["engine"] == "wave" and saved["optics"]["asked"] == "auto"
        assert saved["rmtf"]["meta"]["optics"]["engine"] == "wave"
        assert saved["rmtf"]["method"] == "wave"
        assert saved["efficiency"]["own_method"] == "wave (in band)"
        assert saved["summary"]["headline_optics"] == saved["optics"]
        assert "are by wave optics" in page
