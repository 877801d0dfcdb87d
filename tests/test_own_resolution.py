"""Every default follows the design's own resolution (issue 21), and the depth of field
cannot be flipped by one noisy sample or a dip between samples (issue 28)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from opticalstamp.analysis.dof import depth_of_field, dof_bounds, dof_text, refine_points
from opticalstamp.analysis.lsf import traced_folded_lsf
from opticalstamp.analysis.rmtf import rmtf, rmtf_curves
from opticalstamp.design import load_design, replace, scale_to_dpi, with_stack
from opticalstamp.design.resolution import chart_dpis, dof_chart_dpi, nominal_dpi
from opticalstamp.studies.search import search_base
from opticalstamp.units import period_of_dpi


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def test_the_depth_of_field_chart_is_two_thirds_of_the_designs_resolution(paper):
    assert (nominal_dpi(paper), dof_chart_dpi(paper)) == (300.0, 200.0)
    assert chart_dpis(paper) == (100.0, 150.0, 200.0, 247.0)  # the paper's own charts
    d600, d1200 = scale_to_dpi(paper, 600), scale_to_dpi(paper, 1200)
    assert (nominal_dpi(d600), dof_chart_dpi(d600)) == (600.0, 400.0)
    assert (nominal_dpi(d1200), dof_chart_dpi(d1200)) == (1200.0, 800.0)
    assert chart_dpis(d600) == (200.0, 300.0, 400.0, 494.0)
    # a 1016-ppi fingerprint collimator (25 um pitch) is not rounded to 1025 or 1000
    fp = replace(
        paper,
        {
            "sensor.pixel_pitch_um": 12.5,
            "sensor.sensitive_width_um": 12.5,
            "sensor.sensitive_height_um": 12.5,
            "sensor.row_pitch_um": 50.0,
            "sensor.row_b_offset_x_um": 25.0,
            "sensor.row_b_offset_y_um": 25.0,
            "slabs.0.mask_top.size_um": 12.0,
            "slabs.1.mask_top.size_um": 12.0,
            "slabs.2.mask_top.size_um": 12.0,
        },
    )
    assert (nominal_dpi(fp), dof_chart_dpi(fp)) == (1016.0, 677.0)


def test_rmtf_of_a_600_dpi_design_is_judged_at_400_dpi(paper):
    d600 = scale_to_dpi(paper, 600)
    r = rmtf(d600, z_mm=(0.0, 0.25, 0.5), method="paraxial")
    assert r.dof_dpi == 400.0 and r.dpi == sorted(r.dpi) and 400.0 in r.dpi
    # charts the caller names stay, the depth-of-field chart joins them in order
    r = rmtf(d600, dpi=(600, 300), z_mm=(0.0, 0.5), method="paraxial")
    assert r.dpi == [300.0, 400.0, 600.0]


def test_search_keeps_the_designs_resolution(paper):
    d600 = scale_to_dpi(paper, 600)
    assert search_base(d600) is d600  # rescaled only when asked
    assert search_base(d600, 300.0).sensor.row_pitch_um == pytest.approx(169.333, abs=2e-3)


def test_a_dip_between_two_samples_is_found():
    """A synthetic RMTF curve: high, with a narrow dip below 0.3 between two samples that
    sit just above it (as the thin stack's 0.25-mm samples do); the refinement must put
    samples into the dip and the depth of field must be its first crossing."""

    def curve(z):
        return 0.9 - 0.479 * z - 0.15 * np.exp(-(((z - 1.08) / 0.03) ** 2))

    z = np.arange(0.0, 4.5001, 0.25)
    r, se = curve(z), np.full(z.size, 0.005)
    assert depth_of_field(z, r) > 1.25  # the grid misses the dip
    for _ in range(2):
        new = refine_points(z, r, se, 0.3)
        z = np.sort(np.concatenate([z, new]))
        r, se = curve(z), np.full(z.size, 0.005)
    zf = np.linspace(0, 4.5, 45001)
    truth = depth_of_field(zf, curve(zf))
    assert truth == pytest.approx(1.04, abs=0.02)
    assert depth_of_field(z, r) == pytest.approx(truth, abs=2e-3)


def test_dof_range_and_text():
    z = np.array([0.0, 1.0, 2.0, 3.0])
    r = np.array([0.9, 0.6, 0.31, 0.1])
    lo, hi = dof_bounds(z, r, np.full(4, 0.01))
    assert lo < depth_of_field(z, r) < hi
    res = {
        "dof_dpi": 200.0,
        "dof_mm": {"200": 0.0},
        "dof_threshold": 0.3,
        "rmtf_max": {"200": [0.2, 0.5]},
        "z_mm": [0.0, 1.0],
    }
    assert dof_text(res) == "0 mm (RMTF < 0.3 already at Z = 0 mm)"


def thin(paper):
    """Air 300 / glass 300 / glass 600 um, holes 30/30/36 um (about 43 % ghost light)."""
    return with_stack(paper, holes_um=(36, 30, 30), thicknesses_um=(600, 300, 300), name="thin")


def test_a_ghost_heavy_stack_has_one_depth_of_field_whatever_the_seed(paper):
    """The thin stack's RMTF oscillates with height (ghost copies of the periodic chart);
    on the 0.25-mm grid the oscillation aliases into a smooth curve. Every seed must find
    the same first crossing, within its stated range, as a fine grid does."""
    d = thin(paper)
    kw = dict(dpi=(200,), window_um=25380, shift_step_um=0.5, n_rays=1 << 20)
    dofs = []
    for seed in range(3):
        r = rmtf(d, seed=seed, **kw)
        dofs.append((r.dof_mm["200"], *r.dof_range_mm["200"]))
    fine = rmtf(d, z_mm=np.arange(0.0, 0.6001, 1 / 128), refine=0, **kw)
    truth = fine.dof_mm["200"]
    assert truth < 0.5  # the first dip, far before the grid's apparent crossing
    for v, lo, hi in dofs:
        assert lo - 0.01 <= truth <= hi + 0.01
        assert v == pytest.approx(truth, abs=0.02)


def test_shading_correction_removes_the_rows_white_difference(paper):
    """Misregistered layers make rows A and B collect different light; the scanner's
    shading correction divides each pixel by its own white, so scaling one row's light
    leaves the shading-corrected RMTF unchanged and moves the raw one."""
    d = with_stack(paper, offsets_um=[(0.0, -4.0), (6.0, 0.0), (0.0, 0.0)], name="mis")
    lsf = traced_folded_lsf(
        d, z_mm=(0.5, 2.0), periods_um=[period_of_dpi(200)], n_rays=1 << 18, seed=0
    )
    h = [a.copy() for a in lsf.h]
    h[0][1] *= 1.13  # row B 13 % brighter
    bright = type(lsf)(**{**lsf.__dict__, "h": h})
    for shading in (True, False):
        a = rmtf_curves(lsf, d, shading=shading)["max"]
        b = rmtf_curves(bright, d, shading=shading)["max"]
        if shading:
            np.testing.assert_allclose(a, b, rtol=1e-12)
        else:
            assert np.abs(a - b).max() > 0.01
    white = [h_row.sum(axis=(0, 2)) for h_row in lsf.h[0]]  # per row, per Z
    assert not np.allclose(white[0], white[1], rtol=1e-3)  # the rows differ ...
    res = rmtf(d, dpi=(200,), z_mm=(0.5, 2.0), n_rays=1 << 18, refine=0)
    assert res.shading  # ... and the scanner's line is shading-corrected by default


def test_rmtf_cli_names_the_rule(paper, tmp_path):
    from edges import run

    d600 = scale_to_dpi(paper, 600)
    path = tmp_path / "d600.toml"
    from opticalstamp.design import design_toml

    path.write_text(design_toml(d600))
    res = run(["rmtf", "-d", str(path), "--method", "paraxial", "--z", "0:1:0.5", "--json"])
    data = json.loads(res.stdout)
    assert data["dof_dpi"] == 400.0 and data["shading"]
    res = run(["rmtf", "-d", str(path), "--method", "paraxial", "--z", "0:1:0.5"])
    assert "400-dpi chart (2/3 of the design's 600 dpi)" in res.output


def test_a_row_off_the_sensors_lines_is_named(paper):
    from opticalstamp.design.describe import sensor_warnings

    assert sensor_warnings(paper) == []
    assert sensor_warnings(scale_to_dpi(paper, 600)) == []  # on the grid to 1 nm
    w = sensor_warnings(replace(paper, {"sensor.row_b_offset_y_um": 120.0}))
    assert len(w) == 2 and all("sensor.row_b_offset_y_um" in x for x in w)
    assert "sensor.lines" in w[1]


def test_text_crops_cut_no_letter():
    from opticalstamp.imaging.charts import clear_crop, text_chart

    doc, _ = text_chart(600.0, 6.0)
    f = 2.0  # a 300-dpi scan of a 600-dpi document
    rows, cols = clear_crop(doc, f, slice(20, 40), slice(10, 70))
    assert rows.start <= 20 and rows.stop >= 40 and cols.start <= 10 and cols.stop >= 70
    band = doc[int(rows.start * f) : int(rows.stop * f)]
    for c in (cols.start, cols.stop - 1):  # the edge columns hold no ink in these rows
        assert (band[:, int(c * f) : int((c + 1) * f)] >= 0.98).all()
    across = doc[:, int(cols.start * f) : int(cols.stop * f)]
    for r in (rows.start, rows.stop - 1):
        assert (across[int(r * f) : int((r + 1) * f)] >= 0.98).all()


def test_no_yield_headline_from_a_doubtful_estimator():
    from opticalstamp.report.summary import headline_figures

    data = {
        "ghosts": {"landing": {}},
        "rmtf": {"dof_dpi": 200.0, "dof_mm": {"200": 2.0}},
        "efficiency": {"ratio_own": 0.04, "working_f_number_own": 50.0},
        "tolerance": {"spec": "dof>=2", "yield": 0.5, "meta": {"nominal_disagrees": []}},
    }
    assert headline_figures(data)["yield"] == 0.5
    data["tolerance"]["meta"]["nominal_disagrees"] = ["dof_mm"]
    assert headline_figures(data)["yield"] is None
    data["tolerance"] = {"spec": "", "yield": None, "meta": {}}  # no spec: no yield
    assert headline_figures(data)["yield"] is None


def test_search_of_an_off_grid_600_dpi_design_keeps_it_and_warns_not(paper):
    """A half-scale prototype (225-um gap, off the search's 50-um steps) is searched at its
    own resolution, judged at 400 dpi, and its warm start joins the grid without an
    optuna warning (warnings are errors in the tests)."""
    from opticalstamp.studies.search import search_variants

    half = with_stack(scale_to_dpi(paper, 600), thicknesses_um=(500, 200, 225), name="half")
    (res,) = search_variants(
        half, population=4, generations=1, ghost_rays=1 << 14, workers=1
    ).values()
    assert res.meta["dof_dpi"] == 400.0 and res.dpi == 600.0
    assert res.reference["thicknesses_um"] == [500.0, 200.0, 225.0]


def test_rmtf_of_a_design_through_which_no_light_passes_says_so(paper, tmp_path):
    from edges import run
    from opticalstamp.design import design_toml

    dark = replace(
        paper,
        {"sensor.acceptance_half_angle_deg": 0.001, "slabs.1.mask_top.offset_x_um": 60.0},
    )
    path = tmp_path / "dark.toml"
    path.write_text(design_toml(dark))
    res = run(["rmtf", "-d", str(path), "--z", "0:1:0.5", "--rays", "65536"])
    assert "no light reaches the pixels" in res.output
