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

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2 as chi2_dist
from threadpoolctl import threadpool_limits

from ..design import Design
from ..validate import InputError
from .fitdata import Observation
from .fitident import combination, degeneracies, names_in, starts_apart, weak_directions
from .fitmodel import (
    Param,
    bar_fraction,
    design_params,
    edge_fraction,
    smear_of,
    spread,
    with_params,
)
from .fitresult import HELD, FitResult

#: A standard error beyond this many times a parameter's assembly scale: the parameter
#: is reported as not determined (its error None), not with false precision.
UNDETERMINED = 10.0
#: The residual of every datum where the parameters make no design or no light.
BAD_RESIDUAL = 1e4
#: Rounds of holding undetermined parameters at nominal and fitting the rest again.
HOLD_ROUNDS = 3
#: Width (assembly scales) of the prior on every parameter in a search's first stage.
PRIOR_SCALES = 1.0
#: Weight of a held direction's residual (its distance from nominal in assembly scales):
#: its error becomes 1e-4 scales, a constraint.
HOLD_WEIGHT = 1e4
#: A direction not determined whose largest component (unit vector) is above this is
#: that one parameter's: the parameter is held (pinned) at nominal.
SINGLE = 0.99
#: How far (relative) a bar block's period may move from the one measured.
PERIOD_TOL = 0.03


class FitError(InputError):
    """A fit that cannot be set up: the message names the argument."""


@dataclass(frozen=True)
class Layout:
    """Where each parameter sits in the vector the optimiser moves.

    ``free``: the physical parameters fitted; ``fixed``: the value of every physical
    parameter (pinned or nominal where not free); ``nuis``: per observation, the slice of
    its nuisance parameters and their names.
    """

    params: tuple[Param, ...]
    free: tuple[int, ...]
    fixed: np.ndarray
    nuis: tuple[tuple[slice, tuple[str, ...]], ...]

    @property
    def n_free(self) -> int:
        return len(self.free)

    def physical(self, theta: np.ndarray) -> np.ndarray:
        v = self.fixed.copy()
        v[list(self.free)] = theta[: self.n_free]
        return v


def _nuisance_names(obs: Observation) -> tuple[str, ...]:
    if obs.kind == "bars":
        names = []
        for i, _ in enumerate(obs.blocks):
            b = f"block{i + 1}"
            names += [f"{b}.phase_um", f"{b}.period_um", f"{b}.black", f"{b}.white"]
        return tuple(names)
    names = []
    for e in obs.edges:
        a = "xy"[e.axis]
        names += [f"edge_{a}.pos_um", f"edge_{a}.slope", f"edge_{a}.black", f"edge_{a}.white"]
    return tuple(names)


def _nuisance_start(obs: Observation) -> np.ndarray:
    if obs.kind == "bars":
        v = []
        for b in obs.blocks:
            v += [b.phase_um, b.period_um, float(b.value.min()), float(b.value.max())]
        return np.array(v)
    v = []
    for e in obs.edges:
        lo, hi = np.percentile(e.value, [5, 95])
        v += [e.pos_um, e.slope, float(lo), float(hi)]
    return np.array(v)


def predict(obs: Observation, sp, nuis: np.ndarray) -> np.ndarray:
    """The model's values of an observation's data (concatenated as in :func:`data_of`)."""
    out = []
    if obs.kind == "bars":
        for i, b in enumerate(obs.blocks):
            phase, per, black, white = nuis[4 * i : 4 * i + 4]
            out.append(black + (white - black) * bar_fraction(sp, b.x_um, per, phase))
        return np.concatenate(out)
    for i, e in enumerate(obs.edges):
        pos, slope, black, white = nuis[4 * i : 4 * i + 4]
        out.append(black + (white - black) * edge_fraction(sp, e, pos, slope))
    return np.concatenate(out)


def _phase_search(obs: Observation, sp, nuis: np.ndarray, n: int = 24) -> np.ndarray:
    """Bar images' nuisance with each block's phase the best of ``n`` over its period
    (black and white levels solved linearly per trial, shading held)."""
    nuis = nuis.copy()
    for i, b in enumerate(obs.blocks):
        per = nuis[4 * i + 1]
        best = (np.inf, nuis[4 * i : 4 * i + 4])
        for ph in nuis[4 * i] + per * np.arange(n) / n:
            f = bar_fraction(sp, b.x_um, per, ph)
            m = np.column_stack([1 - f, f]) / np.sqrt(b.var)[:, None]
            c, *_ = np.linalg.lstsq(m, b.value / np.sqrt(b.var), rcond=None)
            cost = float(np.sum((m @ c - b.value / np.sqrt(b.var)) ** 2))
            if c[1] > c[0] and cost < best[0]:  # white above black
                best = (cost, np.array([ph % per, per, c[0], c[1]]))
        nuis[4 * i : 4 * i + 4] = best[1]
    return nuis


def data_of(obs: Observation) -> tuple[np.ndarray, np.ndarray]:
    """(values, standard deviations) of an observation's data."""
    items = obs.blocks if obs.kind == "bars" else obs.edges
    v = np.concatenate([it.value for it in items])
    s = np.sqrt(np.concatenate([it.var for it in items]))
    return v, np.maximum(s, 1e-9)


class Problem:
    """A fit's residuals and Jacobian, with the spreads cached by physical values."""

    def __init__(
        self,
        design: Design,
        observations: list[Observation],
        layout: Layout,
        hold: np.ndarray | None = None,
        prior: float = 0.0,
    ):
        """``hold``: (m, free) directions, in units of each parameter's assembly scale,
        along which the fit is held at nominal (rows of weight HOLD_WEIGHT appended to
        the residuals); ``prior``: the weight of every free parameter's distance from
        nominal in assembly scales (a search's first stage; 0: none)."""
        self.design = design
        self.obs = observations
        self.lay = layout
        self.smear = smear_of(design)
        self.data = [data_of(o) for o in observations]
        self.n_data = sum(v.size for v, _ in self.data)
        nf = layout.n_free
        self.hold = np.zeros((0, nf)) if hold is None else np.asarray(hold).reshape(-1, nf)
        self._nominal = layout.fixed[list(layout.free)]
        self._scales = np.array([layout.params[j].scale for j in layout.free])
        self.prior = float(prior)
        self._cache: dict[bytes, list] = {}

    def penalty(self, theta: np.ndarray) -> np.ndarray:
        """The held directions' residuals (HOLD_WEIGHT x their distance from nominal) and
        the prior's."""
        d = (theta[: self.lay.n_free] - self._nominal) / self._scales
        out = HOLD_WEIGHT * self.hold @ d
        return np.concatenate([out, self.prior * d]) if self.prior else out

    def spreads(self, phys: np.ndarray) -> list:
        """Each observation's spread at these physical values, or None where the design
        is not one (a rule broken) or passes no light (the optimiser is sent back)."""
        key = phys.tobytes()
        if key not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            try:
                d = with_params(self.design, list(self.lay.params), phys)
                by_z = {z: spread(d, z, self.smear) for z in {o.z_mm for o in self.obs}}
                self._cache[key] = [by_z[o.z_mm] for o in self.obs]
            except ValueError:  # DesignError is one too
                self._cache[key] = None
        return self._cache[key]

    def residual_of(self, i: int, sp, theta: np.ndarray) -> np.ndarray:
        sl, _ = self.lay.nuis[i]
        v, s = self.data[i]
        return (predict(self.obs[i], sp, theta[sl]) - v) / s

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        sps = self.spreads(self.lay.physical(theta))
        if sps is None:
            data = np.full(self.n_data, BAD_RESIDUAL)
        else:
            data = np.concatenate([self.residual_of(i, sp, theta) for i, sp in enumerate(sps)])
        return np.concatenate([data, self.penalty(theta)])

    def steps(self, theta: np.ndarray) -> np.ndarray:
        h = np.empty(theta.size)
        for k, j in enumerate(self.lay.free):
            h[k] = 1e-3 * self.lay.params[j].scale
        for sl, names in self.lay.nuis:
            for k, n in zip(range(sl.start, sl.stop), names, strict=True):
                h[k] = 1e-2 if n.endswith("phase_um") or n.endswith("pos_um") else 1e-5
                if n.endswith("period_um"):
                    h[k] = 1e-4
        return h

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """Forward differences: every image for a physical column, one image's residuals
        for its own nuisance columns (the spreads reused)."""
        r0 = self.residuals(theta)
        sps = self.spreads(self.lay.physical(theta))
        sizes = [self.data[i][0].size for i in range(len(self.obs))]
        starts = np.concatenate([[0], np.cumsum(sizes)])
        jac = np.zeros((r0.size, theta.size))
        h = self.steps(theta)
        for k in range(self.lay.n_free):
            t = theta.copy()
            p = self.lay.params[self.lay.free[k]]
            step = h[k] if t[k] + h[k] <= p.hi else -h[k]
            t[k] += step
            jac[:, k] = (self.residuals(t) - r0) / step
        for i, (sl, _) in enumerate(self.lay.nuis):
            a, b = starts[i], starts[i + 1]
            for k in range(sl.start, sl.stop):
                t = theta.copy()
                t[k] += h[k]
                jac[a:b, k] = (self.residual_of(i, sps[i], t) - r0[a:b]) / h[k]
        return jac

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The physical parameters' bounds; a bar block's period within PERIOD_TOL of
        the one measured (a wider step could jump to an alias of the bars), black and
        white levels in [-0.5, 1.5]."""
        n = sum(sl.stop - sl.start for sl, _ in self.lay.nuis)
        lo = np.full(self.lay.n_free + n, -np.inf)
        hi = np.full(self.lay.n_free + n, np.inf)
        for k, j in enumerate(self.lay.free):
            lo[k], hi[k] = self.lay.params[j].lo, self.lay.params[j].hi
        for o, (sl, names) in zip(self.obs, self.lay.nuis, strict=True):
            start = _nuisance_start(o)
            for k, n, v in zip(range(sl.start, sl.stop), names, start, strict=True):
                if n.endswith("period_um"):
                    lo[k], hi[k] = v * (1 - PERIOD_TOL), v * (1 + PERIOD_TOL)
                elif n.endswith("phase_um"):
                    per = start[k - sl.start + 1]
                    lo[k], hi[k] = -2 * per, 3 * per
                elif n.endswith("black") or n.endswith("white"):
                    lo[k], hi[k] = -0.5, 1.5
        return lo, hi

    def fit_nuisance(self, theta: np.ndarray) -> np.ndarray:
        """Each image's nuisance parameters fitted with the physical ones held: the bar
        blocks' phases first by a search over one period (a block past the RMTF's zero
        shows its bars in reverse), then every nuisance parameter by least squares."""
        theta = theta.copy()
        lo, hi = self.bounds()
        sps = self.spreads(self.lay.physical(theta))
        if sps is None:
            return theta
        for i, (sl, _) in enumerate(self.lay.nuis):
            if self.obs[i].kind == "bars":
                theta[sl] = _phase_search(self.obs[i], sps[i], theta[sl])

            def res(nu, i=i, sl=sl):
                t = theta.copy()
                t[sl] = nu
                return self.residual_of(i, sps[i], t)

            nu0 = np.clip(theta[sl], lo[sl] + 1e-9, hi[sl] - 1e-9)
            theta[sl] = least_squares(res, nu0, bounds=(lo[sl], hi[sl]), x_scale="jac").x
        return theta


def layout_for(
    design: Design,
    observations: list[Observation],
    free: list[str] | None = None,
    pinned: dict[str, float] | None = None,
) -> Layout:
    """The parameters of a fit: ``free`` names (default: every physical parameter not
    pinned), ``pinned`` {name: value} held (``ref``: the offset in um)."""
    params = tuple(design_params(design))
    names = [p.name for p in params]
    pinned = dict(pinned or {})
    for n in list(pinned) + list(free or []):
        if n not in names:
            raise FitError(f"--free/--pin: unknown parameter {n!r} (this design has {names})")
    fixed = np.array([0.0 if p.offset else p.nominal for p in params])
    for n, v in pinned.items():
        j = names.index(n)
        if not params[j].lo <= v <= params[j].hi:
            raise FitError(
                f"--pin {n}={v:g}: outside [{params[j].lo:g}, {params[j].hi:g}] for this design"
            )
        fixed[j] = v
    chosen = names if free is None else list(free)
    both = set(chosen) & set(pinned) if free is not None else set()
    if both:
        raise FitError(f"--free/--pin: {sorted(both)} both free and pinned")
    idx = tuple(j for j, n in enumerate(names) if n in chosen and n not in pinned)
    nuis, at = [], len(idx)
    for o in observations:
        nn = _nuisance_names(o)
        nuis.append((slice(at, at + len(nn)), nn))
        at += len(nn)
    return Layout(params, idx, fixed, tuple(nuis))


def _draw_start(prob: Problem, rng: np.random.Generator) -> np.ndarray:
    lay = prob.lay
    lo, hi = prob.bounds()
    theta = np.zeros(lo.size)
    for k, j in enumerate(lay.free):
        p = lay.params[j]
        v = lay.fixed[j] + p.scale * rng.standard_normal()
        theta[k] = np.clip(v, lo[k] + 1e-6 * p.scale, hi[k] - 1e-6 * p.scale)
    return theta


def _local(prob: Problem, theta0: np.ndarray, max_nfev: int):
    lo, hi = prob.bounds()
    pad = 1e-9 * (np.abs(np.where(np.isfinite(lo), lo, 0)) + 1)
    theta0 = np.clip(theta0, lo + pad, hi - pad)
    theta0 = prob.fit_nuisance(theta0)
    scale = np.abs(prob.steps(theta0)) * 1e3
    return least_squares(
        prob.residuals,
        theta0,
        jac=prob.jacobian,
        bounds=(lo, hi),
        x_scale=scale,
        method="trf",
        tr_solver="exact",
        max_nfev=max_nfev,
    )


def _estimate(prob: Problem, theta: np.ndarray):
    """(chi2, dof, error scale^2, covariance, messages, blind, weak directions) at
    ``theta`` (chi2 and dof of the images' data; the held directions are constraints)."""
    lay = prob.lay
    jac = prob.jacobian(theta)
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
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    for k in range(lay.n_free):  # an error far beyond the assembly scale: not determined
        p = lay.params[lay.free[k]]
        if k not in blind and sd[k] > UNDETERMINED * p.scale:
            blind.add(k)
            msgs.append(
                f"{p.name} is not determined by these images (standard error "
                f"{sd[k]:.3g} um, over {UNDETERMINED:g} x its assembly scale {p.scale:g} um): "
                f"fix it with --pin {p.name}=..., or add images at other heights"
            )
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
    """
    if not observations:
        raise FitError("no images to fit")
    # BLAS on one thread for the fit only (restored on leaving): the solves are small,
    # and OpenBLAS's spinning threads made a fit 5x slower on a loaded 2-core machine
    with threadpool_limits(limits=1, user_api="blas"):
        return _fit(design, observations, free, pinned, starts, seed, max_nfev)


def _fit(design, observations, free, pinned, starts, seed, max_nfev) -> FitResult:
    lay = layout_for(design, observations, free, pinned)
    prob = Problem(design, observations, lay)
    rng = np.random.default_rng([seed, 24])
    n_nu = sum(sl.stop - sl.start for sl, _ in lay.nuis)
    base = np.concatenate([lay.fixed[list(lay.free)], np.zeros(n_nu)])
    for o, (sl, _) in zip(observations, lay.nuis, strict=True):
        base[sl] = _nuisance_start(o)
    runs, ends, best = [], [], None
    for s in range(max(1, starts)):
        t0 = base.copy()
        if s:
            t0[: lay.n_free] = _draw_start(prob, rng)[: lay.n_free]
        # first near the start (a prior of PRIOR_SCALES assembly scales on every
        # parameter: the well-seen ones converge before the barely-seen ones wander
        # into another valley), then free
        first = _local(Problem(design, observations, lay, prior=1 / PRIOR_SCALES), t0, max_nfev)
        r = _local(prob, first.x, max_nfev)
        chi2 = float(2 * r.cost)
        runs.append(
            {
                "start": s,
                "chi2": chi2,
                "nfev": int(first.nfev + r.nfev),
                "status": int(r.status),
            }
        )
        ends.append(r.x)
        if best is None or r.cost < best.cost:
            best = r
    theta = best.x
    for r in runs:  # how far each start's minimum is from the best one
        r["delta_chi2"] = r["chi2"] - float(2 * best.cost)
    chi2, dof, scale2, cov, msgs, blind, weak = _estimate(prob, theta)
    names_now = [lay.params[j].name for j in lay.free]
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))[: lay.n_free]
    delta = scale2 * chi2_dist.ppf(0.95, max(lay.n_free, 1))
    chis = np.array([r["chi2"] for r in runs])
    apart = starts_apart(np.array(ends)[:, : lay.n_free], chis, theta[: lay.n_free], sd, delta)
    for k, (lo, hi) in apart.items():
        msgs.append(
            f"{names_now[k]} is not determined by these images: starts that fit them as "
            f"well (chi2 within {delta:.3g} of the best) put it from {lo:.4g} to {hi:.4g} um "
            f"(error at the best {sd[k]:.2g} um)"
        )
    held: dict[str, float] = {}
    combos: list[dict[str, float]] = []
    said: list[str] = []  # why each held parameter or combination is held
    rows = np.zeros((0, lay.n_free))  # the combinations held, in assembly scales
    extra = set(apart)  # held in the first round with the single directions
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
            said += [m for m in why if m not in said] or [f"{names_now[k]}: {HELD}"]
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
                "members' values and errors are given it; pin one to choose otherwise"
            )
        rows = np.vstack([rows[:, keep]] + [v[None] for v in new])
        lay = layout_for(
            design, observations, [names_now[k] for k in keep], dict(pinned or {}) | held
        )
        prob = Problem(design, observations, lay, hold=rows)
        t0 = np.concatenate([theta[keep], theta[len(names_now) :]])
        theta = _local(prob, t0, max_nfev).x
        chi2, dof, scale2, cov, msgs, blind, weak = _estimate(prob, theta)
    msgs = said + [m for m in msgs if m not in said]
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    nf = lay.n_free
    names = [lay.params[j].name for j in lay.free]
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
    )
