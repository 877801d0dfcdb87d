"""`compare --optics`: each stamp's light, contrast and depth of field by the engine asked
for (auto: each by its own validity rule), the row saying which; circles' ray-vs-wave
figures by the 2-D path where wave optics is asked for."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from opticalstamp.analysis.efficiency import efficiency
from opticalstamp.analysis.raywave import NEEDS_RECTANGLES
from opticalstamp.cli import app
from opticalstamp.design import load_design, with_hole_shape
from opticalstamp.report.compare import engine_cell
from opticalstamp.studies import compare as cmp


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def test_a_stamps_figures_follow_the_optics_asked_for(paper):
    """With wave optics the row's light is the wave engine's (efficiency by wave optics,
    own-path signal over F/10), its optics says wave, and it differs from the ray row's
    (the prototype's Fresnel numbers are near 1: diffraction adds about 10 % of light)."""
    wave = cmp.evaluate_stamp(paper, optics="wave")
    ray = cmp.evaluate_stamp(paper, optics="ray")
    assert wave["optics"]["engine"] == "wave" and ray["optics"]["engine"] == "ray"
    eff = efficiency(paper, area_scales=(1.0,), z_mm=(0.0,), optics="wave")
    assert wave["light_vs_f10"] == eff.ratio_own
    assert abs(wave["light_vs_f10"] / ray["light_vs_f10"] - 1) > 0.03
    assert engine_cell(wave) == "wave (asked for)" and engine_cell(ray) == "ray (asked for)"
    # one ghost fraction whatever the light's optics: the traced ghost light over all the
    # traced light (as `ghosts` and the report), the wave row saying so and giving its far share
    g = eff.etendue_ghost_um2sr
    assert wave["ghost_fraction"] == pytest.approx(g / (eff.etendue_own_traced_um2sr + g))
    assert wave["ghost_fraction"] == pytest.approx(ray["ghost_fraction"], rel=0.05)
    assert "by ray optics as `opticalstamp ghosts`" in wave["ghost_note"]
    far = 1 - eff.etendue_own_um2sr / eff.etendue_um2sr
    assert f"the far ghosts, is {far:.3g} of all light" in wave["ghost_note"]
    assert "wave optics" not in ray["ghost_note"]


def test_circles_wave_figures_only_where_wave_optics_is_asked_for(paper, monkeypatch):
    """Circular holes take the wave engine's 2-D path (minutes a height on a CPU): with
    ray or auto optics their ray-vs-wave entry says why it is missing, with wave optics
    the comparison is run."""
    circ = with_hole_shape(paper, "circle")
    called = []

    def judged(design, *a, **kw):
        called.append(design.name)
        raise ValueError("no ray light to compare with")  # stops before the 2-D path

    monkeypatch.setattr(cmp, "compare_and_judge", judged)
    for optics in ("ray", "auto"):
        assert cmp.wave_figures(circ, optics=optics)["wave"] == {"not_measurable": NEEDS_RECTANGLES}
    assert called == []
    got = cmp.wave_figures(circ, optics="wave")
    assert called == [circ.name] and "no ray light" in got["wave"]["not_measurable"]


def test_engine_cell_names_auto_and_the_rod_tracer():
    assert engine_cell({"kind": "stamp", "optics": {"asked": "auto", "engine": "wave"}}) == (
        "wave (auto)"
    )
    assert engine_cell({"kind": "rod-lens-array"}) == "rod-lens tracer"


def test_bad_optics_is_refused_naming_the_option(tmp_path):
    res = CliRunner().invoke(app, ["compare", "paper2016", "fig1b", "--optics", "geometric", "-o",
                       str(tmp_path / "c")])  # fmt: skip
    assert res.exit_code == 2 and "optics" in res.output and not (tmp_path / "c").exists()
