"""Back from a search (issue 12, item 4), the report on a design's own terms (item 2), the
paper-vs-model table (item 1), spurious resolution (item 6) and one vocabulary (item 9)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from edges import assert_clean_refusal, run
from opticalstamp.analysis.rmtf import depth_of_field, rmtf, spurious_ranges
from opticalstamp.design import design_toml, load_design, stack_params, with_stack
from opticalstamp.report.build import (
    is_paper_preset,
    report_work,
    tolerance_spec,
)
from opticalstamp.report.paper import paper_vs_model
from opticalstamp.report.summary import parse_report_spec
from opticalstamp.studies.evaluate import evaluate_design
from opticalstamp.studies.search import front_designs, search, verify_front
from opticalstamp.studies.tolerance import error_names, parse_spec
from opticalstamp.studies.verify import SURROGATE_ACCURACY, disagreements, exact_figures


@pytest.fixture(scope="module")
def small_search():
    d = load_design("paper2016")
    res = search(d, dpi=300.0, population=6, generations=2, seed=5, ghost_rays=1 << 15)
    return res, verify_front(res, ghost_rays=1 << 17, lsf_rays=1 << 17, workers=1)


def test_export_round_trips_to_the_same_objectives(small_search, tmp_path):
    """Every Pareto point written as a design file reads back as the same design, whose
    evaluation by the search's own estimator gives the recorded objectives exactly."""
    res, ver = small_search
    points = front_designs({res.base: ver}, ver.pareto)
    assert len(points) == len(ver.pareto) >= 1
    for p in points:
        path = tmp_path / f"{p['name']}.toml"
        path.write_text(design_toml(p["design"], tuple(p["provenance"])))
        back = load_design(str(path))
        assert back.fingerprint() == p["design"].fingerprint()
        assert back.name == p["name"] and "Pareto point" in back.description
        assert stack_params(back)["holes_um"] == p["row"]["holes_um"]
        assert stack_params(back)["thicknesses_um"] == p["row"]["thicknesses_um"]
        again = evaluate_design(back, dpi=200.0, near_mm=1.0, ghost_rays=1 << 15, seed=5)
        sur = p["row"]["surrogate"]
        assert again["efficiency_ratio"] == sur["efficiency_ratio"]
        assert again["dof_mm"] == sur["dof_mm"]
        assert again["ghost_fraction"] == sur["ghost_fraction"]
        text = path.read_text()
        assert text.startswith("# exported by opticalstamp")
        assert "exact tracer (figure of record)" in text


def test_verified_front_carries_exact_figures_of_record(small_search):
    """Each point's exact figures are those of its own design traced with the search's
    seed and chart; the figures that disagree and the exact domination count are those
    of its numbers; the base design is verified alike."""
    res, ver = small_search
    exact = [(r["efficiency_ratio"], r["dof_mm"]) for r in ver.pareto]
    for before, after, p in zip(res.pareto, ver.pareto, exact, strict=True):
        assert after["surrogate"]["dof_mm"] == before["dof_mm"]
        assert after["dof_mm"] == after["exact"]["dof_mm"]  # the figure of record
        assert after["efficiency_ratio"] == after["exact"]["efficiency_ratio"]
        assert after["estimator"].startswith("exact tracer")
        assert after["disagrees"] == disagreements(after["surrogate"], after["exact"])
        dominating = [q for q in exact if q[0] >= p[0] and q[1] >= p[1] and q != p]
        assert after["exact_dominated_by"] == len(dominating)
    first = ver.pareto[0]
    d = with_stack(ver.design, holes_um=first["holes_um"], thicknesses_um=first["thicknesses_um"])
    again = exact_figures(
        d, dpi=res.meta["dof_dpi"], near_mm=res.meta["near_mm"], ghost_rays=1 << 17,
        lsf_rays=1 << 17, seed=res.seed,
    )  # fmt: skip
    # the exact figures and the engine that gave them (ray optics in this search)
    assert again == {k: v for k, v in first["exact"].items() if k != "optics"}
    assert first["exact"]["optics"] == "ray"
    ref = ver.reference
    assert ref["surrogate"]["dof_mm"] == res.reference["dof_mm"]
    assert ref["dof_mm"] == ref["exact"]["dof_mm"] and ref["exact"]["efficiency_ratio"] > 0
    assert ref["disagrees"] == disagreements(ref["surrogate"], ref["exact"])
    assert ver.meta["surrogate_accuracy"]["dof_mm"] == SURROGATE_ACCURACY["dof_mm"]


def test_exact_figures_match_the_surrogate_on_the_prototype():
    """The prototype's ghost light lands >= 6 mm away, where the uniform background of
    the surrogate holds: the two agree within the stated accuracy."""
    d = load_design("paper2016")
    ex = exact_figures(d, ghost_rays=1 << 18, lsf_rays=1 << 18)
    sur = evaluate_design(d)
    assert disagreements(sur, ex) == []
    assert ex["efficiency_ratio"] == pytest.approx(0.0379, rel=0.01)
    assert not ex["near_ghost"] and ex["nearest_ghost_mm"] > 5


def test_disagreements_flag_beyond_the_stated_accuracy():
    base = {
        "dof_mm": 2.0,
        "efficiency_ratio": 0.04,
        "ghost_fraction": 0.1,
        "rmtf_at": {"1": 0.6},
        "near_ghost": False,
    }
    assert disagreements(base, base) == []
    off = base | {"dof_mm": 2.0 + SURROGATE_ACCURACY["dof_mm"] * 1.5}
    assert disagreements(off, base) == ["dof_mm"]
    # where ghost light is a large share the surrogate's stated accuracy is wider
    high = base | {"ghost_fraction": 0.5}
    assert disagreements(high | {"dof_mm": off["dof_mm"]}, high) == []
    assert "near_ghost" in disagreements(base, base | {"near_ghost": True})


def test_surrogate_depth_of_field_does_not_saturate():
    """A design whose RMTF stays above 0.3 past 4.5 mm gets its crossing, not 4.5."""
    d = with_stack(load_design("paper2016"), holes_um=(15, 29, 41), thicknesses_um=(150, 850, 900))
    r = evaluate_design(d)
    assert r["dof_mm"] > 4.6 and not r["dof_open_ended"]


def test_spurious_resolution_is_reported_not_counted():
    z = np.linspace(0, 5, 11)
    r = np.array([0.9, 0.8, 0.6, 0.4, 0.2, 0.05, 0.2, 0.35, 0.4, 0.31, 0.1])
    assert depth_of_field(z, r) == pytest.approx(1.5 + 0.5 * 0.1 / 0.2)
    # the ends are the interpolated crossings: up between 3.0 and 3.5, down past 4.5
    got = spurious_ranges(z, r)
    assert got == [[pytest.approx(3.0 + 0.5 * 0.1 / 0.15), pytest.approx(4.5 + 0.5 * 0.01 / 0.21)]]
    assert spurious_ranges(z[:-1], r[:-1]) == [[pytest.approx(3.0 + 0.5 * 0.1 / 0.15), 4.5]]
    assert spurious_ranges(z, np.linspace(1, 0.5, 11)) == []


def test_layers_and_slabs_numbered_from_the_object_side():
    d = load_design("paper2016")
    p = stack_params(d)
    assert p["holes_um"] == [48.0, 40.0, 40.0]  # layer 1 (object side) first
    assert p["thicknesses_um"] == [1000.0, 400.0, 450.0]  # slab 1 carries layer 1
    names = error_names(d)
    assert {"dx1", "dy3", "hole1", "slab1", "slab3", "tilt"} <= set(names)
    assert parse_spec("ghost_radius>=5") == [("ghost_radius", ">=", 5.0)]


def test_tolerance_spec_follows_the_report_spec():
    assert tolerance_spec(parse_report_spec("dof>=2.2,ghost_radius>=5,thickness<=3")) == (
        "dof>=2.2,ghost_radius>=5"
    )
    assert tolerance_spec(parse_report_spec("light>=0.03")) == "efficiency>=0.03"
    # no hidden specification: no yield where the user bounds none of its figures
    assert tolerance_spec(parse_report_spec("thickness<=3")) is None
    assert tolerance_spec([]) is None


def test_paper_sections_only_for_the_papers_presets():
    assert is_paper_preset(load_design("paper2016")) and is_paper_preset(load_design("fig1c"))
    mine = with_stack(load_design("paper2016"), holes_um=(52, 40, 40), name="mine")
    assert not is_paper_preset(mine)
    w = report_work(False, paper=False)
    assert not w.paper and any("paper's own sections" in x for x in w.left_out)
    w = report_work(True, z_mm=(0.0, 2.0, 6.3))
    assert w.z_mm == (0.0, 2.0, 6.3) and w.lsf_z_mm[-1] >= 6.3
    assert np.allclose(np.diff(w.lsf_z_mm), 0.5)


def test_paper_vs_model_rows_from_numbers():
    data = {
        "diffraction": {"geometric_edge_um": 31.9, "fraction_outside": {"0.4": 0.0697}},
        "spots": {
            "z_mm": [0.0, 2.0, 4.0],
            "fwhm_x_um": [82.0, 150.0, 220.0],
            "extent_x_um": [114.0, 245.0, 376.0],
            "meta": {"cell_um": 84.6},
        },
        "ghosts": {"landing": {"0": {"within_detector_um2sr": 0.0, "nearest_um": 6100.0}}},
        "rmtf": {"dof_dpi": 200.0, "dof_mm": {"200": 2.48}},
        "efficiency": {"ratio_own": 0.0379, "working_f_number_own": 51.4, "sensitive_area": []},
        "stack": [{"z_top_um": 2850.0}],
    }
    rows = {r["statement"]: r for r in paper_vs_model(data)}
    dof = next(r for r in rows.values() if r["statement"].startswith("depth of field"))
    assert dof["paper"] == 3.5 and dof["model"] == 2.48
    assert dof["ratio"] == pytest.approx(2.48 / 3.5)
    spot3 = next(r for r in rows.values() if "Z = 3 mm" in r["statement"])
    assert spot3["model"] == pytest.approx((245 + 0.5 * 131) / 84.6)
    rod = next(r for r in rows.values() if r["statement"] == "light vs a rod-lens array")
    assert rod["model"] is None and rod["model_text"] == "not computed"


@pytest.mark.slow
def test_cli_export_then_report_on_a_pareto_point(tmp_path):
    """search --export-designs -> report --quick on the exported point; a custom design's
    report leaves out the paper's sections and checks its spec."""
    out = tmp_path / "front"
    res = run(
        ["search", "--population", "6", "--generations", "1", "--workers", "1",
         "--export-designs", str(out), "--json"]
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    index = json.loads((out / "front.json").read_text())["points"]
    assert index and all((out / p["file"]).exists() for p in index)
    point = out / index[0]["file"]
    rep = tmp_path / "rep"
    res = run(
        ["report", "-d", str(point), "--quick", "-o", str(rep), "--spec",
         "dof>=2.2,ghost_radius>=5", "--z", "0,2,5", "--dpi", "150", "--json"]
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    data = json.loads((rep / "report.json").read_text())
    assert data["concepts"] is None and data["paper_vs_model"] is None
    assert data["rmtf"]["dof_dpi"] == 150.0 and data["rmtf"]["z_mm"][-1] >= 5.0
    assert sorted(data["ghosts"]["landing"]) == ["0", "2", "5"]
    # the verdict from the report's own numbers: DOF at 150 dpi and the nearest ghost
    dof = data["rmtf"]["dof_mm"]["150"]
    near = [v["nearest_um"] for v in data["ghosts"]["landing"].values() if v["nearest_um"]]
    radius = min(near) / 1000 if near else math.inf
    checks = {f["figure"]: f["check"]["pass"] for f in data["summary"]["figures"] if f["check"]}
    assert checks == {"dof": dof >= 2.2, "ghost_radius": radius >= 5}
    assert data["summary"]["meets_spec"] is (dof >= 2.2 and radius >= 5)
    html = (rep / "index.html").read_text()
    assert "The paper's Fig. 1 concepts</h3>" not in html
    assert "The paper against the model" not in html and "at Z = 0, 2, 5 mm" in html
    assert "Verdict" in html


def test_cli_report_refuses_bad_options(tmp_path):
    for args, name in (
        (["report", "--paper-sections", "maybe"], "--paper-sections"),
        (["report", "--z", "0,-1"], "--z"),
        (["report", "--dpi", "10"], "--dpi"),
    ):
        res = run([*args, "-o", str(tmp_path / "r")])
        assert_clean_refusal(res, (name,), tmp_path)


@pytest.mark.parametrize("holes", [(48, 40, 40), (60, 48, 48), (70, 40, 40)])
def test_crossings_refined_as_on_a_fine_grid(holes):
    """The depth of field and the spurious ranges found on the 0.25 mm grid with the
    refinement equal those on a grid 8 times finer (closed form: no noise), including a
    spurious range (70/40/40, 300 dpi, threshold 0.1: 1.78-1.88 mm) narrower than the
    grid step; without the refinement that range is missed."""
    d = with_stack(load_design("paper2016"), holes_um=holes)
    kw = {"method": "paraxial", "dpi": (150, 200, 247, 300), "dof_threshold": 0.1}
    z = np.arange(0, 6.01, 0.25)
    got = rmtf(d, z_mm=z, refine=8, **kw)
    fine = rmtf(d, z_mm=np.arange(0, 6.001, 0.25 / 8), refine=0, **kw)
    coarse = rmtf(d, z_mm=z, refine=0, **kw)
    assert got.z_mm == coarse.z_mm and got.rmtf_max == coarse.rmtf_max  # the grid as given
    for k in fine.dof_mm:
        assert got.dof_mm[k] == pytest.approx(fine.dof_mm[k], abs=1e-9)
        assert len(got.spurious_mm[k]) == len(fine.spurious_mm[k])
        for a, b in zip(got.spurious_mm[k], fine.spurious_mm[k], strict=True):
            assert a == pytest.approx(b, abs=1e-9)
    if holes == (70, 40, 40):
        assert fine.spurious_mm["300"] and not coarse.spurious_mm["300"]
