"""RMTF (paper Eq. 1) and depth of field against closed forms and the paraxial model."""

from __future__ import annotations

import numpy as np
import pytest

from opticalstamp.analysis.lsf import FoldedLSF
from opticalstamp.analysis.rmtf import (
    chart_correlation,
    depth_of_field,
    period_of_dpi,
    rmtf,
    rmtf_curves,
)
from opticalstamp.design import load_design


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def test_periods_of_the_paper():
    """Paper §5: 100, 150, 200, 247 dpi are periods of 508, 339, 254, 206 um."""
    got = [period_of_dpi(d) for d in (100, 150, 200, 247)]
    np.testing.assert_allclose(got, [508, 338.7, 254, 205.7], atol=0.1)


def test_chart_correlation_matches_direct_sum():
    rng = np.random.default_rng(1)
    n = 40
    h = rng.random(n)
    white = np.r_[np.ones(n // 2), np.zeros(n // 2)]
    direct = [sum(h[p] * white[(p + v) % n] for p in range(n)) for v in range(n)]
    np.testing.assert_allclose(chart_correlation(h), direct, atol=1e-12)


def _box_lsf(width_um: float, period_um: float, rows: int = 2) -> FoldedLSF:
    n = int(round(period_um / 0.5))
    phi = (np.arange(n) + 0.5) * period_um / n
    d = np.minimum(phi, period_um - phi)  # distance from the pixel axis, folded
    h = (d <= width_um / 2).astype(float) * (period_um / n)
    arr = np.broadcast_to(h, (rows, 1, 1, n)).copy()
    return FoldedLSF(
        np.array([0.0]),
        np.array([period_um]),
        [(0, 0), (84.6, 84.6)],
        [arr],
        "test",
        0,
        False,
        False,
    )


@pytest.mark.parametrize("frac", [0.6, 0.8])
def test_box_lsf_rmtf_closed_form(paper, frac):
    """A box LSF of width w (P/2 < w < P) gives C from (w - P/2)/w to (P/2)/w, so
    RMTF = (P - w) / w when the pixels sample every phase (206 um: incommensurate)."""
    per = 205.7
    w = frac * per
    lsf = _box_lsf(w, per)
    w_bins = lsf.h[0][0, 0, 0].sum()  # the box's width on the bin grid
    out = rmtf_curves(lsf, paper, window_um=50_000.0, shift_step_um=0.5)
    assert out["max"][0, 0] == pytest.approx((per - w_bins) / w_bins, abs=2e-3)


def test_narrow_box_gives_full_contrast(paper):
    """An LSF narrower than a bar: some pixel sees only white, another only black."""
    out = rmtf_curves(_box_lsf(30.0, 254.0), paper, window_um=5000.0)
    assert out["max"][0, 0] == pytest.approx(1.0)
    assert out["min"][0, 0] <= out["mean"][0, 0] <= out["max"][0, 0]


def test_depth_of_field_interpolates():
    z = np.array([0.0, 1.0, 2.0, 3.0])
    assert depth_of_field(z, [0.9, 0.6, 0.4, 0.2], 0.3) == pytest.approx(2.5)
    assert depth_of_field(z, [0.9, 0.8, 0.7, 0.6], 0.3) == 3.0
    assert depth_of_field(z, [0.2, 0.8, 0.7, 0.6], 0.3) == 0.0


def test_traced_own_path_rmtf_agrees_with_paraxial(paper):
    """Exact tracer (own path only) vs the paraxial closed form, every dpi and Z."""
    z = (0.0, 1.0, 2.0, 3.0, 4.0)
    tr = rmtf(paper, z_mm=z, ghosts=False, n_rays=1 << 21, seed=2)
    par = rmtf(paper, z_mm=z, method="paraxial")
    for k in tr.rmtf_max:
        a, b, se = map(np.asarray, (tr.rmtf_max[k], par.rmtf_max[k], tr.rmtf_max_se[k]))
        assert np.all(se < 0.005)
        # paraxial error (< 0.5 % in etendue) plus 5 SE for the max-over-shifts noise
        assert np.all(np.abs(a - b) <= 5 * se + 0.01), (k, a, b)


def test_ghost_light_lowers_contrast_by_the_ghost_fraction(paper):
    """Ghost light from far away is a uniform background B: at Z = 0 with 100 dpi bars a
    pixel sees white (G + B/2) or black (B/2): RMTF = G / (G + B) = 1 - ghost fraction."""
    from opticalstamp.analysis.ghosts import analyse_ghosts

    r = rmtf(paper, dpi=(100.0,), z_mm=(0.0,), n_rays=1 << 21)
    g = analyse_ghosts(paper, n_rays=1 << 21)
    assert r.rmtf_max["100"][0] == pytest.approx(1 - g.ghost_fraction, abs=0.01)


def test_rmtf_reproducible_and_se_reported(paper):
    a = rmtf(paper, dpi=(200.0,), z_mm=(1.0, 3.0), n_rays=1 << 18, seed=9)
    b = rmtf(paper, dpi=(200.0,), z_mm=(1.0, 3.0), n_rays=1 << 18, seed=9)
    assert a.rmtf_max == b.rmtf_max
    assert all(0 < s < 0.02 for s in a.rmtf_max_se["200"])
    assert a.dof_mm["200"] == b.dof_mm["200"]


def test_rmtf_rejects_bad_input(paper):
    with pytest.raises(ValueError, match="dpi"):
        rmtf(paper, dpi=(-5.0,), method="paraxial")
    with pytest.raises(ValueError, match="method"):
        rmtf(paper, method="magic")
    circ = load_design("paper2016").model_dump(mode="json", exclude_none=True)
    for sl in circ["slabs"]:
        sl["mask_top"]["shape"] = "circle"
    from opticalstamp.design import design_from_dict

    with pytest.raises(ValueError, match="rectangular"):
        rmtf(design_from_dict(circ), method="paraxial")
