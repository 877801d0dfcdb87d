"""The fit's errors checked by secants (issue 24, studies/fitident.py: secant_check): on
least squares whose sums of squares are known in closed form, a quadratic one keeps its
covariance to rounding, a direction flatter than its curvature at the optimum says is
widened by exactly the measured factor, and a probe beyond a bound is not measured."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from opticalstamp.studies.fitident import (
    SECANT_AT,
    SECANT_MIN,
    descend,
    joined,
    secant_check,
    secant_estimate,
    secant_words,
)

SCALES = np.array([3.0, 20.0])


def _cov(jac: np.ndarray, scale2: float = 1.0) -> np.ndarray:
    return scale2 * np.linalg.inv(jac.T @ jac)


def test_a_quadratic_sum_of_squares_keeps_its_covariance():
    """Linear residuals A theta - b, two physical columns and one nuisance column (not
    probed, shifted by the covariance's regression): every probe rises by exactly
    SECANT_AT^2 x scale^2, so nothing is widened."""
    rng = np.random.default_rng(5)
    a = rng.standard_normal((40, 3)) * [1 / 3.0, 1 / 20.0, 1.0]
    a[:, 2] += 0.8 * a[:, 0] * 3.0  # the nuisance correlated with the first
    b = rng.standard_normal(40)
    theta = np.linalg.lstsq(a, b, rcond=None)[0]
    chi2 = float(np.sum((a @ theta - b) ** 2))
    scale2 = max(1.0, chi2 / 37)
    seen = []

    def sumsq(points):
        out = [float(np.sum((a @ p - b) ** 2)) for p in points]
        seen.extend(out)
        return out

    cov = _cov(a, scale2)
    out, found = secant_check(sumsq, theta, cov, scale2, SCALES, [0, 1])
    assert found == [] and np.array_equal(out, cov)
    rises = np.array(seen[1:]) - seen[0]
    assert rises.size == 4
    assert np.allclose(rises, SECANT_AT**2 * scale2, rtol=1e-9)


def test_a_flat_direction_is_widened_by_its_secant():
    """r0 = tanh(theta0 / s0) (its error s0 at the optimum), r1 = theta1 / s1: SECANT_AT
    errors along theta0 raise the sum by tanh(SECANT_AT)^2 = 0.99 where 9 is expected,
    so theta0's error is widened by SECANT_AT / tanh(SECANT_AT) and theta1's kept."""
    s0, s1 = 0.5, 15.0

    def res(p):
        return np.array([np.tanh(p[0] / s0), p[1] / s1])

    theta = np.zeros(2)
    jac = np.diag([1 / s0, 1 / s1])
    out, found = secant_check(
        lambda pts: [float(res(p) @ res(p)) for p in pts], theta, _cov(jac), 1.0, SCALES, [0, 1]
    )
    assert len(found) == 1
    f = found[0]
    assert np.allclose(np.abs(f["direction"]), [1, 0], atol=1e-12)
    assert f["factor"] == pytest.approx(SECANT_AT / np.tanh(SECANT_AT), rel=1e-9)
    assert f["rise"] == pytest.approx([np.tanh(SECANT_AT) ** 2] * 2, rel=1e-9)
    assert np.sqrt(out[0, 0]) == pytest.approx(s0 * f["factor"], rel=1e-9)
    assert out[1, 1] == pytest.approx(s1**2, rel=1e-12) and abs(out[0, 1]) < 1e-9
    # a curvature a little below the one claimed (rho = 1.2 SECANT_MIN): kept
    c = np.sqrt(1.2 * SECANT_MIN)

    def mild(p):
        return np.array([c * p[0] / s0, p[1] / s1])

    _, found = secant_check(
        lambda pts: [float(mild(p) @ mild(p)) for p in pts], theta, _cov(jac), 1.0, SCALES, [0, 1]
    )
    assert found == []


def test_a_probe_beyond_a_bound_is_not_measured():
    """A side that the caller cannot evaluate (NaN) leaves the other side's rise alone to
    judge (here none: flat, so its error x 100); with both sides missing the direction is
    not judged at all."""
    s0, s1 = 0.5, 15.0
    jac = np.diag([1 / s0, 1 / s1])
    theta = np.zeros(2)

    def flat_right(pts):  # flat for theta0 > 0, quadratic for theta0 < 0, nan below -1
        out = []
        for p in pts:
            if p[0] < -1.0:
                out.append(np.nan)
            else:
                out.append(float((min(p[0], 0.0) / s0) ** 2 + (p[1] / s1) ** 2))
        return out

    _, found = secant_check(flat_right, theta, _cov(jac), 1.0, SCALES, [0, 1])
    assert len(found) == 1 and found[0]["factor"] == pytest.approx(100.0)
    assert np.isnan(found[0]["rise"]).sum() == 1

    def none_left(pts):
        return [np.nan if abs(p[0]) > 1e-9 else float((p[1] / s1) ** 2) for p in pts]

    _, found = secant_check(none_left, theta, _cov(jac), 1.0, SCALES, [0, 1])
    assert found == []


def test_the_two_sides_are_averaged_and_a_fall_is_said():
    """One side flat, the other rising 3.6 (a parabola's 9 x 0.4): the mean 1.8 is 0.2 of
    9, so the error is widened by sqrt(5) (the larger side alone, 0.4, would pass). Falls
    on both sides (the point is no minimum along it): widened 100 x and said so."""
    s0, s1 = 0.5, 15.0
    jac = np.diag([1 / s0, 1 / s1])
    theta = np.zeros(2)

    def one_sided(pts):
        return [float(0.4 * (max(p[0], 0.0) / s0) ** 2 + (p[1] / s1) ** 2) for p in pts]

    _, found = secant_check(one_sided, theta, _cov(jac), 1.0, SCALES, [0, 1])
    assert len(found) == 1 and found[0]["factor"] == pytest.approx(np.sqrt(5), rel=1e-9)
    assert "changes by +3.6 and +0 where a rise of 9 was expected;" in secant_words(
        found[0], ["layer1.x", "slab1"]
    )

    def saddle(pts):
        return [float(10 - (p[0] / s0) ** 2 + (p[1] / s1) ** 2) for p in pts]

    _, found = secant_check(saddle, theta, _cov(jac), 1.0, SCALES, [0, 1])
    assert len(found) == 1 and found[0]["factor"] == pytest.approx(100.0)
    words = secant_words(found[0], ["layer1.x", "slab1"])
    assert "changes by -9 and -9 where a rise of 9 was expected (a fall" in words
    assert "+1.00 layer1.x" in words


def test_directions_joined_once():
    """The Jacobian's weak directions and the secants' loose ones joined: one already
    spanned is dropped, one half new keeps its new part (unit length), none gives (0, n)."""
    a = np.array([[1.0, 0.0, 0.0]])
    more = np.array([[0.999, 0.0447, 0.0], [0.6, 0.8, 0.0]])
    out = joined(a, more)
    assert out.shape == (2, 3) and np.allclose(out[1], [0, 1, 0])
    assert joined(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0, 3)
    assert np.allclose(joined(np.zeros((0, 3)), more[1:]), [[0.6, 0.8, 0.0]])


def test_a_descent_is_kept_only_where_it_ends_lower():
    """:func:`descend` keeps the refit from a probe below the optimum where its chi2 ends
    below the optimum's, with the three chi2 recorded, and refuses one that does not."""
    est = (100.0, 10, 1.0)
    probe = np.array([1.0, 2.0])

    def estimate(prob, t):
        return (prob, 10, 1.0)

    t, p, new, rec = descend(96.0, None, est, (3.0, probe), lambda pr, t0: (t0, 95.5), estimate)
    assert np.array_equal(t, probe) and new[0] == 95.5
    assert rec == {"chi2_from": 100.0, "fall": 3.0, "chi2_to": 95.5}
    # above the probe but below the optimum: kept (the optimum is what it must beat)
    assert descend(96.0, None, est, (3.0, probe), lambda pr, t0: (t0, 98.0), estimate)[2][0] == 98
    assert descend(96.0, None, est, (3.0, probe), lambda pr, t0: (t0, 100.0), estimate) is None


class _Lay:
    """Two free physical columns of assembly scales SCALES, no nuisance."""

    params = [SimpleNamespace(name=n, scale=s) for n, s in zip(("a", "b"), SCALES, strict=True)]
    free = (0, 1)
    n_free = 2

    @staticmethod
    def physical(p):
        return np.asarray(p)


class _Quadratic:
    """Residuals (theta - opt) / SCALES: chi2 = |.|^2, its minimum at ``opt``; NaN where
    ``bad`` says (a probe whose design cannot be evaluated)."""

    lay = _Lay()

    def __init__(self, opt, bad=lambda p: False):
        self.opt, self.bad = np.asarray(opt, dtype=float), bad

    def bounds(self):
        return np.full(2, -np.inf), np.full(2, np.inf)

    def spreads(self, phys):
        return None if self.bad(phys) else {}

    def residuals(self, p):
        return (np.asarray(p) - self.opt) / SCALES

    def fit_nuisance(self, p, search=False):
        return np.asarray(p, dtype=float)


@pytest.mark.parametrize("scale2", [1.0, 4.0])
def test_a_probe_below_the_point_is_found_past_its_threshold_in_error_scales(scale2):
    """chi2 = |(theta - 0) / SCALES|^2, checked at a point k errors (of the covariance
    scale2 x diag(SCALES^2)) from its minimum along the first column: the probe 3 errors
    back lies at k - 3, its fall (k^2 - (k - 3)^2) scale2. At k = 2 (fall 3 scale2) it is
    found, with its point; at k = 1.6 (fall 0.6 scale2, over DESCEND_MIN = 1 in chi2 where
    scale2 is 4, but not in error scales) it is not; a probe that cannot be evaluated
    (NaN) is never the lowest."""
    s = np.sqrt(scale2)
    est = (0.0, 10, scale2, scale2 * np.diag(SCALES**2), [], set(), np.zeros((0, 2)))
    prob = _Quadratic([0.0, 0.0])

    def at(k):
        return np.array([k * s * SCALES[0], 0.0])

    fall, point = secant_estimate(prob, at(2.0), est, 10.0)[3]
    assert fall == pytest.approx(3 * scale2) and np.allclose(point, at(-1.0))
    assert secant_estimate(prob, at(1.6), est, 10.0)[3] is None
    nan = _Quadratic([0.0, 0.0], bad=lambda p: p[0] < at(1.0)[0])
    assert secant_estimate(nan, at(2.0), est, 10.0)[3] is None
