"""Levenberg-Marquardt with geodesic acceleration (studies/fitlm.py), the wave fit's own
least squares: checked against closed-form minima and scipy's least squares."""

import numpy as np
from scipy.optimize import least_squares

from opticalstamp.studies.fitlm import geodesic_lm


def _rosen(x):
    return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0]])


def _rosen_jac(x):
    return np.array([[-20 * x[0], 10.0], [-1.0, 0.0]])


def test_rosenbrock_valley_to_its_minimum():
    """The curved valley the method is made for: from (-1.2, 1) to (1, 1), the sum of
    squares 0 there."""
    inf = np.full(2, np.inf)
    r = geodesic_lm(_rosen, np.array([-1.2, 1.0]), _rosen_jac, (-inf, inf), chi2_tol=1e-14)
    assert r.status > 0, r.message
    assert np.allclose(r.x, [1.0, 1.0], atol=1e-5)
    assert r.cost < 1e-10
    assert r.njev < 40


def _sloppy():
    """A sum of three decaying exponentials (a sloppy model: rates hard to tell apart)
    sampled with fixed noise."""
    t = np.linspace(0, 5, 60)
    true = np.array([1.0, 0.5, 2.0, 1.5, 0.7, 4.0])  # amplitude, rate pairs
    rng = np.random.default_rng(3)
    y = sum(true[2 * i] * np.exp(-true[2 * i + 1] * t) for i in range(3))
    y = y + 1e-3 * rng.standard_normal(t.size)

    def fun(p):
        return (sum(p[2 * i] * np.exp(-p[2 * i + 1] * t) for i in range(3)) - y) / 1e-3

    def jac(p):
        cols = []
        for i in range(3):
            e = np.exp(-p[2 * i + 1] * t)
            cols += [e / 1e-3, -p[2 * i] * t * e / 1e-3]
        return np.column_stack(cols)

    return fun, jac, np.array([0.8, 0.4, 1.8, 1.2, 0.9, 3.0])


def test_sloppy_model_reaches_scipys_minimum():
    fun, jac, x0 = _sloppy()
    lo, hi = np.zeros(6), np.full(6, 10.0)
    ref = least_squares(fun, x0, jac=jac, bounds=(lo, hi), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    r = geodesic_lm(fun, x0, jac, (lo, hi), max_nfev=400, max_njev=200, chi2_tol=1e-6)
    assert r.status > 0, r.message
    assert abs(2 * r.cost - 2 * ref.cost) < 1e-3  # chi2 ~ 54: the same minimum
    assert np.allclose(r.x, ref.x, rtol=1e-3, atol=1e-3)


def test_bounds_hold_and_acceleration_points_are_announced():
    """Every evaluation lies within the bounds, the minimum on a bound stays there, and
    ``ahead`` is told both acceleration points before they are evaluated."""
    seen, told = [], []

    def fun(x):
        seen.append(x.copy())
        return np.array([x[0] - 3.0, 2 * (x[1] + 1.0)])

    def jac(x):
        return np.array([[1.0, 0.0], [0.0, 2.0]])

    lo, hi = np.array([-1.0, 0.0]), np.array([1.0, 5.0])
    r = geodesic_lm(fun, np.array([0.0, 2.0]), jac, (lo, hi), ahead=told.extend)
    assert np.allclose(r.x, [1.0, 0.0], atol=1e-6)
    assert all(np.all(x >= lo) and np.all(x <= hi) for x in seen)
    assert told and all(any(np.array_equal(t, s) for s in seen) for t in told)


def test_out_of_jacobians_is_not_converged():
    inf = np.full(2, np.inf)
    r = geodesic_lm(_rosen, np.array([-1.2, 1.0]), _rosen_jac, (-inf, inf), max_njev=2)
    assert r.status == 0 and r.njev == 2
    assert "Jacobians" in r.message


def test_broyden_updates_reach_the_same_minima():
    """With Broyden's updates between full Jacobians (the wave fit's default): the same
    minima of Rosenbrock's valley and of the sloppy model, with fewer Jacobians on the
    sloppy one; an updated Jacobian never declares convergence (a full one confirms)."""
    inf = np.full(2, np.inf)
    r = geodesic_lm(
        _rosen, np.array([-1.2, 1.0]), _rosen_jac, (-inf, inf), chi2_tol=1e-14, broyden=3,
        max_nfev=500, max_njev=100,
    )  # fmt: skip
    assert r.status > 0 and np.allclose(r.x, [1.0, 1.0], atol=1e-5), r.message
    fun, jac, x0 = _sloppy()
    lo, hi = np.zeros(6), np.full(6, 10.0)
    calls = []

    def counted(p):
        calls.append(p)
        return jac(p)

    plain = geodesic_lm(fun, x0, jac, (lo, hi), max_nfev=800, max_njev=200, chi2_tol=1e-6)
    b = geodesic_lm(fun, x0, counted, (lo, hi), max_nfev=800, max_njev=200, chi2_tol=1e-6,
                    broyden=3)  # fmt: skip
    assert b.status > 0 and abs(b.cost - plain.cost) < 1e-4
    assert np.allclose(b.x, plain.x, rtol=1e-3, atol=1e-3)
    assert b.njev < plain.njev and len(calls) == b.njev
    assert np.array_equal(calls[-1], b.x)  # the last word was a full Jacobian's, at the end


def test_an_updated_jacobian_is_kept_when_only_the_acceleration_refuses_its_step():
    """A full Jacobian follows a step that the updated one let raise the sum of squares,
    not a step refused because its acceleration was not trusted (that is the valley's
    bend, and the damping answers it): on Rosenbrock's valley with Broyden's updates no
    Jacobian comes right after the two acceleration probes (three did when any refusal
    on an updated Jacobian called for a full one), and the minimum is the same."""
    events, probes = [], []

    def fun(x):
        events.append(("f", any(np.array_equal(x, p) for p in probes)))
        return _rosen(x)

    def jac(x):
        events.append(("J", None))
        return _rosen_jac(x)

    inf = np.full(2, np.inf)
    r = geodesic_lm(
        fun, np.array([-1.2, 1.0]), jac, (-inf, inf), chi2_tol=1e-14, broyden=3,
        max_nfev=500, max_njev=100, ahead=lambda pts: probes.extend(p.copy() for p in pts),
    )  # fmt: skip
    assert r.status > 0 and np.allclose(r.x, [1.0, 1.0], atol=1e-5), r.message
    assert probes and sum(e[0] == "J" for e in events) == r.njev > 1
    before_jacobian = [a for a, b in zip(events, events[1:], strict=False) if b[0] == "J"]
    assert ("f", True) not in before_jacobian


def test_a_parameter_the_residuals_barely_see_does_not_stall_the_others(monkeypatch):
    """A parameter whose column is 1e-12 of the other's (its residuals flat here, a wall
    at |x1| = 2): damped as one at D_FLOOR of the stiffest, it moves no further than the
    others and the fit reaches the valley's floor; without the floor its step is
    unbounded, every probe lands on the wall and the damping grows until the fit stops
    where it started."""
    import opticalstamp.studies.fitlm as fitlm

    s = 1e-12

    def fun(x):
        return np.array([x[0] - 1 + s * x[1], 1e3 * max(abs(x[1]) - 2.0, 0.0)])

    def jac(x):
        wall = 1e3 * np.sign(x[1]) if abs(x[1]) > 2 else 0.0
        return np.array([[1.0, s], [0.0, wall]])

    bounds = (np.array([-10.0, -50.0]), np.array([10.0, 50.0]))
    x0 = np.array([3.0, 0.0])
    r = geodesic_lm(fun, x0, jac, bounds, max_nfev=200, max_njev=50, chi2_tol=1e-8)
    assert r.status == 1 and 2 * r.cost < 1e-8 and abs(r.x[1]) < 2, (r.x, r.message)
    assert r.nfev < 20
    monkeypatch.setattr(fitlm, "D_FLOOR", 0.0)
    stalled = geodesic_lm(fun, x0, jac, bounds, max_nfev=200, max_njev=50, chi2_tol=1e-8)
    assert 2 * stalled.cost > 3.9  # where it started (chi2 4): the floor is what moves it


def test_a_parameter_on_its_bound_is_held_there():
    """The minimum with x1 on its lower bound (the descent pushes it out, a curved
    coupling with x0): the step and its acceleration among the free parameters reach
    (1, 0) in a few evaluations, converged by the decrement of the free ones; probes
    clipped on one side only (the bound held by clipping alone) had read the residuals'
    slope as a bend and kept refusing, out of evaluations at x0 = 1.75."""
    seen = []

    def fun(x):
        seen.append(x.copy())
        return np.array([x[0] - 1 + 0.5 * x[1] ** 2, 10 * (x[1] + 1), 3 * x[0] * x[1]])

    def jac(x):
        return np.array([[1.0, x[1]], [0.0, 10.0], [3 * x[1], 3 * x[0]]])

    lo, hi = np.array([-10.0, 0.0]), np.array([10.0, 5.0])
    r = geodesic_lm(fun, np.array([3.0, 0.0]), jac, (lo, hi), max_nfev=200, chi2_tol=1e-10)
    assert r.status == 1, r.message
    assert np.allclose(r.x, [1.0, 0.0], atol=1e-5) and abs(2 * r.cost - 100.0) < 1e-5
    assert r.nfev < 20
    assert all(np.all(x >= lo) and np.all(x <= hi) for x in seen)


def test_a_parameter_leaving_its_bound_is_probed_on_one_side():
    """x1 starts on its lower bound and the step moves it inward: the acceleration's
    probes go forward (x + h v, x + 2 h v), not one of them clipped back onto the bound
    (which put the residuals' slope into their second difference): the minimum (1, 1) in
    7 evaluations; 53 with the clipped central probe."""
    r = geodesic_lm(
        lambda x: np.array([x[0] - 1.0, x[1] - 1.0]), np.array([3.0, 0.0]), lambda x: np.eye(2),
        (np.array([-10.0, 0.0]), np.array([10.0, 5.0])), max_nfev=200, chi2_tol=1e-12,
    )  # fmt: skip
    assert r.status == 1 and np.allclose(r.x, [1.0, 1.0], atol=1e-5), r.message
    assert r.nfev <= 10


def test_a_step_that_couples_a_parameter_out_of_its_bound_holds_it():
    """A linear least squares whose gradient moves x1 (on its lower bound) inward but
    whose damped step, through the columns' coupling, pushes it out: the step is solved
    again with x1 held, and the fit reaches scipy's bounded minimum (x1 on its bound) in
    10 evaluations; with the outward step merely clipped it took 25, and before the
    bounds were held at all it was out of 100 evaluations 0.04 away."""
    from scipy.optimize import lsq_linear

    a = np.array([[1.22, 0.89], [-0.88, -0.74], [1.75, 1.52]])
    b = np.array([2.56, 0.10, 0.04])
    lo, hi = np.array([-20.0, 0.0]), np.array([20.0, 20.0])
    x0 = np.array([-1.43, 0.0])
    assert (a.T @ (a @ x0 - b))[1] < 0  # the descent moves x1 inward
    ref = lsq_linear(a, b, bounds=(lo, hi), tol=1e-14).x
    assert ref[1] < 1e-12  # the minimum on x1's bound
    r = geodesic_lm(lambda x: a @ x - b, x0, lambda x: a, (lo, hi), max_nfev=100, chi2_tol=1e-12)
    assert r.status == 1 and np.allclose(r.x, ref, atol=1e-6), (r.x, ref, r.message)
    assert r.nfev <= 12
