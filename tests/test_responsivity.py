"""LSFs on the object plane: paraxial closed form against the exact tracer and against
independent geometry."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import assert_agree
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.lsf import traced_folded_lsf
from opticalstamp.analysis.paraxial import (
    paraxial_cumulative,
    paraxial_etendue,
    paraxial_folded_lsf,
    paraxial_profile,
    paraxial_support,
)
from opticalstamp.design import load_design


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def test_paraxial_etendue_matches_tracer(paper):
    """Own-path etendue: closed form G_x G_y vs the exact tracer (paraxial error < 0.5 %)."""
    g = analyse_ghosts(paper, n_rays=1 << 21, seed=3)
    par = paraxial_etendue(paper)
    assert abs(par - g.etendue_own_um2sr) <= 4 * g.etendue_own_se + 5e-3 * par


def _brute_force_rays(design, z_mm, n=1201):
    """Paraxial rays on a (x0, s) grid propagated plane by plane (independent of the
    interval algebra): object-plane X and whether each passes the pixel and every hole."""
    a = design.sensor.sensitive_width_um
    x0 = np.linspace(-a / 2, a / 2, n)[:, None]
    s = np.linspace(-0.2, 0.2, 4 * n)[None, :]
    ok = np.ones((x0.size, s.size), bool)
    red = 0.0
    for sl in design.slabs:
        red += sl.thickness_um / design.index(sl.medium)
        m = sl.mask_top
        if m is not None:
            ok &= np.abs(x0 + s * red - m.offset_x_um) <= m.hole_width_um / 2
    red += design.reference_gap.thickness_um / design.index(design.reference_gap.medium)
    x_obj = x0 + s * (red + z_mm * 1000.0)
    return x_obj, ok, (s[0, 1] - s[0, 0]) * (x0[1, 0] - x0[0, 0])


@pytest.mark.parametrize("z", [0.0, 1.0, 4.0])
def test_paraxial_support_and_profile_against_brute_force(paper, z):
    x_obj, ok, cell = _brute_force_rays(paper, z)
    lo, hi = paraxial_support(paper, z)
    assert x_obj[ok].max() == pytest.approx(hi, abs=0.5)
    assert x_obj[ok].min() == pytest.approx(lo, abs=0.5)
    # 1-D etendue and the profile histogram
    g_x = paraxial_cumulative(paper, z, np.array([np.inf]))[0]
    assert ok.sum() * cell == pytest.approx(g_x, rel=5e-3)
    edges = np.linspace(lo, hi, 21)
    hist = np.histogram(x_obj[ok], edges)[0] * cell
    exact = np.diff(paraxial_cumulative(paper, z, edges))
    np.testing.assert_allclose(hist, exact, atol=0.01 * exact.max())


def test_support_grows_linearly_with_z(paper):
    e = [2 * paraxial_support(paper, z)[1] for z in (1.0, 2.0, 3.0)]
    assert e[2] - e[1] == pytest.approx(e[1] - e[0], rel=1e-9)
    # spots of the tracer: 114 um at Z = 0 (paper Fig. 5 analysis, docs/paper-comparison.md)
    assert 2 * paraxial_support(paper, 0.0)[1] == pytest.approx(113.9, abs=0.5)


def test_cumulative_is_exact_integral(paper):
    u = np.linspace(-120, 120, 200001)
    r = paraxial_profile(paper, 1.0, u)
    num = np.trapezoid(r, u)
    assert paraxial_cumulative(paper, 1.0, np.array([130.0]))[0] == pytest.approx(num, rel=1e-6)


def test_folded_lsf_conserves_etendue(paper):
    zs, per = [0.0, 2.0], [254.0, 508.0]
    par = paraxial_folded_lsf(paper, z_mm=zs, periods_um=per)
    for h in par.h:
        np.testing.assert_allclose(h.sum(axis=(1, 3)), paraxial_etendue(paper), rtol=1e-9)
    tr = traced_folded_lsf(paper, z_mm=zs, periods_um=per, n_rays=1 << 19, ghosts=False)
    g = analyse_ghosts(paper, n_rays=1 << 19)
    for h in tr.h:
        tot = h.sum(axis=(1, 3))  # (rows, nz): the same rays at every Z and period
        assert np.ptp(tot, axis=1).max() < 1e-9 * tot.max()
        assert_agree(tot[0, 0], g.etendue_own_se * 2, g.etendue_own_um2sr, g.etendue_own_se)


def test_traced_lsf_matches_paraxial_shape(paper):
    """The exact own-path LSF folded on 508 um equals the closed form within noise."""
    tr = traced_folded_lsf(paper, z_mm=[1.0], periods_um=[508.0], n_rays=1 << 21, ghosts=False)
    par = paraxial_folded_lsf(paper, z_mm=[1.0], periods_um=[508.0])
    a = tr.h[0][0].sum(axis=0)[0]
    b = par.h[0][0, 0, 0]
    # compare on 10 um blocks (20 bins) to beat down the noise
    ab = a[: a.size // 20 * 20].reshape(-1, 20).sum(1)
    bb = b[: b.size // 20 * 20].reshape(-1, 20).sum(1)
    assert np.abs(ab - bb).max() < 0.02 * bb.max()


def test_traced_lsf_is_reproducible_and_chunk_independent(paper):
    kw = dict(z_mm=[0.5], periods_um=[339.0], n_rays=1 << 18, seed=5)
    a = traced_folded_lsf(paper, chunk=1 << 16, **kw)
    b = traced_folded_lsf(paper, chunk=1 << 20, **kw)
    np.testing.assert_array_equal(a.h[0], b.h[0])
