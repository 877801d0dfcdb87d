"""The ray kernel against closed forms: plate shift, Snell, TIR, view factors, Fresnel."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from helpers import (
    Tally,
    assert_agree,
    parallel_rectangles_etendue,
    preset_dict,
    quadrature_etendue,
)
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.design import design_from_dict, load_design
from opticalstamp.raytrace.kernel import ABSORBED, ESCAPED, TIR, TRANSMITTED
from opticalstamp.raytrace.launch import launch, trace_rays
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.sampling import Source, site_index
from opticalstamp.raytrace.stack import Lattice, Path, forward_path, reverse_path
from opticalstamp.raytrace.tally import is_own_path, object_plane

SETTINGS = settings(deadline=None, max_examples=60)


def open_path(thickness, index, index_out=None) -> Path:
    """A stack of unmasked slabs (no aperture anywhere), plates wide enough never to escape."""
    thickness = np.asarray(thickness, dtype=np.float64)
    index = np.asarray(index, dtype=np.float64)
    slabs = np.column_stack([thickness, index, np.full(thickness.size, -1.0)])
    lattice = Lattice(pitch=1e6, k_lo=0, k_hi=0, row_x=np.zeros(2), row_y=np.zeros(2), n_rows=1)
    return Path(
        slabs,
        float(index[-1] if index_out is None else index_out),
        np.zeros((0, 5)),
        lattice,
        np.array([1e15, 1e15]),
        np.cumsum(thickness),
        (),
    )


def one_hole_design(gap_um: float, hole: dict) -> dict:
    """A single air gap above the pixel, one mask on top, reference plane on the mask."""
    return {
        "name": "one-hole",
        "slabs": [{"medium": "air", "thickness_um": gap_um, "mask_top": hole}],
        "reference_gap": {"thickness_um": 0.0},
    }


# -- (a) lateral shift through plates -------------------------------------------------------
@pytest.mark.parametrize("theta_deg", [0.0, 5.0, 30.0, 60.0, 85.0])
def test_plate_displacement_textbook(theta_deg):
    # Beam displacement by a tilted plate (thickness t, index n) in air:
    # D = t sin(theta) (1 - cos(theta) / sqrt(n^2 - sin^2(theta))), perpendicular to the ray.
    t, n, phi = 1000.0, 1.52, math.radians(30.0)
    path = open_path([300.0, t, 200.0], [1.0, n, 1.0])
    th = math.radians(theta_deg)
    s = math.sin(th)
    x0, y0 = 12.5, -7.0
    res = trace_rays(path, [x0], [y0], s * math.cos(phi), s * math.sin(phi))
    assert res.status[0] == TRANSMITTED
    undeviated = 1500.0 * math.tan(th)
    actual = math.hypot(res.x[0] - x0, res.y[0] - y0)
    if theta_deg:  # the ray stays in its plane of incidence
        assert math.atan2(res.y[0] - y0, res.x[0] - x0) == pytest.approx(phi)
    expected = t * s * (1 - math.cos(th) / math.sqrt(n * n - s * s))
    assert (undeviated - actual) * math.cos(th) == pytest.approx(expected, rel=1e-9, abs=1e-9)


slab_lists = st.lists(
    st.tuples(st.floats(1.0, 3000.0), st.floats(1.0, 2.0)), min_size=1, max_size=5
)


@SETTINGS
@given(
    slabs=slab_lists,
    frac=st.floats(0.0, 0.995),
    phi=st.floats(-math.pi, math.pi),
    x0=st.floats(-500.0, 500.0),
    y0=st.floats(-500.0, 500.0),
)
def test_lateral_shift_property(slabs, frac, phi, x0, y0):
    # x_out = x0 + sum_i d_i tan(theta_i) (cos phi, sin phi), with n_i sin(theta_i) = |s|
    d = np.array([a for a, _ in slabs])
    n = np.array([b for _, b in slabs])
    s = frac * n.min()
    res = trace_rays(open_path(d, n), [x0], [y0], s * math.cos(phi), s * math.sin(phi))
    assert res.status[0] == TRANSMITTED
    r = sum(di * math.tan(math.asin(s / ni)) for di, ni in zip(d, n, strict=True))
    assert res.x[0] == pytest.approx(x0 + r * math.cos(phi), rel=1e-9, abs=1e-7)
    assert res.y[0] == pytest.approx(y0 + r * math.sin(phi), rel=1e-9, abs=1e-7)
    assert res.w[0] == 1.0


# -- (b) Snell's law ------------------------------------------------------------------------
@SETTINGS
@given(
    n1=st.floats(1.0, 2.0),
    n2=st.floats(1.0, 2.0),
    theta1=st.floats(0.0, math.radians(85.0)),
    phi=st.floats(-math.pi, math.pi),
)
def test_snell_refraction_angle(n1, n2, theta1, phi):
    # The angle in the second medium, measured from the ray's advance over an extra depth,
    # obeys n1 sin(theta1) = n2 sin(theta2).
    s = n1 * math.sin(theta1)
    assume(s < 0.999 * n2)  # otherwise totally reflected: tested below
    sx, sy = s * math.cos(phi), s * math.sin(phi)
    depth, extra = 500.0, 1000.0
    a = trace_rays(open_path([700.0, depth], [n1, n2]), [0.0], [0.0], sx, sy)
    b = trace_rays(open_path([700.0, depth + extra], [n1, n2]), [0.0], [0.0], sx, sy)
    assert a.status[0] == b.status[0] == TRANSMITTED
    tan2 = math.hypot(b.x[0] - a.x[0], b.y[0] - a.y[0]) / extra
    sin2 = tan2 / math.sqrt(1 + tan2 * tan2)
    assert n2 * sin2 == pytest.approx(n1 * math.sin(theta1), rel=1e-9, abs=1e-12)


def test_glued_plates_do_not_refract():
    # glass on glass (same index): the ray goes straight through the interface
    a = trace_rays(open_path([400.0, 1000.0], [1.52, 1.52]), [0.0], [0.0], 1.3, 0.0)
    b = trace_rays(open_path([1400.0], [1.52]), [0.0], [0.0], 1.3, 0.0)
    assert a.status[0] == b.status[0] == TRANSMITTED
    assert a.x[0] == pytest.approx(b.x[0], rel=1e-12)


# -- (c) total internal reflection ----------------------------------------------------------
def test_total_internal_reflection():
    n = 1.52
    path = open_path([200.0, 300.0], [n, 1.0])
    crit = math.asin(1.0 / n)
    theta = np.array([0.0, 0.5 * crit, crit - 1e-6, crit + 1e-6, math.radians(60.0)])
    s = n * np.sin(theta)
    res = trace_rays(path, np.zeros(5), np.zeros(5), s, np.zeros(5))
    assert res.status.tolist() == [TRANSMITTED] * 3 + [TIR] * 2
    assert res.plane[3:].tolist() == [0, 0]  # stopped at the glass/air interface
    # a ray leaving the last slab into a lower index is also reflected there
    last = trace_rays(
        open_path([200.0], [n], index_out=1.0), [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [1.2, 0.9]
    )
    assert last.status.tolist() == [TIR, TRANSMITTED]


def test_direction_outside_first_medium_is_rejected():
    with pytest.raises(ValueError):
        trace_rays(open_path([100.0], [1.0]), [0.0], [0.0], [1.0], [0.0])


# -- (d) etendue through one square hole = pi A F (view factor) -----------------------------
PIXEL = (-21.15, 21.15, -21.15, 21.15)


def test_view_factor_formula_matches_quadrature():
    # the two independent references used below agree with each other
    for gap, hole in [
        (450.0, PIXEL),
        (100.0, (-20, 20, -20, 20)),
        (100.0, (64.6, 104.6, 64.6, 104.6)),
    ]:
        closed = parallel_rectangles_etendue(PIXEL, hole, gap)
        assert closed == pytest.approx(quadrature_etendue(PIXEL, hole, gap), rel=1e-9)
    # aligned equal squares: Incropera's table formula for coaxial parallel rectangles
    a, c = 40.0, 450.0
    X = Y = a / c
    f = (2 / (math.pi * X * Y)) * (
        math.log(math.sqrt((1 + X * X) * (1 + Y * Y) / (1 + X * X + Y * Y)))
        + X * math.sqrt(1 + Y * Y) * math.atan(X / math.sqrt(1 + Y * Y))
        + Y * math.sqrt(1 + X * X) * math.atan(Y / math.sqrt(1 + X * X))
        - X * math.atan(X)
        - Y * math.atan(Y)
    )
    sq = (-20.0, 20.0, -20.0, 20.0)
    assert parallel_rectangles_etendue(sq, sq, c) == pytest.approx(math.pi * a * a * f, rel=1e-12)


def _hole_etendue(gap, hole, site, importance, n_rays, seed, focus=False):
    design = design_from_dict(one_hole_design(gap, hole))
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    weights = None
    if focus:
        lat = path.lattice
        weights = np.zeros(lat.n_rows * (lat.k_hi - lat.k_lo + 1))
        weights[site_index(path, *site)] = 1.0
    tally = Tally()
    for b in launch(
        path, src, n_rays, seed, importance=importance, hole_weights=weights, chunk=1 << 22
    ):
        hit = (b.hole_row[:, 0] == site[0]) & (b.hole_k[:, 0] == site[1])
        tally.add(b.w[hit], b.n_samples)
    return tally, design


@pytest.mark.parametrize(
    ("gap", "site", "importance", "focus", "n_rays"),
    [
        (450.0, (0, 0), True, True, 1 << 21),  # the prototype's layer-3 gap, own hole
        (450.0, (0, 0), True, False, 1 << 22),  # geometric hole table
        (100.0, (0, 0), True, False, 1 << 20),
        (100.0, (0, 0), False, False, 1 << 26),  # plain Lambertian sampling
        (100.0, (1, 0), True, True, 1 << 20),  # the other row's hole at (84.6, 84.6)
        (100.0, (1, 0), False, False, 1 << 26),
        (100.0, (0, 1), True, True, 1 << 20),  # the next hole of the row at (169.2, 0)
    ],
)
def test_etendue_through_one_square_hole(gap, site, importance, focus, n_rays):
    tally, design = _hole_etendue(gap, {"size_um": 40.0}, site, importance, n_rays, 5, focus)
    cx = site[1] * design.sensor.row_pitch_um + site[0] * design.sensor.row_b_offset_x_um
    cy = site[0] * design.sensor.row_b_offset_y_um
    hole = (cx - 20.0, cx + 20.0, cy - 20.0, cy + 20.0)
    exact = parallel_rectangles_etendue(PIXEL, hole, gap)
    assert_agree(tally.value, tally.se, exact, 0.0)
    assert tally.value == pytest.approx(exact, rel=5e-3)


@pytest.mark.parametrize(
    ("importance", "n_rays"), [(True, 1 << 20), (False, 1 << 26)], ids=["importance", "plain"]
)
def test_etendue_through_one_circular_hole(importance, n_rays):
    # circle of diameter 40 um at 100 um: 4-D quadrature over square x disk
    gap, radius = 100.0, 20.0
    hole = {"shape": "circle", "size_um": 40.0}
    tally, _ = _hole_etendue(gap, hole, (0, 0), importance, n_rays, 9, importance)
    xg, wx = np.polynomial.legendre.leggauss(16)
    px, pw = 21.15 * xg, 21.15 * wx
    rg, rw = np.polynomial.legendre.leggauss(24)
    r, rw = radius * (rg + 1) / 2, radius * rw / 2
    ph = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    X, Y, R, P = np.meshgrid(px, px, r, ph, indexing="ij")
    W = np.einsum("i,j,k->ijk", pw, pw, rw * r)[..., None] * (2 * np.pi / ph.size)
    rr = (X - R * np.cos(P)) ** 2 + (Y - R * np.sin(P)) ** 2 + gap * gap
    exact = float((W * gap * gap / rr**2).sum())
    assert_agree(tally.value, tally.se, exact, 0.0)
    assert tally.value == pytest.approx(exact, rel=5e-3)


@pytest.mark.parametrize(
    ("importance", "n_rays"), [(True, 1 << 20), (False, 1 << 26)], ids=["importance", "plain"]
)
def test_etendue_through_misregistered_rectangular_hole(importance, n_rays):
    # a 30 x 50 um rectangle shifted by (12, -7) um (assembly misregistration, paper section 5)
    hole = {"shape": "rectangle", "width_um": 30.0, "height_um": 50.0}
    hole |= {"offset_x_um": 12.0, "offset_y_um": -7.0}
    tally, _ = _hole_etendue(100.0, hole, (0, 0), importance, n_rays, 10, importance)
    exact = parallel_rectangles_etendue(PIXEL, (-3.0, 27.0, -32.0, 18.0), 100.0)
    assert_agree(tally.value, tally.se, exact, 0.0)
    assert tally.value == pytest.approx(exact, rel=5e-3)


def test_grazing_ray_passes_a_hole_far_along_the_row():
    # hole membership is arithmetic over the whole array (DESIGN.md section 3): a ray aimed
    # at hole k = 300 (50.76 mm away, 89.5 degrees off axis) goes through it.
    design = design_from_dict(one_hole_design(450.0, {"size_um": 40.0}))
    path = reverse_path(design)
    for k in (300, -450, 600):
        xt = k * design.sensor.row_pitch_um + 5.0
        s = xt / math.hypot(xt, 450.0)
        res = trace_rays(path, [0.0], [0.0], [s], [0.0])
        assert res.status[0] == TRANSMITTED
        assert (res.hole_row[0, 0], res.hole_k[0, 0]) == (0, k)
        assert res.x[0] == pytest.approx(xt, rel=1e-9)


def test_holes_exist_only_above_used_pixels():
    # a finite array: pixels_per_row = 5 gives holes k = -2 ... 2 only
    data = one_hole_design(450.0, {"size_um": 40.0})
    data["sensor"] = {"pixels_per_row": 5}
    path = reverse_path(design_from_dict(data))
    pitch = 169.2
    xt = np.array([2 * pitch, 3 * pitch, -2 * pitch, -3 * pitch, 84.6 - 3 * pitch])
    yt = np.array([0.0, 0.0, 0.0, 0.0, 84.6])
    r = np.hypot(xt, yt)
    s = r / np.hypot(r, 450.0)
    res = trace_rays(path, np.zeros(5), np.zeros(5), s * xt / r, s * yt / r)
    assert res.status.tolist() == [TRANSMITTED, ABSORBED, TRANSMITTED, ABSORBED, ABSORBED]
    assert res.hole_k[[0, 2], 0].tolist() == [2, -2]


# -- (e) every launched ray is accounted for ------------------------------------------------
@pytest.mark.parametrize("importance", [False, True])
@pytest.mark.parametrize("forward", [False, True])
def test_ledger_conservation(importance, forward):
    design = load_design("paper2016")
    if forward:
        path = forward_path(design, 1000.0)
        src = Source(30.0, 10.0, 20.0, 20.0)
    else:
        path = reverse_path(design)
        src = pixel_source(design, 0, 0)
    n_rays = 1 << 20
    led = np.zeros((path.slabs.shape[0], 4), np.int64)
    launched = samples = survivors = 0
    for b in launch(path, src, n_rays, 3, importance=importance, chunk=1 << 18):
        led += b.ledger
        launched += b.n_launched
        samples += b.n_samples
        survivors += b.ids.size
        assert b.ledger.sum() == b.n_launched
    assert samples == n_rays
    # launched == absorbed + tir + escaped + transmitted
    assert led.sum() == launched
    assert led[:, TRANSMITTED].sum() == survivors == led[-1, TRANSMITTED]
    assert led[:, ABSORBED].sum() > 0
    if importance:
        assert launched == n_rays
    else:
        # rejection sampling of the disk |s| < n0 in the square [-n0, n0]^2: pi / 4 accepted
        p = math.pi / 4
        assert abs(launched / n_rays - p) < 4 * math.sqrt(p * (1 - p) / n_rays)
    # masks absorb only on mask planes
    mask_planes = path.slabs[:, 2] >= 0
    assert np.all(led[~mask_planes, ABSORBED] == 0)
    # light that starts in air never has |s| > 1, so nothing is totally reflected at the
    # glass/air interfaces; the most oblique rays leave the plates' edges instead
    assert led[:, TIR].sum() == 0
    if not importance:
        assert led[:, ESCAPED].sum() > 0


# -- (f) mirror symmetry in x -----------------------------------------------------------------
def test_mirror_symmetry_ray_by_ray():
    # paper2016 is symmetric under x -> -x about pixel A0: row A hole k <-> -k,
    # row B hole k <-> -k - 1 (row B sits at x = 84.6 + k 169.2)
    path = reverse_path(load_design("paper2016"))
    rng = np.random.default_rng(1)
    n = 200_000
    x = rng.uniform(-21.15, 21.15, n)
    y = rng.uniform(-21.15, 21.15, n)
    # half the rays over the whole disk |s| < 1, half near the axis (which pass)
    rho = np.sqrt(rng.uniform(0, 1, n)) * np.where(np.arange(n) % 2 == 0, 0.999, 0.05)
    phi = rng.uniform(-np.pi, np.pi, n)
    sx, sy = rho * np.cos(phi), rho * np.sin(phi)
    a = trace_rays(path, x, y, sx, sy)
    b = trace_rays(path, -x, y, -sx, sy)
    assert np.array_equal(a.status, b.status)
    assert np.array_equal(a.plane, b.plane)
    np.testing.assert_array_equal(a.x, -b.x)
    np.testing.assert_array_equal(a.y, b.y)
    ok = a.hole_row >= 0
    assert np.array_equal(ok, b.hole_row >= 0)
    assert np.array_equal(a.hole_row, b.hole_row)
    mirrored = np.where(a.hole_row == 1, -a.hole_k - 1, -a.hole_k)
    assert np.array_equal(np.where(ok, mirrored, 0), np.where(ok, b.hole_k, 0))
    assert (a.status == TRANSMITTED).sum() > 1000


def test_mirror_symmetry_of_ghost_paths():
    # each ghost path and its mirror image carry the same etendue (within errors)
    g = analyse_ghosts(load_design("paper2016"), n_rays=1 << 20, seed=4, z_mm=(0.0,))
    table = {tuple((h["row"], h["dk"]) for h in p.holes): p for p in g.paths if p.n_rays >= 100}
    checked = 0
    for key, p in table.items():
        mirror = tuple((row, -dk - 1 if row == "other" else -dk) for row, dk in key)
        if mirror not in table or mirror == key:
            continue
        q = table[mirror]
        assert_agree(p.etendue_um2sr, p.etendue_se, q.etendue_um2sr, q.etendue_se)
        checked += 1
    assert checked >= 10


def test_own_path_spot_is_centred():
    # first moment of the own-path responsivity over the object plane at Z = 1 mm is zero in x
    design = load_design("paper2016")
    path = reverse_path(design)
    m0, m1 = Tally(), Tally()
    for b in launch(path, pixel_source(design, 0, 0), 1 << 20, 8):
        o = is_own_path(b, 0, 0)
        xo, _ = object_plane(b, 1000.0)
        m0.add(b.w[o], b.n_samples)
        m1.add((b.w * xo)[o], b.n_samples)
    assert m0.value > 0
    assert_agree(m1.value, m1.se, 0.0, 0.0)


def test_row_b_pixel_sees_the_point_reflected_lattice():
    # seen from pixel B0, the lattice is row A's seen from A0 turned by 180 degrees about the
    # pixel axis (x, y -> -x, -y); the stack is symmetric under that turn, so both pixels
    # have the same own-path and ghost etendue
    design = load_design("paper2016")
    a = analyse_ghosts(design, n_rays=1 << 20, seed=1, pixel=(0, 0))
    b = analyse_ghosts(design, n_rays=1 << 20, seed=2, pixel=(1, 0))
    assert_agree(a.etendue_own_um2sr, a.etendue_own_se, b.etendue_own_um2sr, b.etendue_own_se)
    assert_agree(
        a.etendue_ghost_um2sr, a.etendue_ghost_se, b.etendue_ghost_um2sr, b.etendue_ghost_se
    )


def test_pixel_angular_response_cuts_grazing_ghosts():
    # every ghost path of the prototype leaves the pixel beyond 60 degrees; a pixel that only
    # accepts light within 60 degrees of its normal keeps its own path and loses the ghosts
    design = load_design("paper2016")
    full = analyse_ghosts(design, n_rays=1 << 20, seed=1)
    assert min(p.emission_angle_deg[0] for p in full.paths) > 60.0
    data = preset_dict("paper2016")
    data["sensor"]["acceptance_half_angle_deg"] = 60.0
    cut = analyse_ghosts(design_from_dict(data), n_rays=1 << 20, seed=1)
    assert cut.etendue_ghost_um2sr == 0.0
    assert_agree(
        cut.etendue_own_um2sr, cut.etendue_own_se, full.etendue_own_um2sr, full.etendue_own_se
    )


# -- (g) Fresnel transmission ---------------------------------------------------------------
@pytest.mark.parametrize("n", [1.33, 1.5, 1.52, 2.0])
def test_fresnel_normal_incidence(n):
    expected = 1 - ((n - 1) / (n + 1)) ** 2
    up = trace_rays(
        open_path([100.0], [1.0], index_out=n), [0.0], [0.0], [0.0], [0.0], fresnel=True
    )
    down = trace_rays(
        open_path([100.0], [n], index_out=1.0), [0.0], [0.0], [0.0], [0.0], fresnel=True
    )
    assert up.w[0] == pytest.approx(expected, rel=1e-12)
    assert down.w[0] == pytest.approx(expected, rel=1e-12)
    off = trace_rays(open_path([100.0], [1.0], index_out=n), [0.0], [0.0], [0.0], [0.0])
    assert off.w[0] == 1.0


def _fresnel_amplitude_t(n1, n2, theta1):
    """Power transmittances (T_s, T_p) from the amplitude coefficients t_s, t_p."""
    c1 = math.cos(theta1)
    c2 = math.sqrt(1 - (n1 * math.sin(theta1) / n2) ** 2)
    ts = 2 * n1 * c1 / (n1 * c1 + n2 * c2)
    tp = 2 * n1 * c1 / (n2 * c1 + n1 * c2)
    return (n2 * c2) / (n1 * c1) * ts * ts, (n2 * c2) / (n1 * c1) * tp * tp


@SETTINGS
@given(n=st.floats(1.05, 2.0), theta=st.floats(0.0, math.radians(85.0)))
def test_fresnel_oblique_plate(n, theta):
    # air -> glass -> air: s and p never mix, so (Ts1 Ts2 + Tp1 Tp2) / 2 (tests/test_fresnel.py)
    s = math.sin(theta)
    res = trace_rays(
        open_path([100.0, 500.0], [1.0, n], index_out=1.0), [0.0], [0.0], [s], [0.0], fresnel=True
    )
    theta_glass = math.asin(s / n)
    ts1, tp1 = _fresnel_amplitude_t(1.0, n, theta)
    ts2, tp2 = _fresnel_amplitude_t(n, 1.0, theta_glass)
    expected = 0.5 * (ts1 * ts2 + tp1 * tp2)
    assert res.status[0] == TRANSMITTED
    assert res.w[0] == pytest.approx(expected, rel=1e-9)


def test_fresnel_brewster_angle():
    # at Brewster's angle p light is fully transmitted: T = 1 - R_s / 2
    n = 1.52
    tb = math.atan(n)
    tt = math.asin(math.sin(tb) / n)
    rs = math.sin(tb - tt) / math.sin(tb + tt)
    res = trace_rays(
        open_path([100.0], [1.0], index_out=n), [0.0], [0.0], [math.sin(tb)], [0.0], fresnel=True
    )
    assert res.w[0] == pytest.approx(1 - 0.5 * rs * rs, rel=1e-12)
