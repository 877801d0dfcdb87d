"""Unpolarised Fresnel transmission through a stack: (prod Ts + prod Tp) / 2, exactly.

Across parallel planar interfaces a ray keeps its plane of incidence, so the s and p
components never mix: the transmittance of unpolarised light is the average over the two
polarisations of the *products* of the interface transmittances, not the product of the
per-interface averages.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from opticalstamp.raytrace.kernel import TRANSMITTED
from opticalstamp.raytrace.launch import trace_rays
from opticalstamp.raytrace.stack import Lattice, Path

N_GLASS = 1.52


def open_path(thickness, index, index_out) -> Path:
    """Unmasked slabs, plates wide enough that no ray escapes."""
    thickness = np.asarray(thickness, dtype=np.float64)
    index = np.asarray(index, dtype=np.float64)
    slabs = np.column_stack([thickness, index, np.full(thickness.size, -1.0)])
    lattice = Lattice(pitch=1e6, k_lo=0, k_hi=0, row_x=np.zeros(2), row_y=np.zeros(2), n_rows=1)
    return Path(
        slabs,
        float(index_out),
        np.zeros((0, 5)),
        lattice,
        np.array([1e15, 1e15]),
        np.cumsum(thickness),
        (),
    )


def interface_ts_tp(n1: float, n2: float, theta1: float) -> tuple[float, float]:
    """Power transmittances (Ts, Tp) from the textbook amplitude coefficients.

    t_s = 2 n1 cos1 / (n1 cos1 + n2 cos2), t_p = 2 n1 cos1 / (n2 cos1 + n1 cos2) and
    T = (n2 cos2) / (n1 cos1) |t|^2 (Hecht, Optics, Sec. 4.6).
    """
    c1 = math.cos(theta1)
    c2 = math.sqrt(1.0 - (n1 * math.sin(theta1) / n2) ** 2)
    ts = 2 * n1 * c1 / (n1 * c1 + n2 * c2)
    tp = 2 * n1 * c1 / (n2 * c1 + n1 * c2)
    factor = (n2 * c2) / (n1 * c1)
    return factor * ts * ts, factor * tp * tp


def plate_in_air(theta: float, n: float = N_GLASS) -> tuple[float, float]:
    """(exact, old) transmittance of one plate: air -> glass -> air at incidence theta."""
    ts1, tp1 = interface_ts_tp(1.0, n, theta)
    ts2, tp2 = interface_ts_tp(n, 1.0, math.asin(math.sin(theta) / n))
    exact = 0.5 * (ts1 * ts2 + tp1 * tp2)
    old = 0.5 * (ts1 + tp1) * 0.5 * (ts2 + tp2)
    return exact, old


def trace_plate(theta_deg: np.ndarray, n: float = N_GLASS, phi: float = 0.3) -> np.ndarray:
    """Weights of rays crossing one glass plate in air (azimuth ``phi``), Fresnel on."""
    s = np.sin(np.radians(theta_deg))
    res = trace_rays(
        open_path([100.0, 500.0, 100.0], [1.0, n, 1.0], 1.0),
        np.zeros(s.size),
        np.zeros(s.size),
        s * math.cos(phi),
        s * math.sin(phi),
        fresnel=True,
    )
    assert np.all(res.status == TRANSMITTED)
    return res.w


ANGLES = np.array([0.0, 30.0, 60.0, 77.0, 85.0])


def test_plate_matches_average_of_polarisation_products():
    w = trace_plate(ANGLES)
    for wi, th in zip(w, ANGLES, strict=True):
        exact, _ = plate_in_air(math.radians(th))
        assert wi == pytest.approx(exact, rel=1e-12, abs=1e-14)


def test_exact_form_differs_from_product_of_averages_at_grazing_incidence():
    # the old per-interface average is ~4.7 % low at 77 deg and ~9 % low at 85 deg
    exact, old = plate_in_air(math.radians(85.0))
    assert old < exact * 0.95
    (w,) = trace_plate(np.array([85.0]))
    assert abs(w - old) > 1e3 * abs(w - exact)
    exact77, old77 = plate_in_air(math.radians(77.0))
    assert 1 - old77 / exact77 == pytest.approx(0.047, abs=0.003)


def test_normal_incidence_both_forms_agree():
    r = ((N_GLASS - 1) / (N_GLASS + 1)) ** 2
    exact, old = plate_in_air(0.0)
    assert exact == pytest.approx((1 - r) ** 2, rel=1e-14)
    assert old == pytest.approx((1 - r) ** 2, rel=1e-14)
    (w,) = trace_plate(np.array([0.0]))
    assert w == pytest.approx((1 - r) ** 2, rel=1e-12)


def test_weight_and_losses_multiply():
    # an initial weight scales the result; Fresnel off leaves weights untouched
    path = open_path([100.0, 500.0, 100.0], [1.0, N_GLASS, 1.0], 1.0)
    s = math.sin(math.radians(60.0))
    on = trace_rays(path, [0.0], [0.0], [s], [0.0], [2.5], fresnel=True)
    off = trace_rays(path, [0.0], [0.0], [s], [0.0], [2.5])
    assert on.w[0] == pytest.approx(2.5 * plate_in_air(math.radians(60.0))[0], rel=1e-12)
    assert off.w[0] == 2.5


def test_three_interfaces_keep_polarisations_apart():
    # air -> glass -> water -> air: (Ts1 Ts2 Ts3 + Tp1 Tp2 Tp3) / 2
    theta, n1, n2 = math.radians(70.0), 1.52, 1.33
    s = math.sin(theta)
    res = trace_rays(
        open_path([50.0, 300.0, 200.0], [1.0, n1, n2], 1.0), [0.0], [0.0], [s], [0.0], fresnel=True
    )
    a = interface_ts_tp(1.0, n1, theta)
    b = interface_ts_tp(n1, n2, math.asin(s / n1))
    c = interface_ts_tp(n2, 1.0, math.asin(s / n2))
    expected = 0.5 * (a[0] * b[0] * c[0] + a[1] * b[1] * c[1])
    assert res.w[0] == pytest.approx(expected, rel=1e-12)
