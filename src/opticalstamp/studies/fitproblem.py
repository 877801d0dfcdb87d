"""A fit's problem (issue 24): the parameters' layout, the residuals of the images' data
under a forward model, and their Jacobian.

The residuals are the noise-weighted differences between each image's data
(:mod:`.fitdata`) and the model's values: per bar block ``black + (white - black) F``,
F the fraction of the pixel's spread on white (:func:`~.fitmodel.bar_fraction`), per
edge region the same along the edge's normal (:func:`~.fitmodel.edge_fraction`). The
spread at each height comes from the problem's forward model: by default the fast model
(:func:`~.fitmodel.spreads`, the paraxial own path); the wave fit passes its own
(:mod:`.fitwave`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..design import Design
from ..validate import InputError
from .fitdata import Observation
from .fitmodel import (
    Param,
    Spread,
    bar_fraction,
    chart_blurred,
    design_params,
    edge_fraction,
    smear_of,
    spreads,
    with_params,
)

#: A forward model: (design, heights in mm, motion smear in um, the physical values that
#: made the design) -> {Z: spread}.
Model = Callable[[Design, list, float], dict[float, Spread]]

#: The residual of every datum where the parameters make no design or no light.
BAD_RESIDUAL = 1e4
#: Weight of a held direction's residual (its distance from nominal in assembly scales):
#: its error becomes 1e-4 scales, a constraint.
HOLD_WEIGHT = 1e4
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


def nuisance_start(obs: Observation) -> np.ndarray:
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


def item_fraction(obs: Observation, i: int, sp, nuis: np.ndarray) -> np.ndarray:
    """The white fraction F of an observation's item ``i`` (bar block or edge region)
    under its own four nuisance parameters ``nuis`` (phase/pos, period/slope, black,
    white: the last two unused)."""
    if obs.kind == "bars":
        b = obs.blocks[i]
        return bar_fraction(sp, b.x_um, nuis[1], nuis[0])
    return edge_fraction(sp, obs.edges[i], nuis[0], nuis[1])


def _level(nu: np.ndarray, f: np.ndarray) -> np.ndarray:
    """An item's values ``black + (white - black) F`` under its nuisance ``nu``."""
    return nu[2] + (nu[3] - nu[2]) * f


def _sd(var: np.ndarray) -> np.ndarray:
    """Standard deviations of data of variance ``var`` (at least 1e-9)."""
    return np.maximum(np.sqrt(var), 1e-9)


def predict(obs: Observation, sp, nuis: np.ndarray) -> np.ndarray:
    """The model's values of an observation's data (concatenated as in :func:`data_of`):
    per item ``black + (white - black) F``."""
    out = []
    for i in range(len(obs.items)):
        nu = nuis[4 * i : 4 * i + 4]
        out.append(_level(nu, item_fraction(obs, i, sp, nu)))
    return np.concatenate(out)


def fit_items(obs: Observation, sp, nuis: np.ndarray, lo: np.ndarray, hi: np.ndarray, steps):
    """An observation's nuisance parameters ``nuis`` fitted by least squares with the
    spread ``sp`` held, each item (bar block, edge region) on its own
    (:func:`_fit_item`): its four parameters move its own data only, so the image's
    problem is block-diagonal and its minimum is the items' minima."""
    out = np.array(nuis, dtype=np.float64)
    for i in range(len(obs.items)):
        sl = slice(4 * i, 4 * i + 4)
        out[sl] = _fit_item(obs, i, sp, out[sl], lo[sl], hi[sl], steps[sl])
    return out


def _fit_item(obs: Observation, i: int, sp, nu0, lo, hi, h) -> np.ndarray:
    """Item ``i``'s four nuisance parameters by least squares, its Jacobian's black and
    white columns exact (the model is linear in them: (1 - F) / s and F / s), its
    phase/pos and period/slope ones by forward differences of ``h`` (as
    :meth:`Problem.jacobian`): a twentieth of the image-wide finite differences'
    evaluations on the bar charts."""
    it = obs.items[i]
    inv = 1.0 / _sd(it.var)
    memo: dict = {}

    def frac(nu):  # F at the point, once for the residuals and the Jacobian
        key = (float(nu[0]), float(nu[1]))
        if key not in memo:
            memo.clear()
            memo[key] = item_fraction(obs, i, sp, nu)
        return memo[key]

    def res(nu):
        return (_level(nu, frac(nu)) - it.value) * inv

    def jac(nu):
        f = frac(nu)
        r0 = _level(nu, f)
        j = np.empty((f.size, 4))
        for k in (0, 1):
            t = nu.copy()
            t[k] += h[k]
            j[:, k] = (_level(t, item_fraction(obs, i, sp, t)) - r0) * inv / h[k]
        j[:, 2] = (1.0 - f) * inv
        j[:, 3] = f * inv
        return j

    nu0 = np.clip(nu0, lo + 1e-9, hi - 1e-9)
    return least_squares(res, nu0, jac=jac, bounds=(lo, hi), x_scale="jac").x


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
    v = np.concatenate([it.value for it in obs.items])
    return v, _sd(np.concatenate([it.var for it in obs.items]))


class Problem:
    """A fit's residuals and Jacobian, with the spreads cached by physical values."""

    def __init__(
        self,
        design: Design,
        observations: list[Observation],
        layout: Layout,
        hold: np.ndarray | None = None,
        prior: float = 0.0,
        model: Model = spreads,
    ):
        """``hold``: (m, free) directions, in units of each parameter's assembly scale,
        along which the fit is held at nominal (rows of weight HOLD_WEIGHT appended to
        the residuals); ``prior``: the weight of every free parameter's distance from
        nominal in assembly scales (a search's first stage; 0: none); ``model``: the
        forward model, (design, heights, smear, physical values) -> {Z: spread} (default
        the fast one,
        :func:`~.fitmodel.spreads`)."""
        self.model = model
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

    def offset(self, theta: np.ndarray) -> np.ndarray:
        """The free physical parameters' distance from nominal, in assembly scales."""
        return (theta[: self.lay.n_free] - self._nominal) / self._scales

    def penalty(self, theta: np.ndarray) -> np.ndarray:
        """The held directions' residuals (HOLD_WEIGHT x their distance from nominal) and
        the prior's."""
        d = self.offset(theta)
        out = HOLD_WEIGHT * self.hold @ d
        return np.concatenate([out, self.prior * d]) if self.prior else out

    def onto_held(self, theta: np.ndarray) -> np.ndarray:
        """``theta`` with its physical part moved onto the combinations held at nominal
        (its :meth:`offset` without its component along each held direction), where its
        penalty is 0."""
        if not self.hold.shape[0]:
            return theta
        d = self.offset(theta)
        q, _ = np.linalg.qr(self.hold.T)
        out = theta.copy()
        out[: self.lay.n_free] = self._nominal + self._scales * (d - q @ (q.T @ d))
        return out

    def spreads(self, phys: np.ndarray) -> list:
        """Each observation's spread at these physical values, or None where the design
        is not one (a rule broken) or passes no light (the optimiser is sent back)."""
        key = phys.tobytes()
        if key not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            try:
                d = with_params(self.design, list(self.lay.params), phys)
                by_z = self.model(d, sorted({o.z_mm for o in self.obs}), self.smear, phys)
                # each image's chart drawn in its own pixels (none: the spread itself)
                self._cache[key] = [chart_blurred(by_z[o.z_mm], o.chart_um) for o in self.obs]
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

    def column_points(self, theta: np.ndarray) -> list[tuple[float, np.ndarray]]:
        """(step, point) of each physical column's forward difference: a step of
        :meth:`steps` up, or down where up would leave the parameter's bounds."""
        h, out = self.steps(theta), []
        for k in range(self.lay.n_free):
            t = theta.copy()
            p = self.lay.params[self.lay.free[k]]
            step = h[k] if t[k] + h[k] <= p.hi else -h[k]
            t[k] += step
            out.append((step, t))
        return out

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """Forward differences: every image for a physical column, one image's residuals
        for its own nuisance columns (the spreads reused); the black and white levels'
        columns exact (the model is linear in them: 1 - F and F over the item's noise)."""
        r0 = self.residuals(theta)
        sps = self.spreads(self.lay.physical(theta))
        sizes = [self.data[i][0].size for i in range(len(self.obs))]
        starts = np.concatenate([[0], np.cumsum(sizes)])
        jac = np.zeros((r0.size, theta.size))
        h = self.steps(theta)
        for k, (step, t) in enumerate(self.column_points(theta)):
            jac[:, k] = (self.residuals(t) - r0) / step
        for i, (sl, names) in enumerate(self.lay.nuis):
            a = starts[i]
            level = [n.rsplit(".", 1)[1] for n in names]  # 4 an item: phase/pos, ...
            unit = theta[sl].copy()  # every item's black 0, white 1: the fractions F
            unit[[m for m, n in enumerate(level) if n == "black"]] = 0.0
            unit[[m for m, n in enumerate(level) if n == "white"]] = 1.0
            inv = 1.0 / self.data[i][1]
            frac = predict(self.obs[i], sps[i], unit) * inv
            ends = a + np.cumsum([0] + [it.value.size for it in self.obs[i].items])
            for k in range(sl.start, sl.stop):
                which = level[k - sl.start]
                item = (k - sl.start) // 4
                lo, hi = ends[item], ends[item + 1]
                if which in ("black", "white"):  # (1 - F) / s, F / s on the item's rows
                    f = frac[lo - a : hi - a]
                    jac[lo:hi, k] = f if which == "white" else inv[lo - a : hi - a] - f
                    continue
                # phase/pos, period/slope: its own item's rows only (the others' are 0)
                nu = theta[sl.start + 4 * item : sl.start + 4 * item + 4].copy()
                nu[(k - sl.start) % 4] += h[k]
                pred = _level(nu, item_fraction(self.obs[i], item, sps[i], nu))
                v, s = self.data[i][0][lo - a : hi - a], self.data[i][1][lo - a : hi - a]
                jac[lo:hi, k] = ((pred - v) / s - r0[lo:hi]) / h[k]
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
            start = nuisance_start(o)
            for k, n, v in zip(range(sl.start, sl.stop), names, start, strict=True):
                if n.endswith("period_um"):
                    lo[k], hi[k] = v * (1 - PERIOD_TOL), v * (1 + PERIOD_TOL)
                elif n.endswith("phase_um"):
                    per = start[k - sl.start + 1]
                    lo[k], hi[k] = -2 * per, 3 * per
                elif n.endswith("black") or n.endswith("white"):
                    lo[k], hi[k] = -0.5, 1.5
        return lo, hi

    def fit_nuisance(self, theta: np.ndarray, search: bool = True) -> np.ndarray:
        """Each image's nuisance parameters fitted with the physical ones held: the bar
        blocks' phases first by a search over one period (a block past the RMTF's zero
        shows its bars in reverse; ``search=False``: from where they are), then every
        nuisance parameter by least squares."""
        theta = theta.copy()
        lo, hi = self.bounds()
        sps = self.spreads(self.lay.physical(theta))
        if sps is None:
            return theta
        h = self.steps(theta)
        for i, (sl, _) in enumerate(self.lay.nuis):
            if search and self.obs[i].kind == "bars":
                theta[sl] = _phase_search(self.obs[i], sps[i], theta[sl])
            theta[sl] = fit_items(self.obs[i], sps[i], theta[sl], lo[sl], hi[sl], h[sl])
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
