"""What a fit's images determine (issue 24): the degeneracies named, the directions of
the physical parameters they leave undetermined, on the Jacobian at the optimum."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .fit import Layout

#: Singular value (of the column-normalised Jacobian, over the largest) below which a
#: direction is not seen by the images.
NULL_TOL = 1e-6
#: |correlation| above which two physical parameters are named as hard to tell apart.
CORR_TOL = 0.95


def degeneracies(jac: np.ndarray, lay: Layout, cov: np.ndarray) -> tuple[list[str], set[int]]:
    """Messages naming what the images cannot tell apart, and the physical columns of
    the combinations they do not see at all."""
    names = [lay.params[j].name for j in lay.free]
    nf = lay.n_free
    norms = np.linalg.norm(jac, axis=0)
    msgs, blind = [], set()
    for k in range(nf):
        if norms[k] == 0:
            msgs.append(
                f"{names[k]} is not constrained by these images (none changes with it): "
                f"fix it with --pin {names[k]}=..., or add an image that does (an edge for y)"
            )
            blind.add(k)
    use = norms > 0
    js = jac[:, use] / norms[use]
    _, sv, vt = np.linalg.svd(js, full_matrices=False)
    cols = np.flatnonzero(use)
    for s, v in zip(sv, vt, strict=True):
        if s > NULL_TOL * sv[0]:
            continue
        w = np.zeros(jac.shape[1])
        w[cols] = v
        phys = w[:nf]
        if np.linalg.norm(phys) < 1e-3:
            continue  # nuisance alone
        who = [k for k in range(nf) if abs(phys[k]) > 0.1 * np.abs(phys).max()]
        blind.update(who)
        listed = ", ".join(names[k] for k in who)
        chart = np.linalg.norm(w[nf:]) > 0.3
        why = " (together with the charts' positions)" if chart else ""
        msgs.append(
            f"{listed} are degenerate from these images{why}: one combination of them "
            f"changes no image; fix one with --pin {names[who[0]]}=..., or add an edge at "
            "another height"
        )
    sd = np.sqrt(np.clip(np.diag(cov)[:nf], 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov[:nf, :nf] / np.outer(sd, sd)
    for a in range(nf):
        for b in range(a + 1, nf):
            if a in blind or b in blind or not np.isfinite(corr[a, b]):
                continue
            if abs(corr[a, b]) > CORR_TOL:
                msgs.append(
                    f"{names[a]} and {names[b]} are hard to tell apart from these images "
                    f"(correlation {corr[a, b]:+.3f}): fix one with --pin {names[b]}=..., or "
                    "add an edge at another height"
                )
    return msgs, blind


def weak_directions(jac: np.ndarray, lay: Layout, scale2: float, undetermined: float) -> np.ndarray:
    """(m, free) directions of the physical parameters, in units of their assembly
    scales, that the images do not determine: the right singular vectors of the
    Jacobian's physical columns (each times its assembly scale, the nuisance columns
    projected out) whose standard error s / sigma exceeds ``undetermined`` scales."""
    nf = lay.n_free
    if nf == 0:
        return np.zeros((0, 0))
    scales = np.array([lay.params[j].scale for j in lay.free])
    jp, jn = jac[:, :nf] * scales, jac[:, nf:]
    if jn.shape[1]:
        q, _ = np.linalg.qr(jn)
        jp = jp - q @ (q.T @ jp)
    _, sv, vt = np.linalg.svd(jp, full_matrices=False)
    return vt[sv < np.sqrt(scale2) / undetermined]


#: A held combination's member: a parameter whose component in it (a unit vector of
#: assembly scales) is at least this; it is named in the combination and has no error of
#: its own (``fit._fit``).
MEMBER = 0.1


def combination(v: np.ndarray, names: list[str]) -> dict[str, float]:
    """A held direction as {name: coefficient} over its members (components of at least
    MEMBER), its largest coefficient positive."""
    v = v * np.sign(v[np.argmax(np.abs(v))])
    return {n: round(float(c), 3) for n, c in zip(names, v, strict=True) if abs(c) >= MEMBER}


def names_in(message: str, name: str) -> bool:
    """Whether ``message`` names the parameter ``name`` (as a whole word)."""
    return re.search(rf"(?<![\w.]){re.escape(name)}(?![\w]|\.\w)", message) is not None


def judge_starts(
    fast: list[float], wave: list[float] | None = None
) -> tuple[int, np.ndarray, bool]:
    """The best of the starts' points, by their fast-model chi2 ``fast`` or, where given
    and any is finite, by the wave model's chi2 at them ``wave`` (NaN: a design that
    breaks a rule or passes no light, as infinity).

    Returns (the best point, each point's fast chi2 above the lowest, whether the wave
    model judged).
    """
    f = np.asarray(fast, dtype=float)
    f = np.where(np.isfinite(f), f, np.inf)
    lowest = f - f.min() if np.isfinite(f).any() else np.full(f.shape, np.inf)
    w = None if wave is None else np.asarray(wave, dtype=float)
    by_wave = w is not None and bool(np.isfinite(w).any())
    chis = np.where(np.isfinite(w), w, np.inf) if by_wave else f
    return int(np.argmin(chis)), lowest, by_wave


def starts_apart(
    ends: np.ndarray, chi2s: np.ndarray, best: np.ndarray, sd: np.ndarray, delta: float
) -> dict[int, tuple[float, float]]:
    """Parameters the starts leave undetermined: {column: (lowest, highest)} of those
    that a start fitting the images as well as the best (chi2 within ``delta`` of it)
    puts more than 3 standard errors ``sd`` (the best's) from the best ``best``. The
    local errors cannot see another valley; the starts can.

    ``ends``: (starts, free) each start's minimum; ``chi2s``: their chi2.
    """
    good = ends[chi2s <= chi2s.min() + delta]
    far = np.abs(good - best) > 3 * np.where(np.isfinite(sd), sd, np.inf)
    return {
        int(k): (float(good[:, k].min()), float(good[:, k].max()))
        for k in np.flatnonzero(far.any(axis=0))
    }


#: The errors' check by secants (:func:`secant_check`): each principal direction of the
#: physical parameters' covariance is probed SECANT_AT errors either way of the optimum ...
SECANT_AT = 3.0
#: ... and widened where the sum of squares rises there by less than this fraction of
#: the SECANT_AT^2 x error scale^2 its quadratic model predicts (its error x 2 at least).
SECANT_MIN = 0.25
#: A secant probe whose sum of squares lies this many error scale^2 below the optimum's
#: shows that the fit stopped short of a minimum: it fits again from there
#: (:func:`descend`; at most ``fit.DESCENTS`` times).
DESCEND_MIN = 1.0


def secant_check(
    sumsq, theta: np.ndarray, cov: np.ndarray, scale2: float, scales: np.ndarray, keep
) -> tuple[np.ndarray, list[dict]]:
    """The covariance ``cov`` of the fit at ``theta`` checked against the sum of squares
    itself, away from the optimum: the errors from the Jacobian there are the inverse
    curvature at one point, which a curved or flat valley (the wave fit's layer shifts
    on bench_fit.py --wave's charts: two paths of its polish ended 1 chi2 apart with
    layer 1 at +0.7 and -2.5 um, stated error 0.8 um) makes far too small.

    Along each principal direction e of the physical block (in assembly ``scales``;
    physical columns ``keep`` only), with its error s_e, the profile step d = SECANT_AT
    s_e (e and the other columns' shift that the covariance's regression gives) is
    taken either way; where ``sumsq`` (points (m, p) -> their sums of squares, the data
    and the held directions' penalty, the caller minimising what it will at each probe;
    NaN where it cannot evaluate one: that side is not measured) rises by a mean
    fraction rho < SECANT_MIN of the SECANT_AT^2 scale2 a quadratic would, the
    direction's variance is divided by rho (error x 100 where rho <= 1e-4: a fall along
    it, the point no minimum there). The other physical columns are not minimised at the
    probes, so rho is at least the profile's: a direction flagged is looser still.
    Directions of round-off variance (below 1e-12 of the largest) are not probed.

    Returns (the covariance widened, one record per direction widened: "direction" (free
    columns' coefficients in assembly scales, unit length), "rise" (the two rises),
    "expected", "factor" (error multiplier), "error_scales" (its error now, in assembly
    scales)).
    """
    keep = np.asarray(sorted(keep), dtype=int)
    if keep.size == 0:
        return cov, []
    s = scales[keep]
    cpp = cov[np.ix_(keep, keep)]
    lam, vec = np.linalg.eigh(cpp / np.outer(s, s))
    regress = cov[:, keep] @ np.linalg.pinv(cpp, hermitian=True)
    steps, dirs = [], []
    for k in range(lam.size):
        if not lam[k] > 1e-12 * lam.max():
            continue
        dp = SECANT_AT * np.sqrt(lam[k]) * vec[:, k] * s
        steps.append(regress @ dp)
        dirs.append(k)
    if not steps:
        return cov, []
    pts = np.array([theta + sign * d for d in steps for sign in (1.0, -1.0)])
    rise = np.asarray(sumsq(np.vstack([theta[None], pts])), dtype=float)
    rise = rise[1:] - rise[0]
    expected = SECANT_AT**2 * scale2
    out, found = cov.copy(), []
    for i, k in enumerate(dirs):
        both = rise[2 * i : 2 * i + 2]
        if np.isnan(both).all():  # both probes beyond a bound: not measured
            continue
        rho = float(np.nanmean(both)) / expected
        if rho >= SECANT_MIN:
            continue
        rho = max(rho, 1e-4)
        u = steps[i] / SECANT_AT  # one error along the profile
        out += (1 / rho - 1) * np.outer(u, u)
        e = np.zeros(scales.size)
        e[keep] = vec[:, k] * np.sign(vec[np.argmax(np.abs(vec[:, k])), k])
        found.append(
            {
                "direction": e,
                "rise": [float(r) for r in both],
                "expected": float(expected),
                "factor": float(1 / np.sqrt(rho)),
                "error_scales": float(np.sqrt(lam[k] / rho)),
            }
        )
    return out, found


def name_undetermined(
    lay: Layout, cov: np.ndarray, msgs: list[str], blind: set[int], undetermined: float
) -> None:
    """Each free parameter whose error lies beyond ``undetermined`` x its assembly scale
    named (in ``msgs``) and marked (in ``blind``) as not determined."""
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    for k in range(lay.n_free):
        p = lay.params[lay.free[k]]
        if k not in blind and sd[k] > undetermined * p.scale:
            blind.add(k)
            msgs.append(
                f"{p.name} is not determined by these images (standard error "
                f"{sd[k]:.3g} um, over {undetermined:g} x its assembly scale {p.scale:g} um): "
                f"fix it with --pin {p.name}=..., or add images at other heights"
            )


def secant_estimate(prob, theta: np.ndarray, est: tuple, undetermined: float, runs=None):
    """``est`` (the fit's estimate at the optimum of the problem ``prob``: chi2, dof,
    error scale^2, covariance, messages, blind, weak directions) with its covariance checked by
    secants (:func:`secant_check`: 2 evaluations a free parameter, side by side
    on the wave fit's ``runs``, each image's nuisance parameters fitted again there from
    where the step put them) and widened along each direction where the sum of squares
    rises far less than its curvature at the optimum says, each such direction named.
    Returns (the estimate, the check's record, the directions (m, free) now beyond
    ``undetermined`` assembly scales: not determined, for the hold rounds, the lowest
    probe where its sum of squares lies over DESCEND_MIN error scale^2 below the
    optimum's (its fall, the point with its nuisance fitted again), else None)."""
    chi2, dof, scale2, cov, msgs, blind, weak = est
    lay = prob.lay
    names = [lay.params[j].name for j in lay.free]
    scales = np.array([lay.params[j].scale for j in lay.free])
    nf = lay.n_free
    lo, hi = (b[:nf] for b in prob.bounds())

    def inside(p) -> bool:  # within the physical parameters' bounds (the nuisance clipped)
        return bool(np.all((p[:nf] >= lo) & (p[:nf] <= hi)))

    def one(p) -> tuple[np.ndarray, float]:  # (the point, nuisance fitted; its sum)
        if not inside(p) or prob.spreads(lay.physical(p)) is None:
            return p, np.nan  # beyond a bound, a design rule broken or no light: not measured
        q = prob.fit_nuisance(p, search=False)
        return q, float(np.sum(prob.residuals(q) ** 2))

    probed = []

    def sumsq(points):
        ins = [p for p in points if inside(p)]
        pooled = None if runs is None else runs.refits(prob, ins)
        done = {} if pooled is None else {p.tobytes(): v for p, v in zip(ins, pooled, strict=True)}
        new = [done[k] if (k := p.tobytes()) in done else one(p) for p in points]
        probed.extend(new)
        return [v for _, v in new]

    keep = [k for k in range(lay.n_free) if k not in blind]
    cov, found = secant_check(sumsq, theta, cov, scale2, scales, keep)
    lower = None
    if len(probed) > 1:
        at_opt = probed[0][1]  # the optimum is the first point evaluated
        point, low = min(probed[1:], key=lambda pv: np.inf if np.isnan(pv[1]) else pv[1])
        if at_opt - low > DESCEND_MIN * scale2:
            lower = (float(at_opt - low), point)
    msgs, blind = list(msgs), set(blind)
    for f in found:
        f["message"] = secant_words(f, names)
        f["held"] = bool(f["error_scales"] > undetermined)
        msgs.append(f["message"])
    name_undetermined(lay, cov, msgs, blind, undetermined)
    record = {
        "method": f"secants {SECANT_AT:g} errors either way along each principal direction "
        f"of the physical parameters; widened where chi2 rises by less than {SECANT_MIN:g} "
        "of the quadratic's rise",
        "widened": [
            {"direction": combination(f["direction"], names)}
            | {k: f[k] for k in ("rise", "expected", "factor", "message", "held")}
            for f in found
        ],
    }
    loose = [f["direction"] for f in found if f["held"]]
    loose = np.array(loose) if loose else np.zeros((0, lay.n_free))
    return (chi2, dof, scale2, cov, msgs, blind, weak), record, loose, lower


def descend(prob, theta: np.ndarray, est: tuple, lower, refit, estimate):
    """The fit taken on from a secant probe below its optimum (``lower`` from
    :func:`secant_estimate`): ``refit(problem, start) -> (theta, problem)`` from the
    probe (the ray fit's refit also from nominal, the lower kept), kept where it ends
    below the optimum's chi2. Returns (theta, problem, estimate, record: the chi2 before
    and after, and the probe's fall in the sums the check compares) or None."""
    fall, point = lower
    t, p = refit(prob, point)
    new = estimate(p, t)
    if not new[0] < est[0]:
        return None
    return t, p, new, {"chi2_from": float(est[0]), "fall": fall, "chi2_to": float(new[0])}


def stopped_short(fall: float, descents: int) -> str:
    """The words for a fit left with a secant probe ``fall`` below its optimum."""
    return (
        f"the fit stopped short of a minimum: a secant probe lies {fall:.3g} below its chi2 "
        f"after {descents} descent(s) from such probes; its errors are those of a point that "
        "is no minimum: fit again with more starts, or pin what the images do not determine"
    )


def secant_words(f: dict, names: list[str]) -> str:
    """A direction that :func:`secant_check` widened, in words."""
    terms = " ".join(f"{c:+.2f} {n}" for n, c in combination(f["direction"], names).items())
    rises = " and ".join(f"{r:+.3g}" for r in f["rise"] if r == r)  # NaN: not measured
    fall = " (a fall: the point is no minimum along it)" if np.nanmean(f["rise"]) < 0 else ""
    return (
        f"the combination {terms} (each in its assembly scale) is determined less well "
        f"than the curvature at the optimum says: {SECANT_AT:g} errors either way along it, "
        f"chi2 changes by {rises} where a rise of {f['expected']:.3g} was expected{fall}; "
        f"its members' errors are widened along it ({f['factor']:.3g} x)"
    )


def joined(weak: np.ndarray, more: np.ndarray) -> np.ndarray:
    """The directions ``weak`` (m, free), unit length, and those of ``more`` that they do
    not already span (what is left of each, if over half its length, normalised)."""
    rows = list(weak)
    for v in more:
        if rows:
            q, _ = np.linalg.qr(np.array(rows).T)
            v = v - q @ (q.T @ v)
        if np.linalg.norm(v) > 0.5:
            rows.append(v / np.linalg.norm(v))
    return np.array(rows) if rows else np.zeros((0, weak.shape[1]))
