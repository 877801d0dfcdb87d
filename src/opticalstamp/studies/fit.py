"""Fit a design to a prototype's scans of charts (issue 24): which assembly was built?

The data are the images' own profiles (:mod:`.fitdata`: bar waveforms, edge pixels), the
model the design's own-path responsivity (:mod:`.fitmodel`), the estimate the weighted
least squares of :func:`scipy.optimize.least_squares` (trust region, bounds), from
several starts: the nominal design and ``starts - 1`` designs drawn around it at the
parameters' assembly scales (each with its nuisance parameters fitted first, image by
image), the best minimum kept and the others reported.

Uncertainty: the covariance s^2 (J^T J)^-1 at the optimum, J the Jacobian of the
noise-weighted residuals over every free parameter (nuisance included, so their
uncertainty is propagated), s^2 = max(1, chi^2 / dof) (a misfit beyond the noise widens
the errors, never narrows them). Degeneracies: directions of the column-normalised
Jacobian whose singular value is below ``NULL_TOL`` of the largest are combinations the
images do not see at all (their parameters have no standard error: ``None``); pairs of
physical parameters correlated beyond ``CORR_TOL`` are named too (:mod:`.fitident`).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares
from scipy.special import chdtri
from threadpoolctl import threadpool_limits

from ..analysis.responsivity import Optics, resolve_optics
from ..design import Design
from .fitdata import Observation
from .fitident import (
    combination,
    degeneracies,
    descend,
    joined,
    judge_starts,
    name_undetermined,
    names_in,
    secant_estimate,
    starts_apart,
    stopped_short,
    weak_directions,
)
from .fitlm import geodesic_lm
from .fitmodel import smear_of, spreads, with_params
from .fitpool import WaveRuns, wave_pool
from .fitproblem import (  # noqa: F401 - the fit's problem, re-exported
    BAD_RESIDUAL,
    HOLD_WEIGHT,
    PERIOD_TOL,
    FitError,
    Layout,
    Problem,
    data_of,
    layout_for,
    nuisance_start,
    predict,
)
from .fitresult import HELD, FitResult
from .fitwave import WaveModel, held_sampling

#: A standard error beyond this many times a parameter's assembly scale: the parameter
#: is reported as not determined (its error None), not with false precision.
UNDETERMINED = 10.0
#: Said where no start's minimum runs under the wave model.
NO_WAVE_START = (
    "no start's minimum runs under the wave model (a rule broken or no light): the best "
    "start is the fast model's"
)
#: Rounds of holding undetermined parameters at nominal and fitting the rest again.
HOLD_ROUNDS = 3
#: Times at most that a secant probe below the optimum takes the fit on from there.
DESCENTS = 2
#: Width (assembly scales) of the prior on every parameter in a search's first stage.
PRIOR_SCALES = 1.0
#: A direction not determined whose largest component (unit vector) is above this is
#: that one parameter's: the parameter is held (pinned) at nominal.
SINGLE = 0.99
#: The wave model's own least squares (:func:`_polish`) stops where no step it trusts
#: would lower its chi2 by this (or its Gauss-Newton decrement is below it); or after
#: POLISH_JACOBIANS Jacobians (each one wave run a physical parameter) or POLISH_NFEV
#: other evaluations (each one wave run).
POLISH_CHI2 = 0.1
#: The first polish stops at this (the same two rules): there, within about 1 of the
#: optimum, what the wave model leaves undetermined is found and held before the rest
#: is polished to POLISH_CHI2. On bench_fit.py --wave's charts (2026-11-27) the polish
#: went on to 0.1 first and crawled along the layers' x tilt, which the secants then
#: held: 818 wave runs; held at 1.0: 463 runs (docs/fit.md).
POLISH_COARSE = 1.0
POLISH_JACOBIANS = 40
POLISH_NFEV = 400
#: Steps in a row on a Broyden-updated Jacobian between full ones (:func:`~.fitlm.
#: geodesic_lm`): on the default free set (bench_fit.py --wave's charts, 2026-11-26) the
#: polish converged at wave chi2 2900.58 in 28 Jacobians and 302 evaluations (738 wave
#: runs) with 6, 2901.26 in 31 and 363 (844) with 3, where without (a full Jacobian a
#: step) it stood at 2915.73 after 40 and 255 (871), still moving along the valley.
POLISH_BROYDEN = 6
#: The polish's first damping (Marquardt's, relative to J^T J's diagonal): on the default
#: free set its first step was accepted at about 0.5, after 9 refusals from 1e-3.
POLISH_LAMBDA = 0.1
#: The forward model of each engine, in words (fit.json's ``optics``).
FORWARD = (
    ("ray", "paraxial own path (ray optics)"),
    (
        "wave",
        "wave engine's light in its band (own path, diffraction, near crosstalk); the "
        "starts on the paraxial own path corrected by it about the nominal design",
    ),
)


def _draw_start(prob: Problem, rng: np.random.Generator) -> np.ndarray:
    lay = prob.lay
    lo, hi = prob.bounds()
    theta = np.zeros(lo.size)
    for k, j in enumerate(lay.free):
        p = lay.params[j]
        v = lay.fixed[j] + p.scale * rng.standard_normal()
        theta[k] = np.clip(v, lo[k] + 1e-6 * p.scale, hi[k] - 1e-6 * p.scale)
    return theta


def _local(prob: Problem, theta0: np.ndarray, max_nfev: int, ftol: float = 1e-8):
    """One local least squares (trust-region reflective, bounds) from ``theta0``, the
    nuisance parameters fitted first, each parameter's scale a thousand of its
    difference steps (the physical ones: their assembly scales). (scipy's
    ``x_scale="jac"`` took the wave fit's nominal start to the same minimum in 27
    Jacobians instead of 73, but a drawn start to chi2 4870 instead of 3563.)"""
    lo, hi = prob.bounds()
    pad = 1e-9 * (np.abs(np.where(np.isfinite(lo), lo, 0)) + 1)
    theta0 = np.clip(theta0, lo + pad, hi - pad)
    theta0 = prob.fit_nuisance(theta0)
    return least_squares(
        prob.residuals,
        theta0,
        jac=prob.jacobian,
        bounds=(lo, hi),
        x_scale=np.abs(prob.steps(theta0)) * 1e3,
        method="trf",
        tr_solver="exact",
        max_nfev=max_nfev,
        ftol=ftol,
    )


def _start(job) -> dict:
    """One start's local fits (:func:`_fit`): first with a prior of PRIOR_SCALES
    assembly scales on every parameter, then free. Runs in the wave pool's processes
    too (BLAS on one thread, as the fit's own process)."""
    design, observations, lay, model, theta0, max_nfev = job
    with threadpool_limits(limits=1, user_api="blas"):
        prior = Problem(design, observations, lay, prior=1 / PRIOR_SCALES, model=model)
        first = _local(prior, theta0, max_nfev)
        r = _local(Problem(design, observations, lay, model=model), first.x, max_nfev)
    return {
        "x": r.x,
        "cost": float(r.cost),
        "nfev": int(first.nfev + r.nfev),
        "status": int(r.status),
    }


def _refit(prob: Problem, t0: np.ndarray, max_nfev: int) -> np.ndarray:
    """A hold round's refit (the ray stage): from where the fit was and from nominal,
    each moved onto the combinations held (not 10^4 x their distance away in the
    residuals), the lower minimum. Holding an undetermined direction can leave the point
    the fit had reached far from the held problem's best minimum: on the tests' scans a
    start that had put plate 2 at its bound went, with plates 2 and 3 held at nominal,
    to plate 1 at 334 um against 1000 (chi2 1368), where the refit from nominal found
    993 um (chi2 1324)."""
    nominal = t0.copy()
    nominal[: prob.lay.n_free] = [prob.lay.params[j].nominal for j in prob.lay.free]
    runs = [_local(prob, prob.onto_held(t), max_nfev) for t in (t0, nominal)]
    return min(runs, key=lambda r: r.cost).x


def _estimate(prob: Problem, theta: np.ndarray, jac: np.ndarray | None = None):
    """(chi2, dof, error scale^2, covariance, messages, blind, weak directions) at
    ``theta`` (chi2 and dof of the images' data; the held directions are constraints),
    from the Jacobian ``jac`` (default the problem's)."""
    lay = prob.lay
    jac = prob.jacobian(theta) if jac is None else jac
    chi2 = float(np.sum(prob.residuals(theta)[: prob.n_data] ** 2))
    dof = max(prob.n_data - jac.shape[1] + prob.hold.shape[0], 1)
    scale2 = max(1.0, chi2 / dof)
    norms = np.linalg.norm(jac, axis=0)
    norms[norms == 0] = 1.0
    js = jac / norms
    cov = np.linalg.pinv(js.T @ js, rcond=1e-12, hermitian=True) / np.outer(norms, norms)
    cov *= scale2
    msgs, blind = degeneracies(jac, lay, cov)
    weak = weak_directions(jac, lay, scale2, UNDETERMINED)
    name_undetermined(lay, cov, msgs, blind, UNDETERMINED)
    return chi2, int(dof), scale2, cov, msgs, blind, weak


def fit(
    design: Design,
    observations: list[Observation],
    *,
    free: list[str] | None = None,
    pinned: dict[str, float] | None = None,
    starts: int = 3,
    seed: int = 0,
    max_nfev: int = 100,
    optics: str | Optics = "ray",
) -> FitResult:
    """Fit ``design``'s physical parameters to the observations (see the module doc).

    A parameter the images do not determine (none changes with it, its error beyond
    ``UNDETERMINED`` x its assembly scale, or the largest member of a combination no
    image sees) is held at its nominal value and the rest fitted again from the best
    minimum (up to ``HOLD_ROUNDS`` times): the fitted design carries the drawing's value
    there, never wherever the optimiser stopped. ``FitResult.held`` lists them.

    Parameters
    ----------
    design : the nominal design (rectangular holes: the paraxial own path)
    observations : from :func:`~.fitdata.observation`
    free, pinned : see :func:`layout_for`
    starts : local fits, the first from the nominal design
    seed : of the other starts' draws
    optics : "ray", "wave" or "auto" (:func:`~opticalstamp.analysis.responsivity.
        resolve_optics`, resolved once for the nominal design): the forward model is the
        paraxial own path (ray) or the wave engine's light in its band (wave: the starts
        and holds on the former corrected by the latter about the nominal design,
        :mod:`.fitwave`, then the wave model's own least squares, :func:`_polish`)
    """
    if not observations:
        raise FitError("no images to fit")
    opt = resolve_optics(design, optics)
    # BLAS on one thread for the fit only (restored on leaving): the solves are small,
    # and OpenBLAS's spinning threads made a fit 5x slower on a loaded 2-core machine
    with threadpool_limits(limits=1, user_api="blas"):
        if opt.engine != "wave":
            return _fit(design, observations, free, pinned, starts, seed, max_nfev, opt)
        with wave_pool(starts) as pool:
            return _fit(design, observations, free, pinned, starts, seed, max_nfev, opt, pool)


def _fit(design, observations, free, pinned, starts, seed, max_nfev, opt, pool=None):
    lay = layout_for(design, observations, free, pinned)
    zs = sorted({o.z_mm for o in observations})
    wave = None
    if opt.engine == "wave":  # its grids held: no jump as the parameters move
        wave = WaveModel(held_sampling(design, opt.sampling, max(zs)))
        wave = wave.held(design, zs, smear_of(design))
    # the wave model at first: the fast one corrected by the difference at nominal, to
    # first order in the free parameters
    model = spreads
    if wave is not None:
        at = WaveRuns(wave, design, list(lay.params), zs, smear_of(design), pool)
        at.prefetch(wave.points(at.params, lay.fixed, lay.free))
        model = wave.correction(design, at.params, lay.fixed, lay.free, zs, at.smear, wave_at=at)
    prob = Problem(design, observations, lay, model=model)
    rng = np.random.default_rng([seed, 24])
    n_nu = sum(sl.stop - sl.start for sl, _ in lay.nuis)
    base = np.concatenate([lay.fixed[list(lay.free)], np.zeros(n_nu)])
    for o, (sl, _) in zip(observations, lay.nuis, strict=True):
        base[sl] = nuisance_start(o)
    jobs = []
    for s in range(max(1, starts)):
        t0 = base.copy()
        if s:
            t0[: lay.n_free] = _draw_start(prob, rng)[: lay.n_free]
        jobs.append((design, observations, lay, model, t0, max_nfev))
    # the starts side by side where the wave fit has its pool (the same numbers)
    done = pool(_start, jobs) if pool is not None and len(jobs) > 1 else map(_start, jobs)
    runs, ends = [], []
    for s, r in enumerate(done):
        runs.append({"start": s, "chi2": 2 * r["cost"], "nfev": r["nfev"], "status": r["status"]})
        ends.append(r["x"])
    said: list[str] = []  # why each held parameter or combination is held
    wchis = None
    if wave is not None:
        # each start's minimum judged by the model fitted: the fast model corrected about
        # the nominal design holds near it only, and its minima far from it can fit the
        # wave model badly (docs/fit.md, "Held at nominal": the starts disagree)
        judged = _wave_chi2(prob, at, ends)
        wchis = [c for _, c in judged]
        for r, c in zip(runs, wchis, strict=True):
            r["wave_chi2"] = float(c) if np.isfinite(c) else None
    k_best, lowest, by_wave = judge_starts([r["chi2"] for r in runs], wchis)
    if by_wave:
        ends = [q for q, _ in judged]
    elif wave is not None:
        said.append(NO_WAVE_START)
    theta = ends[k_best]
    for r, lo in zip(runs, lowest, strict=True):
        r["delta_chi2"] = float(lo) if np.isfinite(lo) else None
        r["best"] = r["start"] == k_best
    chi2, dof, scale2, cov, msgs, blind, weak = _estimate(prob, theta)
    names_now = [lay.params[j].name for j in lay.free]
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))[: lay.n_free]
    delta = scale2 * chdtri(max(lay.n_free, 1), 0.05)  # chi2's 95 % quantile
    # the starts' disagreement names what the images leave undetermined where the
    # starts' points are minima of the model fitted; under wave optics they are the fast
    # model's (each ~10^3 above the wave model's own optimum on bench_fit.py --wave's
    # charts), and what the wave model leaves undetermined is found at its optimum
    # (the Jacobian's weak directions and the secants, below)
    apart = (
        {}
        if by_wave
        else starts_apart(np.array(ends)[:, : lay.n_free], lowest, theta[: lay.n_free], sd, delta)
    )
    for k, (lo, hi) in apart.items():
        msgs.append(
            f"{names_now[k]} is not determined by these images: starts that fit them as "
            f"well (chi2 within {delta:.3g} of the best) put it from {lo:.4g} to {hi:.4g} um "
            f"(error at the best {sd[k]:.2g} um)"
        )
    held: dict[str, float] = {}
    combos: list[dict[str, float]] = []
    rows = np.zeros((0, lay.n_free))  # the combinations held, in assembly scales
    extra = set(apart)  # held in the first round with the single directions

    def hold_rounds(theta, prob, est, refit):
        """Hold what ``est`` (an :func:`_estimate`) finds undetermined and fit the rest
        again by ``refit(problem, start) -> (theta, problem)``, up to HOLD_ROUNDS times."""
        nonlocal lay, rows, extra
        msgs, weak = est[4], est[6]
        for _ in range(HOLD_ROUNDS):
            if not len(weak) and not extra:
                break
            names_now = [lay.params[j].name for j in lay.free]
            # a direction along one parameter: that parameter held (pinned) at nominal;
            # a combination of several: held at nominal as a combination
            single = {int(np.argmax(np.abs(v))) for v in weak if np.abs(v).max() > SINGLE}
            single, extra = single | extra, set()
            for k in sorted(single):
                j = lay.free[k]
                held[names_now[k]] = float(lay.params[j].nominal)
                why = [m for m in msgs if names_in(m, names_now[k]) and "hard to tell" not in m]
                said.extend([m for m in why if m not in said] or [f"{names_now[k]}: {HELD}"])
            keep = [k for k in range(lay.n_free) if k not in single]
            new = [
                v[keep] / np.linalg.norm(v[keep])
                for v in weak
                if np.abs(v).max() <= SINGLE and np.linalg.norm(v[keep]) > 0.5
            ]
            for v in new:
                combos.append(combination(v, [names_now[k] for k in keep]))
                terms = " ".join(f"{c:+.2f} {n}" for n, c in combos[-1].items())
                said.append(
                    f"the combination {terms} (each in its assembly scale) is {HELD}: its "
                    "members are where the hold puts them, and none has an error of its "
                    "own (each can move along it); pin one to choose otherwise"
                )
            rows = np.vstack([rows[:, keep]] + [v[None] for v in new])
            lay = layout_for(
                design, observations, [names_now[k] for k in keep], dict(pinned or {}) | held
            )
            prob = Problem(design, observations, lay, hold=rows, model=model)
            t0 = np.concatenate([theta[keep], theta[len(names_now) :]])
            theta, prob = refit(prob, t0)
            est = _estimate(prob, theta)
            msgs, weak = est[4], est[6]
        return theta, prob, est

    est = (chi2, dof, scale2, cov, msgs, blind, weak)
    refit = lambda p, t0: (_refit(p, t0, max_nfev), p)  # noqa: E731
    theta, prob, est = hold_rounds(theta, prob, est, refit)
    info = opt.to_dict() | {"forward_model": dict(FORWARD)[opt.engine]}
    if wave is not None:
        # the wave model's own optimum; what it finds undetermined there (the y shifts'
        # tilt, flat and not quadratic, can wander far) is held and polished again
        schemes = []

        def polish(p, t0, tol=POLISH_CHI2):
            # onto the held combinations: not 10^4 x their distance away in the residuals
            t, exact, sc = _polish(p, p.onto_held(t0), at, tol)
            schemes.append(sc)
            return t, exact

        # first to within POLISH_COARSE of the optimum, where what the wave model leaves
        # undetermined (the Jacobian's weak directions, the secants' loose ones: the
        # stack's tilts) is held, then the rest to POLISH_CHI2: the polish would
        # otherwise crawl along those flat valleys, for the hold to put them back
        theta, prob = polish(prob, theta, POLISH_COARSE)
        est = _estimate(prob, theta)
        est, record, loose, _ = secant_estimate(prob, theta, est, UNDETERMINED, at)
        weak = joined(est[6], loose)
        if len(weak):
            said.extend(w["message"] for w in record["widened"] if w["held"])
            theta, prob, est = hold_rounds(theta, prob, est[:6] + (weak,), polish)
        else:
            theta, prob = polish(prob, theta)
            theta, prob, est = hold_rounds(theta, prob, _estimate(prob, theta), polish)
        refit = polish
    # the errors checked by secants: a probe below the optimum takes the fit on from it
    # (descend); what they find undetermined is held as the Jacobian's weak ones are
    memo, passes, rnd, descents = (at if wave is not None else None), [], 0, 0
    while True:
        est, record, loose, lower = secant_estimate(prob, theta, est, UNDETERMINED, memo)
        passes.append(record)
        go = lower is not None and descents < DESCENTS
        descents += go
        moved = descend(prob, theta, est, lower, refit, _estimate) if go else None
        if moved is not None:  # the optimum, on (its Jacobian's weak directions held)
            theta, prob, est, record["descended"] = moved
            for w in record["widened"]:
                w["held"] = False  # the descent, not a hold, followed this check
            theta, prob, est = hold_rounds(theta, prob, est, refit)
            continue
        record |= {} if lower is None else {"below": lower[0]}
        if not len(loose) or rnd == HOLD_ROUNDS:
            said.extend([] if lower is None else [stopped_short(lower[0], descents)])
            break
        rnd += 1
        said.extend(w["message"] for w in record["widened"] if w["held"])
        theta, prob, est = hold_rounds(theta, prob, est[:6] + (loose,), refit)
    info["error_check"] = passes[-1] | {"passes": passes[:-1]}
    if wave is not None:
        info["scheme"] = _schemes(schemes)
    chi2, dof, scale2, cov, msgs, blind, weak = est
    msgs = said + [m for m in msgs if m not in said]
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    nf = lay.n_free
    names = [lay.params[j].name for j in lay.free]
    # a held combination's members can each move along it (the images do not say
    # where): their values are where the hold puts them, none has an error of its own
    # (the errors on the held plane alone had stated 0.08 um for a layer shift 20 of
    # them from the truth: docs/fit.md)
    members = {n for c in combos for n in c}  # its terms: components >= MEMBER
    blind = sorted(set(blind) | {k for k in range(nf) if names[k] in members})
    errors = [None if k in blind else float(sd[k]) for k in range(nf)]
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov[:nf, :nf] / np.outer(sd[:nf], sd[:nf])
    for k in blind:
        corr[k, :] = np.nan
        corr[:, k] = np.nan
    phys = lay.physical(theta)
    fitted = with_params(design, list(lay.params), phys)
    fitted = fitted.model_copy(update={"name": f"{design.name} fitted"})
    nuisance = {}
    for o, (sl, nn) in zip(observations, lay.nuis, strict=True):
        nuisance[o.name] = {
            n: [float(theta[k]), float(sd[k])]
            for n, k in zip(nn, range(sl.start, sl.stop), strict=True)
        }
    return FitResult(
        design=design,
        fitted=fitted,
        names=names,
        values=[float(v) for v in theta[:nf]],
        errors=errors,
        nominal=[float(lay.params[j].nominal) for j in lay.free],
        pinned={n: float(v) for n, v in (pinned or {}).items()},
        correlation=corr,
        degeneracies=msgs,
        chi2=chi2,
        dof=int(dof),
        error_scale=float(np.sqrt(scale2)),
        nuisance=nuisance,
        starts=runs,
        theta=theta,
        held=held,
        held_combinations=combos,
        optics=info,
    )


def _schemes(schemes: list[dict]) -> dict:
    """One record of the wave fit's polishes (the first, and one after each round of
    holding what it found undetermined): counts summed, chi2 from the first's start to
    the last's end, converged and why stopped the last's."""
    last = schemes[-1]
    out = dict(last)
    for key in ("evaluations", "jacobians"):
        out[key] = sum(sc[key] for sc in schemes)
    out["wave_chi2"] = [schemes[0]["wave_chi2"][0], last["wave_chi2"][1]]
    out["polishes"] = len(schemes)
    return out


def _wave_chi2(prob: Problem, runs: WaveRuns, points: list) -> list[tuple[np.ndarray, float]]:
    """Each point of ``prob`` with its images' nuisance fitted again under the wave model
    (``runs``, the fit's) and its chi2 there: side by side on the pool where there is one
    (:meth:`~.fitpool.WaveRuns.refits`), else here; NaN where the point's design breaks
    a rule or passes no light."""
    pooled = runs.refits(prob, points, min_runs=1)
    if pooled is not None:
        return pooled
    exact = _exact(prob, runs)
    out = []
    for p in points:
        if exact.spreads(exact.lay.physical(p)) is None:  # a rule broken or no light
            out.append((p, float("nan")))
            continue
        q = exact.fit_nuisance(p, search=False)
        out.append((q, float(np.sum(exact.residuals(q) ** 2))))
    return out


def _exact(prob: Problem, runs: WaveRuns) -> Problem:
    """``prob`` on the wave model itself (``runs``, the fit's), each Jacobian's wave runs
    side by side first (the polish's and the errors' Jacobians, :func:`_estimate`)."""
    lay = prob.lay
    exact = Problem(prob.design, prob.obs, lay, hold=prob.hold, model=lambda d, z, s, v: runs(v))
    serial = exact.jacobian

    def jacobian(t):
        runs.prefetch(lay.physical(pt) for _, pt in exact.column_points(t))
        return serial(t)

    exact.jacobian = jacobian
    return exact


def _polish(prob: Problem, theta: np.ndarray, runs: WaveRuns, tol: float = POLISH_CHI2):
    """The wave model's optimum from ``theta`` (the optimum of the fast model corrected
    about the nominal design, :mod:`.fitwave`): Levenberg-Marquardt with geodesic
    acceleration (:func:`~.fitlm.geodesic_lm`) on the wave model's own residuals, its
    Jacobian by forward differences of the wave model (1e-3 assembly scales: one wave
    run a physical column, side by side on the pool where there is one; the nuisance
    columns on the same spreads; between full ones updated along each step, Broyden's way,
    up to POLISH_BROYDEN steps in a row), the acceleration's two runs side by side too,
    each point run once (``runs``, the fit's). It stops where no step the model is trusted
    for would lower the wave chi2 by POLISH_CHI2, after POLISH_JACOBIANS Jacobians at
    most.

    Returns (theta, the wave model's problem, scheme: how it ran and converged).
    """
    lay = prob.lay
    exact = _exact(prob, runs)
    theta = exact.fit_nuisance(theta)
    chi_start = float(np.sum(exact.residuals(theta) ** 2))

    def ahead(points):
        runs.prefetch((lay.physical(p) for p in points), min_runs=2)

    lo, hi = exact.bounds()
    r = geodesic_lm(
        exact.residuals,
        theta,
        exact.jacobian,
        (lo, hi),
        max_nfev=POLISH_NFEV,
        max_njev=POLISH_JACOBIANS,
        chi2_tol=tol,
        lam0=POLISH_LAMBDA,
        ahead=ahead,
        broyden=POLISH_BROYDEN,
    )
    scheme = {
        "method": "Levenberg-Marquardt with geodesic acceleration on the wave model's own "
        "residuals (its Jacobian by forward differences of the wave model, Broyden-updated "
        f"for up to {POLISH_BROYDEN} steps between full ones), from the optimum of the fast "
        "model corrected about the nominal design",
        "evaluations": int(r.nfev),
        "jacobians": int(r.njev),
        "wave_chi2": [chi_start, float(2 * r.cost)],
        "converged": bool(r.status > 0),
        "stopped": r.message,
        "wave_runs": runs.runs,
        "jacobian": "the wave model's at the optimum (forward differences of 1e-3 assembly "
        "scales for the physical columns; the nuisance columns on the same spreads)",
    }
    return r.x, exact, scheme
