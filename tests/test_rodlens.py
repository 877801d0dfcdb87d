"""The rod-lens array: design rules, the tracer against closed forms, the analyses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from opticalstamp.analysis.efficiency import reference_etendue
from opticalstamp.analysis.rodlens import first_crossings, rod_contrast, rod_efficiency
from opticalstamp.design import DesignError, RodLensDesign, design_from_dict, load_design
from opticalstamp.raytrace.rodlens import direction_bound, geometry, trace_rod_rays, trace_rods

PRESETS = ("sla-1row-12deg", "sla-2row-20deg")


def rod(**array) -> RodLensDesign:
    base = dict(rows=1, rod_radius_um=200.0, core_radius_um=200.0, n0=1.6)
    base |= {"numerical_aperture": 0.3, "overlap": 1.5} | array
    if "rod_length_um" in array:
        base.pop("overlap")
    return design_from_dict(
        {"kind": "rod-lens-array", "wavelength_um": 0.55, "array": base}, "test"
    )


# -- the imaging condition --------------------------------------------------------------
@pytest.mark.parametrize("name", PRESETS)
def test_imaging_condition_formulas(name):
    d = load_design(name)
    a = d.array
    na = math.sin(math.radians(a.view_angle_deg))
    g = na / (a.n0 * a.core_radius_um)
    p = 2 * math.pi / g
    x0 = 2 * a.rod_radius_um * a.overlap
    z0 = p / math.pi * math.acos(-a.core_radius_um / x0)
    l0 = -math.tan(math.pi * z0 / p) / (a.n0 * g)
    assert a.g_per_um == pytest.approx(g, rel=1e-12)
    assert a.pitch_length_um == pytest.approx(p, rel=1e-12)
    assert a.length_um == pytest.approx(z0, rel=1e-12)
    assert a.working_um == pytest.approx(l0, rel=1e-12)
    assert a.conjugate_um == pytest.approx(z0 + 2 * l0, rel=1e-12)
    assert p / 2 < z0 < p  # between half a pitch and one pitch: erect image


@pytest.mark.parametrize("name", PRESETS)
def test_paraxial_ray_matrix_is_erect_unit_imaging(name):
    """Independent check: ABCD of air L0, rod Z0, air L0 has B = 0 and A = D = +1."""
    a = load_design(name).array
    ng = a.n0 * a.g_per_um
    t = a.g_per_um * a.length_um
    rod_m = np.array([[math.cos(t), math.sin(t) / ng], [-ng * math.sin(t), math.cos(t)]])
    air = np.array([[1.0, a.working_um], [0.0, 1.0]])
    m = air @ rod_m @ air
    assert m[0, 1] == pytest.approx(0.0, abs=1e-9 * a.working_um)
    assert m[0, 0] == pytest.approx(1.0, abs=1e-12)
    assert m[1, 1] == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize(
    ("array", "field"),
    [
        ({"numerical_aperture": 1.7}, "numerical_aperture"),
        ({"core_radius_um": 260.0, "rod_radius_um": 250.0}, "core_radius_um"),
        ({"overlap": 0.3}, "overlap"),  # X0 = 120 um < r0: acos(-r0/X0) undefined
        ({"rows": 3}, "rows"),
        ({"view_angle_deg": 12.0}, "exactly one of view_angle_deg"),
        ({"h4": -500.0}, "index profile"),
    ],
)
def test_bad_rod_designs_name_the_field(array, field):
    with pytest.raises(DesignError, match=field):
        rod(**array)


def test_unknown_kind_is_refused():
    with pytest.raises(DesignError, match="kind"):
        design_from_dict({"kind": "lens"}, "test")


def test_cover_glass_thicker_than_the_working_distance_is_refused():
    d = load_design("sla-1row-12deg").model_dump(mode="json")
    d["cover_glass"] = {"medium": 1.5, "thickness_um": 9000.0}
    with pytest.raises(DesignError, match="cover_glass"):
        design_from_dict(d, "test")


# -- the tracer against closed forms ------------------------------------------------------
@pytest.mark.parametrize("integrate", [False, True])
@pytest.mark.parametrize("pitches", [0.5, 0.8])
def test_accepted_phase_space_of_one_parabolic_rod(integrate, pitches):
    """Z0 >= P/2: every guided ray traces its whole orbit; etendue (2 pi^2 / 3) r0^2 NA^2."""
    r0, na = 200.0, 0.3
    p = 2 * math.pi * 1.6 * r0 / na
    d = rod(rod_length_um=pitches * p, working_distance_um=1e-6)
    d = design_from_dict(
        d.model_dump(mode="json") | {"sensor": {"pixel_pitch_um": 2 * r0}}, "test"
    )  # a square source over the one core the face can reach
    rays = trace_rods(d, [0.0], n_rays=1 << 20, seed=3, s_max=1.0, integrate=integrate)
    g = rays.w.sum() * rays.ray_etendue
    expected = 2 * math.pi**2 / 3 * r0**2 * na**2
    n_ok = rays.ledger["through"]
    assert g == pytest.approx(expected, rel=4 / math.sqrt(n_ok))


def test_point_near_axis_images_erect_at_unit_magnification():
    """Paraxially M = +1. The exact parabolic rod is not aberration-free: off axis
    beta = n(r) < n0 speeds the oscillation, so M - 1 grows as (g x0)^2."""
    d = rod()  # pure parabolic, working distance from the imaging condition
    dev = []
    for x0 in (2.0, 4.0, 8.0):
        rays = trace_rods(d, [x0], n_rays=1 << 14, seed=1, point=True, s_max=1e-4)
        assert rays.ledger["through"] > 1000
        assert np.ptp(rays.x) < 1e-3  # a point
        dev.append(np.mean(rays.x) / x0 - 1)
    assert 0 < dev[0] < 1e-3  # erect, unit magnification
    assert dev[1] / dev[0] == pytest.approx(4, rel=0.05)  # quadratic in x0
    assert dev[2] / dev[1] == pytest.approx(4, rel=0.05)


def test_integrator_matches_the_closed_form():
    d = rod(overlap=1.2)
    geo_c, closed = geometry(d)
    geo_i, closed_i = geometry(d, integrate=True)
    assert closed and not closed_i
    rng = np.random.default_rng(0)
    n = 20_000
    x = rng.uniform(-300, 300, n)
    y = rng.uniform(-100, 100, n)
    r = 0.3 * np.sqrt(rng.uniform(size=n))
    ph = rng.uniform(0, 2 * np.pi, n)
    sx, sy = r * np.cos(ph), r * np.sin(ph)
    outs = []
    for geo, c in ((geo_c, True), (geo_i, False)):
        o = [np.empty(n, np.int8)] + [np.empty(n) for _ in range(5)]
        trace_rod_rays(x, y, sx, sy, geo, c, False, *o)
        outs.append(o)
    (st_c, xc, *_), (st_i, xi, *_) = outs
    same = st_c == st_i
    assert same.mean() > 0.999  # only grazing rays may differ (radius checked per step)
    ok = same & (st_c == 0)
    assert ok.sum() > 1000
    assert np.abs(xc[ok] - xi[ok]).max() < 1e-3


def test_seed_determinism_and_chunk_invariance():
    """(Any thread count: tests/test_sampling.py, in a process with 4 threads.)"""
    d = load_design("sla-2row-20deg")
    pix = [0.0, 100.0, 250.0]
    a = trace_rods(d, pix, n_rays=50_000, seed=5, chunk=1 << 20)
    b = trace_rods(d, pix, n_rays=50_000, seed=5, chunk=7_777)
    c = trace_rods(d, pix, n_rays=50_000, seed=6)
    assert np.array_equal(a.ids, b.ids) and np.array_equal(a.x, b.x)
    assert not np.array_equal(a.ids, c.ids)


@pytest.mark.parametrize("name", PRESETS)
def test_direction_bound_loses_no_light(name):
    d = load_design(name)
    rays = trace_rods(d, np.linspace(0, 500, 16), n_rays=1 << 18, seed=2)
    s = np.hypot(rays.sx, rays.sy)
    assert s.max() < 0.9 * direction_bound(d)
    full = trace_rods(d, np.linspace(0, 500, 16), n_rays=1 << 20, seed=2, s_max=1.0)
    g_b, g_f = rays.etendue_per_pixel().mean(), full.etendue_per_pixel().mean()
    assert g_b == pytest.approx(g_f, rel=4 / math.sqrt(full.ledger["through"]) * 2)


def test_pixel_response_is_mirror_symmetric():
    d = load_design("sla-1row-12deg")
    rays = trace_rods(d, [120.0, 380.0], n_rays=1 << 19, seed=4)  # u and 2R - u
    g = rays.etendue_per_pixel()
    assert g[0] == pytest.approx(g[1], rel=0.03)


# -- analyses -----------------------------------------------------------------------------
def test_efficiency_against_the_f10_reference():
    d = load_design("sla-1row-12deg")
    e = rod_efficiency(d, n_rays=1 << 19)
    assert e.reference_etendue_um2sr == pytest.approx(reference_etendue(d.sensor.pixel_pitch_um))
    assert e.ratio == pytest.approx(e.etendue_um2sr / e.reference_etendue_um2sr)
    assert e.working_f_number == pytest.approx(10 / math.sqrt(e.ratio))
    assert e.etendue_se / e.etendue_um2sr < 0.005
    # upper bound: a pixel cannot collect more than its area times pi NA^2 per rod image,
    # times the number of rods that see it (about 2 m)
    a = d.array
    bound = d.sensor.width_um * d.sensor.height_um * math.pi * a.na**2 * 2 * a.overlap_degree
    assert 0 < e.etendue_um2sr < bound
    assert e.estimator == "trace"


def test_first_crossings_do_not_count_spurious_resolution():
    h = np.array([-2.0, -1.0, 0.0, 1.0, 2.0, 3.0])
    v = np.array([0.5, 0.1, 0.9, 0.1, 0.6, 0.7])  # comes back above 0.3 beyond the zero
    lo, hi, cl, ch = first_crossings(h, v, 0.3, lambda a, b: 0.5 * (a + b))
    assert (lo, hi, cl, ch) == (-0.5, 0.5, False, False)
    lo, hi, cl, ch = first_crossings(h, np.full(6, 0.9), 0.3, lambda a, b: 0.0)
    assert (lo, hi, cl, ch) == (-2.0, 3.0, True, True)


def test_contrast_peaks_at_focus_and_dof_brackets_it():
    d = load_design("sla-1row-12deg")
    c = rod_contrast(d, dpi=(200,), heights_mm=(-1.0, -0.5, 0.0, 0.5, 1.0), n_rays=1 << 19)
    row = np.array(c.contrast[0])
    assert row.argmax() == 2 and row[2] > 0.9
    assert c.dof_mm["low"] < 0 < c.dof_mm["high"]
    assert c.dof_mm["span"] == pytest.approx(c.dof_mm["high"] - c.dof_mm["low"])
    assert np.array(c.mtf[0]).max() == pytest.approx(c.mtf[0][2])


# -- the scan simulation of a rod-lens array ------------------------------------------------
def test_pixel_groups_cover_every_column_once():
    from opticalstamp.imaging.scan import pixel_groups

    d = load_design("sla-2row-20deg")
    groups = pixel_groups(d, 500)
    x = np.sort(np.concatenate([g.x_um for g in groups]))
    assert np.allclose(x, (np.arange(500) + 0.5) * d.sensor.pixel_pitch_um)
    assert all(g.delay == 0 for g in groups)


def test_rod_scan_is_sharp_at_focus_and_blurs_with_height():
    from opticalstamp.imaging.scan import simulate_scan

    d = load_design("sla-1row-12deg")
    doc = np.ones((80, 900), np.float32)
    cols = np.arange(30, 870, 17)
    doc[:, cols] = 0  # 42 um lines at 600 dpi, every phase on the rods
    widths = []
    for z in (0.0, 0.5, 1.0):
        r = simulate_scan(doc, 600, d, z_mm=z, noiseless=True)
        line = r.image[20]
        assert line.mean() == pytest.approx(doc.mean(), abs=0.01)  # light is conserved
        dark = 1 - line
        widths.append(np.count_nonzero(dark > 0.02))
        if z == 0.0:  # a 1:1 erect image: the 42 um line half-fills one 84.7 um pixel
            x = (np.arange(line.size) + 0.5) * d.sensor.pixel_pitch_um
            idx = [np.argmin(np.abs(x - (c + 0.5) * 25400 / 600)) for c in cols[1:-1]]
            mins = [line[i - 1 : i + 2].min() for i in idx]
            assert np.ptp(mins) < 0.05 and 0.4 < np.mean(mins) < 0.6
    assert widths[0] < widths[1] < widths[2]


def test_f10_reference_against_direct_integration():
    """G = double integral over pixel and pupil of cos(t1) cos(t2) / d^2 (parallel planes:
    h^2 / d^4), by Gauss quadrature in pixel x, y and pupil radius, angle: independent of
    the disk view-factor closed form the code uses."""
    pixel, h, a = 84.667, 20_000.0, 1_000.0  # um: 300-dpi pixel, 20 mm conjugate, 2 mm pupil
    t, wt = np.polynomial.legendre.leggauss(12)
    xs, wx = t * pixel / 2, wt * pixel / 2
    tr, wr = np.polynomial.legendre.leggauss(24)
    r, w_r = (tr + 1) * a / 2, wr * a / 2
    th = np.linspace(0, 2 * np.pi, 96, endpoint=False)
    w_th = 2 * np.pi / th.size
    px, py = np.meshgrid(xs, xs, indexing="ij")
    wp = np.outer(wx, wx)
    qx = (r[:, None] * np.cos(th)[None, :]).ravel()
    qy = (r[:, None] * np.sin(th)[None, :]).ravel()
    wq = (w_r[:, None] * r[:, None] * w_th * np.ones_like(th)[None, :]).ravel()
    d2 = (px.ravel()[:, None] - qx[None, :]) ** 2 + (py.ravel()[:, None] - qy[None, :]) ** 2
    g = np.sum(wp.ravel()[:, None] * wq[None, :] * h**2 / (h**2 + d2) ** 2)
    assert reference_etendue(pixel) == pytest.approx(g, rel=1e-9)
    # and the paraxial limit: pixel area x pi NA^2, NA = a / h
    assert g == pytest.approx(pixel**2 * math.pi * (a / h) ** 2, rel=5e-3)
