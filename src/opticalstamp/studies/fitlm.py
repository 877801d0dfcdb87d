"""Levenberg-Marquardt with geodesic acceleration (Transtrum & Sethna, arXiv:1201.5885,
2012): the least squares of the wave fit's own model (issue 24), whose minimum lies at
the end of a long, curved, narrow valley.

A plain trust-region method (scipy's ``trf``) crawls along such a valley: its linear
model of the residuals holds only over a short step, so each Jacobian (one wave run a
physical parameter) buys a small step. The geodesic acceleration adds the second-order
term of the residuals along the step, measured by one more run: r'' = (2/h)((r(x + h v)
- r(x))/h - J v), a = -(J^T J + lambda D)^-1 J^T r'', step v + a/2, so that the step
follows the valley's bend. A step whose acceleration is large against its velocity
(2|a|/|v| > ``alpha``, D-norm) is not trusted: the damping rises and the step is
shorter.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass
class LMResult:
    """What :func:`geodesic_lm` found: ``x``, its ``cost`` (half the sum of squares, as
    scipy's), evaluations of the residuals (``nfev``) and of the Jacobian (``njev``),
    ``status`` (> 0 converged, 0 out of evaluations, < 0 no step lowers the cost at any
    damping) and ``message``."""

    x: np.ndarray
    cost: float
    nfev: int
    njev: int
    status: int
    message: str


#: The smallest scaling D (Marquardt's) of a parameter, relative to the largest: a
#: parameter whose residuals barely move here (the charts blind to it at this point) is
#: damped as one this much less stiff than the stiffest. Without it, its step is as long
#: as the damping leaves it (none), is clipped onto a bound and the acceleration's
#: probes there read the model's far side: from drawn starts on bench_fit.py's charts
#: (paraxial model, default free set) every step was refused at chi2 7700-16400 until
#: the damping stopped the fit, where with it each fit reached chi2 3441-3596, the
#: minima scipy's trf finds.
D_FLOOR = 1e-10
#: Where the acceleration's two probes go, in steps h v: central (1, -1) where both lie
#: within the bounds, else one-sided, forward (1, 2) or backward (-1, -2)
PROBES = ((1.0, -1.0), (1.0, 2.0), (-1.0, -2.0))


def _solve(m: np.ndarray, b: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.solve(m, b)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(m, b, rcond=None)[0]


def geodesic_lm(
    fun: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    jac: Callable[[np.ndarray], np.ndarray],
    bounds: tuple[np.ndarray, np.ndarray],
    *,
    max_nfev: int = 100,
    max_njev: int = 30,
    chi2_tol: float = 0.02,
    h: float = 0.1,
    alpha: float = 0.75,
    lam0: float = 1e-3,
    lam_max: float = 1e12,
    ahead: Callable[[list[np.ndarray]], None] | None = None,
    broyden: int = 0,
) -> LMResult:
    """Minimise sum(fun(x)^2) within ``bounds`` from ``x0``.

    Each iteration: the velocity v = -(J^T J + lambda D)^-1 J^T r; the second
    directional derivative of the residuals along it, central (r(x + h v) - 2 r(x) +
    r(x - h v)) / h^2 (two evaluations, which ``ahead`` may run side by side: it is
    given both points first; a forward difference against J v would carry the
    Jacobian's own difference error, which dominates as the steps shrink), one-sided
    (x + h v and x + 2 h v, or backwards) where a bound would cut a central probe; the
    acceleration a from it as v from r; the step v + a/2, tried only if 2|a|/|v| <=
    ``alpha`` (D-norm). D is the largest diagonal of J^T J met so far (Marquardt's
    scaling, invariant to the parameters' units), at least :data:`D_FLOOR` of its
    largest; lambda / 3 after an accepted step, x 2 after a refused one or one whose
    acceleration is not trusted. A parameter on a bound that the gradient or the step
    would push out of it is held there (the decrement, the step and its acceleration
    solved among the others); steps are clipped to the bounds.

    ``broyden``: after an accepted step the Jacobian is updated along it (Broyden's rank-one
    update, D-weighted: J + (r_new - r - J dx) (D dx)^T / (dx^T D dx), which makes J dx
    the residuals' actual change) instead of computed again, up to ``broyden`` steps in a
    row; a full Jacobian follows a step that an updated one let raise the sum of squares
    (a step whose acceleration is not trusted is damped on the updated one, as on a full
    one: the bend of the valley, not the Jacobian, refused it), and only a full one may
    declare convergence (0: a full Jacobian after every step). Along a long valley a
    Jacobian costs one evaluation a parameter and an updated one nothing, so the steps
    come several times cheaper (Transtrum & Sethna, above, §5). On the wave fit's
    default free set (bench_fit.py --wave, 2026-11-27) a full Jacobian after every refusal
    on an updated one took 34 Jacobians and 924 wave runs without converging (at most
    400 evaluations); after refused trials only, 25 and 649, converged.

    Stops (status): 1, the Gauss-Newton decrement g^T (J^T J)^+ g (the fall of
    sum(fun^2) that the linear model still predicts) is below ``chi2_tol``; 2, the
    damped step's predicted fall is below it (no step the model is trusted for would
    lower sum(fun^2) by more: a flat, non-quadratic direction); 0, ``max_nfev``
    evaluations or ``max_njev`` Jacobians made; -1, lambda beyond ``lam_max``. A step
    that lowered it by little is no stop: along a curved valley every step does (the
    wave fit's default free set stopped so at chi2 2921.1, 3 above a fit of three of its
    parameters with the rest at nominal).
    """
    lo, hi = (np.asarray(b, dtype=float) for b in bounds)
    pad = 1e-9 * (np.abs(np.where(np.isfinite(lo), lo, 0)) + 1)
    lo_in, hi_in = lo + pad, hi - pad

    def clip(x):
        return np.clip(x, lo_in, hi_in)

    x = clip(np.asarray(x0, dtype=float))
    r = fun(x)
    c = float(r @ r)
    nfev, njev, lam = 1, 0, lam0
    dmax = np.zeros(x.size)
    jj = None
    updated, refresh = 0, False  # steps since the last full Jacobian (Broyden updates)
    status, message = 0, "the most evaluations allowed were made"
    while nfev + 3 <= max_nfev:
        if jj is not None and updated and (refresh or updated > broyden):
            jj, refresh = None, False  # an updated Jacobian refused a step, or aged
        if jj is None:
            if njev >= max_njev:
                message = "the most Jacobians allowed were made"
                break
            jj = jac(x)
            njev += 1
            updated, refresh = 0, False
        a_mat, g = jj.T @ jj, jj.T @ r
        # the updated Jacobians' diagonals too: from full ones only, the default free set
        # of bench_fit.py --wave took another path along its valley and stopped at chi2
        # 2915.03 (lambda 8.8e-5, the Gauss-Newton decrement 0.19: a near-stationary
        # point of the linear model, docs/fit.md) where this reached 2900.58
        dmax = np.maximum(dmax, np.diag(a_mat))
        d = np.where(dmax > 0, dmax, 1.0)
        # a column (nearly) flat here is damped as one at D_FLOOR of the stiffest: without
        # a floor its step is unbounded, lands on a bound and the probes there say nothing
        d = np.maximum(d, D_FLOOR * dmax.max())
        # a parameter on a bound that the descent pushes out of it stays there: the
        # decrement, the step and its acceleration among the others, so that the step
        # moves every coordinate it changes as the linear model says
        free = ~(((x <= lo_in) & (g > 0)) | ((x >= hi_in) & (g < 0)))
        s = 1 / np.sqrt(d[free])
        gs = g[free] * s
        a_free = a_mat[np.ix_(free, free)]
        decrement = float(gs @ np.linalg.pinv(a_free * np.outer(s, s), rcond=1e-12) @ gs)
        if decrement < chi2_tol:
            if updated:  # an updated Jacobian's word is no convergence: a full one first
                refresh = True
                continue
            status = 1
            message = f"the Gauss-Newton decrement {decrement:.3g} < {chi2_tol:g}"
            break
        m = a_mat + lam * np.diag(d)
        for _ in range(x.size):  # the step too may push one out (its coupling)
            v = np.zeros_like(x)
            v[free] = -_solve(m[np.ix_(free, free)], g[free])
            out = ((x <= lo_in) & (v < 0)) | ((x >= hi_in) & (v > 0))
            if not out.any():
                break
            free &= ~out
        pred = -float(2 * g @ v + v @ a_mat @ v)
        if pred < chi2_tol and updated:
            refresh = True
            continue
        if pred < chi2_tol:
            status = 2
            message = f"the damped step's predicted fall {pred:.3g} < {chi2_tol:g}"
            break
        # the probes at t1 h v and t2 h v: central where both lie inside the bounds, else
        # one-sided (a probe clipped on one side only puts a first difference into the
        # second: a parameter on a bound that the step moves inward)
        for t1, t2 in PROBES:  # the first pair within the bounds
            if all(np.array_equal(clip(x + k * h * v), x + k * h * v) for k in (t1, t2)):
                break
        else:
            t1, t2 = PROBES[0]
        pts = [clip(x + t1 * h * v), clip(x + t2 * h * v)]
        if ahead is not None:
            ahead(pts)
        r1, r2 = fun(pts[0]), fun(pts[1])
        nfev += 2
        if (t1, t2) == PROBES[0]:
            d2 = (r1 - 2 * r + r2) / h**2
        else:  # the second difference of the parabola through (0, r), (t1, r1), (t2, r2)
            d2 = 2 * ((r1 - r) / t1 - (r2 - r) / t2) / (t1 - t2) / h**2
        acc = np.zeros_like(v)
        acc[free] = -_solve(m[np.ix_(free, free)], (jj.T @ d2)[free])
        tried = 2 * np.sqrt(acc @ (d * acc)) <= alpha * np.sqrt(v @ (d * v))
        if tried:
            xn = clip(x + v + acc / 2)
            rn = fun(xn)
            nfev += 1
            cn = float(rn @ rn)
            if cn < c:  # a small fall is no stop: in a curved valley the falls are small
                if broyden > 0:  # Broyden's update along the step (D-weighted)
                    dx = xn - x
                    dd = d * dx
                    jj = jj + np.outer(rn - r - jj @ dx, dd) / float(dx @ dd)
                    updated += 1
                else:
                    jj = None
                x, r, c = xn, rn, cn
                lam = max(lam / 3, 1e-12)
                continue
        if updated and tried:  # its step raised the sum: a full Jacobian before more damping
            refresh = True
            continue
        lam *= 2
        if lam > lam_max:
            if updated:  # only a full Jacobian's word says no step lowers it
                refresh = True
                continue
            status, message = -1, "no step lowers the sum of squares"
            break
    return LMResult(x, c / 2, nfev, njev, status, message)
