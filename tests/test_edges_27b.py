"""Bad input at the edges, issue 27 (second group): degenerate geometry, long mask lines and
two-level images. Each case ends with a correct answer or a clean refusal (exit 2, the
field or file and the rule named, no traceback, no file left behind)."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from edges import assert_clean_refusal, run, to_toml
from helpers import preset_dict
from opticalstamp.design import DesignError, design_from_dict, load_design
from opticalstamp.design.model import MIN_LENGTH_UM


def _design(tmp_path, d: dict, name: str = "d.toml"):
    f = tmp_path / name
    f.write_text(to_toml(d))
    return f


def _gap(value: float) -> dict:
    d = preset_dict("paper2016")
    d["reference_gap"]["thickness_um"] = value
    return d


def _clean_exit(res):
    """Exit 0, no traceback."""
    assert res.exit_code == 0, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in res.output


# -- lengths below what the model honours: refused at load time, the field named -----------
TOO_SHORT = [
    (("slabs", 1, "thickness_um"), 1e-300),
    (("slabs", 0, "thickness_um"), 0.05),
    (("slabs", 2, "mask_top", "size_um"), 1e-300),
    (("sensor", "sensitive_width_um"), 1e-300),
    (("sensor", "sensitive_height_um"), 0.09),
    (("reference_gap", "thickness_um"), 1e-300),
    (("reference_gap", "thickness_um"), 0.05),
]


@pytest.mark.parametrize(("path", "value"), TOO_SHORT)
def test_lengths_below_the_floor_are_refused_naming_the_field(tmp_path, path, value):
    d = preset_dict("paper2016")
    node = d
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    field = ".".join(str(p) for p in path)
    with pytest.raises(DesignError, match=field.replace(".", r"\.") + ".*at least 0.1"):
        design_from_dict(d)
    f = _design(tmp_path, d)
    res = run(["ghosts", "-d", f, "--rays", 1000])
    assert_clean_refusal(res, field, tmp_path, [f.name])
    if path[0] == "slabs":  # the slab as the user counts it, as every design error does
        assert "counted from the sensor" in res.output


def test_the_floor_itself_is_accepted():
    d = preset_dict("paper2016")
    d["slabs"][0]["thickness_um"] = MIN_LENGTH_UM
    d["slabs"][2]["mask_top"]["size_um"] = MIN_LENGTH_UM
    d["sensor"]["sensitive_width_um"] = MIN_LENGTH_UM
    d["reference_gap"]["thickness_um"] = MIN_LENGTH_UM
    design_from_dict(d)


# -- a reference gap of 0 is a design: the document on the top mask ---------------------------
@pytest.mark.parametrize("zero", [0, -0.0])
def test_zero_reference_gap_runs_ghosts(tmp_path, zero):
    d = design_from_dict(_gap(zero))
    assert d.reference_gap.thickness_um == 0 and math.copysign(1, d.reference_gap.thickness_um) > 0
    res = run(["ghosts", "-d", _design(tmp_path, _gap(zero)), "--rays", 100_000])
    _clean_exit(res)
    assert "own-path etendue" in res.output


def test_zero_gap_diffraction_budget_is_the_limit():
    """The source in the top hole's plane (R1 = 0) casts no shadow: nothing outside it,
    all of it outside the next layer's hole; just above, the budget tends to that."""
    from opticalstamp.analysis.diffraction import diffraction_budget, geometric_optics_warnings

    d = design_from_dict(_gap(0.0))
    b = diffraction_budget(d, z_mm=0.0, wavelengths_um=(0.55,))
    top = b["layers"][0]
    assert top["r1_um"] == 0 and top["geometric_edge_um"] == math.inf
    assert top["outside_shadow"]["0.55"] == 0.0 and top["outside_next"]["0.55"] == 1.0
    near = diffraction_budget(d, z_mm=1e-6, wavelengths_um=(0.55,))["layers"][0]
    assert near["outside_shadow"]["0.55"] < 1e-3
    assert near["outside_next"]["0.55"] > 0.999
    assert geometric_optics_warnings(d) == []  # no ZeroDivisionError on loading it


def test_diffraction_with_the_source_in_the_slit_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = run(["diffraction", "--gap-um", 0, "--z", 0])
    assert_clean_refusal(res, "--gap-um", tmp_path, [])
    assert "R1 = 0" in res.output
    f = _design(tmp_path, _gap(0.0))
    res = run(["diffraction", "-d", f, "--z", 0])
    assert_clean_refusal(res, "reference_gap.thickness_um", tmp_path, [f.name])
    _clean_exit(run(["diffraction", "-d", f, "--z", 1]))
    _clean_exit(run(["diffraction", "-d", f, "--z", 0, "--gap-um", 500]))


def test_zero_gap_paraxial_model_is_continuous_at_z0():
    """A mask in the object plane bounds U to its hole whatever the slope: the paraxial
    profile at Z = 0 is the limit of Z -> 0+ (it was a division by zero)."""
    from opticalstamp.analysis.paraxial import (
        paraxial_cumulative,
        paraxial_etendue_1d,
        paraxial_support,
    )

    d = design_from_dict(_gap(0.0))
    u = np.linspace(-40.0, 40.0, 81)
    for axis in (0, 1):
        lo, hi = paraxial_support(d, 0.0, axis)
        assert (lo, hi) == pytest.approx((-24.0, 24.0))  # the 48 um top hole
        c0 = paraxial_cumulative(d, 0.0, u, axis)
        c1 = paraxial_cumulative(d, 1e-9, u, axis)
        assert np.allclose(c0, c1, rtol=1e-6, atol=1e-9)
        assert c0[-1] == pytest.approx(paraxial_etendue_1d(d, axis), rel=1e-12)
    base = load_design("paper2016")
    assert paraxial_etendue_1d(d, 0) == pytest.approx(paraxial_etendue_1d(base, 0), rel=1e-12)


def test_zero_gap_rmtf_and_scan_at_z0(tmp_path):
    from opticalstamp.analysis.rmtf import rmtf
    from opticalstamp.imaging.scan import ScanSettings, simulate_scan

    d = design_from_dict(_gap(0.0))
    r = rmtf(d, z_mm=(0.0, 3.0), method="paraxial", dpi=(200.0,), dof_dpi=200.0)
    assert np.all(np.isfinite(r.rmtf_max["200"]))
    assert r.rmtf_max["200"][0] > r.rmtf_max["200"][1]  # sharpest on the mask
    doc = np.ones((24, 24), np.float32)
    doc[:, :12] = 0.1
    s = simulate_scan(doc, 300.0, d, z_mm=0.0, settings=ScanSettings(kernel_rays=1 << 14))
    assert np.isfinite(s.image).all()


def test_zero_gap_psf_at_z0_is_unbiased():
    """An object point on the top mask: importance sampling aims at the next mask (the top
    one is met at the source point itself) and agrees with plain Lambertian sampling."""
    from opticalstamp.raytrace.launch import launch
    from opticalstamp.raytrace.sampling import Source
    from opticalstamp.raytrace.stack import forward_path

    d = design_from_dict(_gap(0.0))
    path = forward_path(d, 0.0)
    est = []
    for importance, n in ((True, 1 << 18), (False, 1 << 22)):
        s1 = s2 = 0.0
        for b in launch(path, Source(0.0, 0.0), n, 7, importance=importance):
            s1 += float(b.w.sum())
            s2 += float((b.w**2).sum())
        m = s1 / n
        est.append((m, math.sqrt((s2 / n - m * m) / n)))
    (a, sa), (b, sb) = est
    assert np.isfinite(a) and a > 0
    assert abs(a - b) < 4 * math.hypot(sa, sb)
    # on the chrome between holes no light leaves the point
    blocked = sum(
        float(x.w.sum()) for x in launch(path, Source(30.0, 0.0), 1 << 14, 7, importance=True)
    )
    assert blocked == 0.0


# -- no light reaches the pixel: a statement and a bound, not a row of zeros ----------------
def _dark(acceptance_deg: float, bottom_offset_um: float = 0.0, top_offset_um: float = 60.0):
    d = preset_dict("paper2016")
    d["sensor"]["acceptance_half_angle_deg"] = acceptance_deg
    d["slabs"][2]["mask_top"]["offset_x_um"] = top_offset_um
    d["slabs"][0]["mask_top"]["offset_x_um"] = bottom_offset_um
    return d


def test_no_light_found_is_stated_with_a_bound(tmp_path):
    from opticalstamp.analysis.ghosts import analyse_ghosts

    d = design_from_dict(_dark(1.0))
    g = analyse_ghosts(d, n_rays=1 << 16)
    assert g.etendue_own_um2sr == 0 and g.etendue_ghost_um2sr == 0
    assert 0 < g.own_etendue_bound < 0.1  # rule of three: about 3 w_max / n
    res = run(["ghosts", "-d", _design(tmp_path, _dark(1.0)), "--rays", 1 << 16])
    _clean_exit(res)
    assert "no light found reaching this pixel" in res.output
    assert "own-path etendue   0" not in res.output and "ghost fraction" not in res.output
    assert "95 % bound" in res.output


def test_no_accepted_ray_reaches_a_hole_stops_at_once():
    """Where no ray inside the acceptance cone reaches any hole of the first mask, the
    etendue is exactly 0: the adaptive run stops at its first check."""
    from opticalstamp.analysis.ghosts import FIRST_CHECK, analyse_ghosts

    d = design_from_dict(_dark(0.5, bottom_offset_um=60.0, top_offset_um=0.0))
    g = analyse_ghosts(d)
    assert g.own_etendue_bound == 0.0 and g.n_rays == FIRST_CHECK
    assert g.etendue_own_um2sr == 0 and g.etendue_ghost_um2sr == 0


def test_efficiency_of_no_light_is_zero_not_a_division_by_zero():
    from opticalstamp.analysis.efficiency import efficiency
    from opticalstamp.analysis.ghosts import analyse_ghosts

    d = design_from_dict(_dark(1.0))
    g = analyse_ghosts(d, n_rays=1 << 14)
    r = efficiency(d, ghosts=g, area_scales=(1.0,))
    assert r.ratio == 0 and r.working_f_number == math.inf
    assert math.isnan(r.sensitive_area[0]["gain_vs_design"])


def test_a_front_point_with_no_exact_light_is_flagged_not_divided_by():
    """The search's exact check of a Pareto point that finds no own-path light (a 5-mask
    stack of small holes): the surrogate's light is flagged; the pages write 0, not 1/0."""
    from opticalstamp.report.paper import one_in
    from opticalstamp.studies.verify import disagreements

    exact = {"ghost_fraction": 0.0, "dof_mm": 3.0, "efficiency_ratio": 0.0, "rmtf_at": {}}
    sur = exact | {"efficiency_ratio": 1e-4}
    assert "efficiency_ratio" in disagreements(sur, exact)
    assert "efficiency_ratio" not in disagreements(exact, exact)
    assert one_in(0.0) == "0"


def test_no_light_in_the_efficiency_page_figure_and_signal():
    from opticalstamp.analysis.efficiency import efficiency, ratio_text
    from opticalstamp.analysis.ghosts import analyse_ghosts
    from opticalstamp.imaging.sensor import signal_budget
    from opticalstamp.io.files import to_json
    from opticalstamp.report.html.light import efficiency_html
    from opticalstamp.report.plotting import plot_efficiency

    d = design_from_dict(_dark(1.0))
    r = efficiency(d, ghosts=analyse_ghosts(d, n_rays=1 << 14), area_scales=(1.0,))
    assert "<table>" in efficiency_html(json.loads(to_json(r.to_dict())))
    plot_efficiency(r)
    assert [ratio_text(v) for v in (0.0, 0.038, 87.8)] == ["0", "1/26.3", "87.8×"]
    sg = signal_budget(d.electronics, 0.0)
    assert sg["electrons_white"] == 0 and sg["exposure_for_target_ms"] == math.inf
    assert sg["max_line_rate_for_target_hz"] == 0 and not sg["saturates_at_target"]


# -- a stack far thinner than its holes: maps on coarser bins, the tracer for the scan ------
def _thin() -> dict:
    d = preset_dict("paper2016")
    for s in d["slabs"]:
        s["thickness_um"] = MIN_LENGTH_UM
    return d


def test_thin_stack_maps_fit_and_the_scan_traces():
    from opticalstamp.analysis.maps import traced_maps
    from opticalstamp.analysis.paraxial import PARAXIAL_MAX_SLOPE, paraxial_max_slope
    from opticalstamp.analysis.spots import spots
    from opticalstamp.defaults import MAP_MAX_BINS
    from opticalstamp.imaging.kernels import kernel_source

    d = design_from_dict(_thin())
    m = traced_maps(d, z_mm=[1.0], n_rays=1 << 14)  # was 996 TiB (slabs of 1e-3 um)
    assert max(m.own.shape[1:]) <= MAP_MAX_BINS + 1 and m.fine_bin_um > 4.0
    assert np.isfinite(m.own).all() and m.own.sum() > 0
    s = spots(d, z_mm=(0.0, 1.0), n_rays=1 << 14)
    assert all(max(sp.map_sr.shape) <= MAP_MAX_BINS + 1 for sp in s.spots)
    # the paraxial closed form is no stand-in for such a stack: its etendue has no bound
    assert paraxial_max_slope(d) > PARAXIAL_MAX_SLOPE
    assert kernel_source(d) == "trace"
    proto = load_design("paper2016")
    assert paraxial_max_slope(proto) == pytest.approx(0.033, abs=1e-3)
    assert kernel_source(proto) == "paraxial"


# -- any design that loads runs ghosts, rmtf and a scan (property-based) --------------------
def _log_uniform(lo: float, hi: float):
    return st.floats(math.log10(lo), math.log10(hi)).map(lambda e: round(10.0**e, 6))


@settings(
    max_examples=int(os.environ.get("OPTICALSTAMP_EDGE_EXAMPLES", "15")),
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)
@given(
    thick=st.lists(_log_uniform(MIN_LENGTH_UM, 5000.0), min_size=3, max_size=3),
    holes=st.lists(_log_uniform(MIN_LENGTH_UM, 160.0), min_size=3, max_size=3),
    sensitive=_log_uniform(MIN_LENGTH_UM, 42.3),
    gap=st.one_of(st.just(0.0), _log_uniform(MIN_LENGTH_UM, 10_000.0)),
)
def test_any_loadable_design_runs(thick, holes, sensitive, gap):
    from opticalstamp.analysis.ghosts import analyse_ghosts
    from opticalstamp.analysis.rmtf import rmtf
    from opticalstamp.imaging.scan import ScanSettings, simulate_scan

    d = preset_dict("paper2016")
    for s, t, h in zip(d["slabs"], thick, holes, strict=True):
        s["thickness_um"] = t
        s["mask_top"]["size_um"] = h
    d["sensor"]["sensitive_width_um"] = d["sensor"]["sensitive_height_um"] = sensitive
    d["reference_gap"]["thickness_um"] = gap
    try:
        design = design_from_dict(d)
    except DesignError:  # refused at load time (overlapping holes): the other way out
        return
    g = analyse_ghosts(design, n_rays=1 << 14, z_mm=(0.0, 1.0))
    assert g.etendue_own_um2sr >= 0 and np.isfinite(g.etendue_own_um2sr)
    assert g.etendue_own_um2sr > 0 or g.own_etendue_bound is not None
    for method in ("paraxial", "trace"):
        r = rmtf(design, z_mm=(0.0, 1.0), method=method, n_rays=1 << 14, dpi=(200.0,))
        assert np.all(np.isfinite(r.rmtf_max["200"]))
    doc = np.ones((16, 16), np.float32)
    doc[:, :8] = 0.1
    s = simulate_scan(doc, 300.0, design, z_mm=0.5, settings=ScanSettings(kernel_rays=1 << 14))
    assert np.isfinite(s.image).all()


# -- mask artwork: rows longer than a GDSII array, lines longer than its coordinates --------
def _line(n: int, pitch: float = 42.3) -> dict:
    d = preset_dict("paper2016")
    d["sensor"] |= {"row_pitch_um": pitch, "rows": 1, "pixels_per_row": n}
    d["slabs"][2]["mask_top"]["size_um"] = 40.0  # holes below the 42.3 um pitch
    return d


@pytest.mark.parametrize("fmt", ["gds", "dxf"])
def test_rows_longer_than_an_array_reference_read_back_hole_for_hole(tmp_path, fmt):
    db = pytest.importorskip("klayout.db", reason="KLayout's Python module (the test extra)")
    from opticalstamp.io.artwork import MAX_ARRAY

    n = 40_000
    f = _design(tmp_path, _line(n))
    out = tmp_path / f"m.{fmt}"
    res = run(["masks", f, "-o", out])
    _clean_exit(res)
    ly = db.Layout()
    ly.read(str(out))
    top = ly.top_cell()
    if fmt == "gds":  # two references a row (32,767 + 7,233), each a regular array
        counts = sorted(i.na * i.nb for i in top.each_inst())
        assert counts == [n - MAX_ARRAY] * 3 + [MAX_ARRAY] * 3
    layers = 0
    for li in ly.layer_indexes():
        info = ly.get_info(li)
        if info.layer not in (1, 2, 3) or info.datatype != 0:  # marks, DXF's own layers
            continue
        layers += 1
        xs = []
        it = top.begin_shapes_rec(li)
        while not it.at_end():
            if not it.shape().is_text():
                xs.append(it.shape().bbox().transformed(it.trans()).center().x)
            it.next()
        xs = np.sort(np.array(xs))  # database units: 1 nm
        assert xs.size == n
        assert np.all(np.diff(xs) == 42_300)  # the pitch exactly, across the joins too
        assert xs[0] == -(n // 2) * 42_300
    assert layers == 3


@pytest.mark.parametrize(("n", "pitch"), [(1_000_000, 169.2), (40_000, 169.2)])
def test_lines_beyond_gdsii_coordinates_are_refused(tmp_path, n, pitch):
    f = _design(tmp_path, _line(n, pitch) | {"name": "long"})
    for fmt in ("gds", "dxf"):
        res = run(["masks", f, "-o", tmp_path / f"m.{fmt}"])
        assert_clean_refusal(res, "sensor.pixels_per_row", tmp_path, [f.name])
        assert "sensor.row_pitch_um" in res.output and "2.147 m" in res.output


def test_the_longest_line_that_fits():
    from opticalstamp.design.variants import replace
    from opticalstamp.io.artwork import ArtworkError, check_extent

    d = load_design("paper2016")
    check_extent(replace(d, {"sensor.pixels_per_row": 25_368}))
    with pytest.raises(ArtworkError, match="at most 25,368 holes"):
        check_extent(replace(d, {"sensor.pixels_per_row": 25_369}))


# -- images: two grey levels hold no SFR; an MTF50 not reached is said so -------------------
def _edge(path, sigma_px: float, levels=None, mode="I;16"):
    from PIL import Image
    from scipy.special import erf

    n = 120
    y, x = np.mgrid[0:n, 0:n] + 0.5
    x0 = 60 + (y - 60) * math.tan(math.radians(5))
    v = 0.1 + 0.8 * 0.5 * (1 + erf((x - x0) / (sigma_px * math.sqrt(2))))
    if mode == "1":
        Image.fromarray(v > 0.5).convert("1").save(path, dpi=(600, 600))
    else:
        Image.fromarray((v * 65535).astype(np.uint16)).save(path, dpi=(600, 600))
    return path


@pytest.mark.parametrize("direction", ["auto", "both"])
def test_sfr_of_a_one_bit_image_is_refused(tmp_path, direction):
    f = _edge(tmp_path / "edge1.tif", 1.5, mode="1")
    res = run(["sfr", f, "--direction", direction, "--plot", tmp_path / "s.png"])
    assert_clean_refusal(res, "edge1.tif", tmp_path, [f.name])
    assert "two grey levels" in res.output


def test_sfr_of_a_thresholded_8bit_image_is_refused():
    from opticalstamp.imaging.measure import sfr

    img = np.where(np.arange(64)[None, :] + 0.1 * np.arange(64)[:, None] > 30, 0.9, 0.1)
    with pytest.raises(ValueError, match="two grey levels"):
        sfr(img, 600.0)


def test_sfr_says_mtf50_is_not_reached(tmp_path):
    sharp = _edge(tmp_path / "sharp.tif", 0.1)
    res = run(["sfr", sharp])
    _clean_exit(res)
    assert "MTF50 not reached" in res.output and "nan" not in res.output
    data = json.loads(run(["sfr", sharp, "--json"]).output)
    assert data["mtf50_cy_per_mm"] is None and data["mtf50_reached"] is False
    soft = run(["sfr", _edge(tmp_path / "soft.tif", 1.5), "--json"])
    data = json.loads(soft.output)
    assert data["mtf50_reached"] is True and data["mtf50_cy_per_mm"] > 0
