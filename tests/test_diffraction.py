"""Fresnel diffraction (paper Fig. 6): Fresnel integrals against direct integration."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from scipy import integrate

from opticalstamp.analysis.diffraction import (
    circle_field,
    diffraction_budget,
    fraction_outside,
    geometric_edge,
    slit_case,
    slit_field,
    slit_intensity,
)
from opticalstamp.design import load_design, replace


def _direct_slit(x, w, r1, r2, lam):
    """U/U0 by direct quadrature of the Fresnel-Kirchhoff integral (paraxial phases)."""
    big_l = 1 / (1 / r1 + 1 / r2)

    def ph(xi):
        return math.pi / lam * (xi * xi / r1 + (x - xi) ** 2 / r2)

    re = integrate.quad(lambda t: math.cos(ph(t)), -w / 2, w / 2, limit=400)[0]
    im = integrate.quad(lambda t: math.sin(ph(t)), -w / 2, w / 2, limit=400)[0]
    # normalise by the unobstructed integral: sqrt(lambda L) e^{i pi/4} e^{i pi x^2/(lam(R1+R2))}
    norm = math.sqrt(lam * big_l) * cmath.exp(1j * math.pi / 4)
    norm *= cmath.exp(1j * math.pi * x * x / (lam * (r1 + r2)))
    return complex(re, im) / norm


@pytest.mark.parametrize("x", [0.0, 12.0, 31.9, 45.0])
@pytest.mark.parametrize("lam", [0.4, 0.7])
def test_slit_intensity_against_direct_integration(x, lam):
    u = _direct_slit(x, 48.0, 2000.0, 657.9, lam)
    assert slit_intensity(np.array([x]), 48.0, 2000.0, 657.9, lam)[0] == pytest.approx(
        abs(u) ** 2, abs=1e-6
    )


def test_energy_and_edge():
    """Parseval: the power over the whole plane equals I0 times the geometric image."""
    x = np.linspace(-3000, 3000, 600001)
    tot = np.trapezoid(slit_intensity(x, 48, 2000, 657.9, 0.55), x)
    assert tot == pytest.approx(2 * geometric_edge(48, 2000, 657.9), rel=2e-3)
    assert abs(slit_field(np.array([1e5]), 48, 2000, 657.9, 0.55)[0]) < 1e-2
    # 1/4 of I0 at the geometric edge of a wide slit (half-plane result)
    xg = geometric_edge(4000, 2000, 657.9)
    assert slit_intensity(np.array([xg]), 4000, 2000, 657.9, 0.55)[0] == pytest.approx(
        0.25, abs=0.02
    )


def test_paper_figure_6():
    """Paper §3: Z = 1 mm, 48 um slit, 0.66 mm air-equivalent gap: edge X = 32 um and
    about 7 % of the light diffracted outside it (we get 7.0 % at 0.4 um, 9.6 % at 0.7)."""
    r = slit_case()
    assert r.geometric_edge_um == pytest.approx(32, abs=0.2)
    assert r.fraction_outside["0.4"] == pytest.approx(0.07, abs=0.01)
    assert r.fraction_outside["0.4"] < r.fraction_outside["0.7"] < 0.12


def test_circle_on_axis_closed_form():
    lam, r1, r2, d = 0.55, 2000.0, 657.9, 48.0
    big_l = 1 / (1 / r1 + 1 / r2)
    exact = 4 * math.sin(math.pi * (d / 2) ** 2 / (2 * lam * big_l)) ** 2
    assert abs(circle_field(np.array([0.0]), d, r1, r2, lam)[0]) ** 2 == pytest.approx(exact)


def test_circle_off_axis_against_2d_integration():
    """Radial Hankel form vs a brute-force 2-D polar quadrature of the Fresnel integral."""
    lam, r1, r2, d, r = 0.55, 2000.0, 657.9, 48.0, 20.0
    big_l = 1 / (1 / r1 + 1 / r2)
    rho0 = big_l * r / r2
    q = math.pi / (lam * big_l)
    rr, wr = np.polynomial.legendre.leggauss(200)
    rho = (rr + 1) * d / 4
    wr = wr * d / 4
    phi = np.linspace(0, 2 * np.pi, 801)[:-1]
    rho_g, phi_g = np.meshgrid(rho, phi, indexing="ij")
    f = np.exp(1j * q * (rho_g**2 + rho0**2 - 2 * rho_g * rho0 * np.cos(phi_g))) * rho_g
    val = (f.sum(axis=1) * (2 * np.pi / phi.size) * wr).sum() * q / (1j * math.pi)
    assert circle_field(np.array([r]), d, r1, r2, lam)[0] == pytest.approx(val, rel=1e-6)


def test_square_is_separable_and_circle_conserves():
    f1 = fraction_outside("slit", 48, 2000, 657.9, 0.55)
    f2 = fraction_outside("square", 48, 2000, 657.9, 0.55)
    assert 1 - f2 == pytest.approx((1 - f1) ** 2)
    # a hole much larger than the Fresnel zone: almost no light outside the shadow
    assert fraction_outside("circle", 2000, 2000, 657.9, 0.55) < 0.01
    with pytest.raises(ValueError, match="shape"):
        fraction_outside("hexagon", 48, 2000, 657.9, 0.55)


def test_budget_warns_beyond_300_dpi():
    """Paper §3: beware of diffraction beyond 300 dpi. Halving the holes (600 dpi) with
    the same gaps quarters the Fresnel number and raises a warning; the prototype's
    budget stays under the threshold at 0.4 um."""
    d = load_design("paper2016")
    b = diffraction_budget(d)
    assert all(row["outside_shadow"]["0.4"] < b["warn_fraction"] for row in b["layers"])
    halved = {
        f"slabs.{i}.mask_top.size_um": sl.mask_top.size_um / 2 for i, sl in enumerate(d.slabs)
    }
    b600 = diffraction_budget(replace(d, halved))
    assert len(b600["warnings"]) >= 3
    for row, row600 in zip(b["layers"], b600["layers"], strict=True):
        assert row600["fresnel_number"]["0.4"] == pytest.approx(row["fresnel_number"]["0.4"] / 4)
