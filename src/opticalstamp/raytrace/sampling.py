"""Lambertian ray sources and their importance-sampling tables.

A source is a rectangle (a pixel's sensitive area, paper Fig. 4's virtual source, or an
object area) or a point (paper Fig. 10's object point) that emits Lambertian light into
the first slab of a :class:`~opticalstamp.geometry.Path`.

Plain sampling draws the position uniformly over the rectangle and the invariant
direction s uniformly over the disk |s| <= n0 (the Lambertian law in phase space).
Importance sampling instead picks a hole j of the first mask met with probability q_j
(proportional to the etendue from the source centre to that hole, over *every* hole of
the array), a uniform point in that hole, and the direction joining the two points
through the layered slabs; the weight A_hole / (q_j |J|) with J = d(x_t)/d(s) makes the
estimator unbiased (tested against plain sampling).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .stack import Path


@dataclass(frozen=True)
class Source:
    """A Lambertian emitter: a rectangle ``width`` x ``height`` (0 x 0: a point).

    Weights are etendue (um^2 sr) per ray for an area and fraction of emitted power per
    ray for a point.
    """

    x: float
    y: float
    width: float = 0.0
    height: float = 0.0

    @property
    def is_point(self) -> bool:
        return self.width == 0.0 and self.height == 0.0

    @property
    def area(self) -> float:
        return self.width * self.height


@dataclass(frozen=True)
class Targets:
    """Alias table over the holes of the first mask met (importance sampling)."""

    x: np.ndarray
    y: np.ndarray
    prob: np.ndarray
    alias: np.ndarray
    q_per_area: np.ndarray
    n_pre: int


def _reach(rho: np.ndarray, d: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d, n = d[d > 0], n[d > 0]  # a slab of no thickness carries the ray no distance
    c = np.sqrt(n[None, :] ** 2 - rho[:, None] ** 2)
    dr = (d / c).sum(axis=1)
    dd = (d * n**2 / c**3).sum(axis=1)
    return rho * dr, dd * dr


def solve_rho(r: np.ndarray, d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """|s| that carries a ray a lateral distance ``r`` across slabs (d, n) (vectorised)."""
    n_min = n.min()
    d_eq = (d * n_min / n).sum()
    rho = n_min * r / np.sqrt(d_eq**2 + r**2)
    d, n = d[d > 0], n[d > 0]  # the ray crosses a slab of no thickness at no distance
    for _ in range(60):
        f = _reach(rho, d, n)
        c = np.sqrt(n[None, :] ** 2 - rho[:, None] ** 2)
        fp = (d * n**2 / c**3).sum(axis=1)
        new = rho - (f[0] - r) / fp
        new = np.where(new >= n_min, 0.5 * (rho + n_min), np.where(new <= 0, 0.5 * rho, new))
        done = np.abs(new - rho).max(initial=0.0) <= 1e-15 * n_min
        rho = new
        if done:
            break
    return rho


def jacobian(r: np.ndarray, d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """|d(x_t, y_t) / d(s_x, s_y)| for lateral distance ``r`` across slabs (d, n)."""
    return _reach(solve_rho(r, d, n), d, n)[1]


def alias_table(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vose's alias method for drawing index i with probability p_i (p sums to 1).

    Compiled (:func:`_vose`); the tables are bit for bit those of the plain-Python loop
    (the same stacks, popped and pushed in the same order, the same float64 arithmetic).
    """
    scaled = np.ascontiguousarray(p * p.size)
    if scaled.dtype != np.float64:  # the loop's arithmetic is in p's own precision
        return _vose_python(scaled)
    prob = np.ones(scaled.size)
    alias = np.arange(scaled.size, dtype=np.int64)
    _vose(scaled, prob, alias)
    return prob, alias


@nb.njit(cache=True, nogil=True)
def _vose(scaled, prob, alias):  # pragma: no cover - compiled
    """Vose's loop on ``scaled`` = p n (changed in place), filling ``prob`` and ``alias``.

    ``small`` and ``large`` are stacks (last in, first out) seeded in index order, as the
    Python lists of :func:`_vose_python`.
    """
    n = scaled.size
    small = np.empty(n, np.int64)
    large = np.empty(n, np.int64)
    ns = 0
    nl = 0
    for i in range(n):
        if scaled[i] < 1.0:
            small[ns] = i
            ns += 1
        elif scaled[i] >= 1.0:  # NaN in neither, as with flatnonzero
            large[nl] = i
            nl += 1
    while ns > 0 and nl > 0:
        ns -= 1
        s = small[ns]
        nl -= 1
        g = large[nl]
        prob[s] = scaled[s]
        alias[s] = g
        scaled[g] -= 1.0 - scaled[s]
        if scaled[g] < 1.0:
            small[ns] = g
            ns += 1
        else:
            large[nl] = g
            nl += 1


def _vose_python(scaled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vose's loop in plain Python (for a ``scaled`` = p n that is not float64)."""
    n = scaled.size
    prob = np.ones(n)
    alias = np.arange(n, dtype=np.int64)
    small = list(np.flatnonzero(scaled < 1.0))
    large = list(np.flatnonzero(scaled >= 1.0))
    while small and large:
        s, g = small.pop(), large.pop()
        prob[s], alias[s] = scaled[s], g
        scaled[g] -= 1.0 - scaled[s]
        (small if scaled[g] < 1.0 else large).append(g)
    return prob, alias


#: share of the geometric (defensive) table mixed into a user-given hole allocation
DEFENSIVE_SHARE = 0.1


def site_index(path: Path, row: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Index of lattice site (row, k) in the order of :meth:`Lattice.all_sites`."""
    lat = path.lattice
    return np.asarray(row, np.int64) * (lat.k_hi - lat.k_lo + 1) + np.asarray(k) - lat.k_lo


def hole_targets(path: Path, source: Source, weights: np.ndarray | None = None) -> Targets:
    """Importance table over every hole of the first mask.

    q_j is proportional to the etendue from the source centre to hole j alone; if
    ``weights`` (one per lattice site, >= 0) is given, q = 0.1 q_geometric + 0.9 weights,
    which stays positive for every hole, so the estimator stays unbiased.
    """
    n_pre, hx, hy, area, q = _geometric(path, source)
    if weights is not None and np.sum(weights) > 0:
        q = DEFENSIVE_SHARE * q + (1 - DEFENSIVE_SHARE) * weights / np.sum(weights)
    prob, alias = alias_table(q)
    return Targets(hx, hy, prob, alias, q / area, n_pre)


def geometric_q_per_area(path: Path, source: Source) -> np.ndarray:
    """``hole_targets(path, source).q_per_area`` (the geometric table, no weights), without
    building the alias table."""
    _, _, _, area, q = _geometric(path, source)
    return q / area


def _geometric(path: Path, source: Source) -> tuple:
    """(n_pre, hole x, hole y, hole area, geometric q) of :func:`hole_targets`.

    The targets are the holes of the first mask a finite distance from the source. A mask
    in the source's own plane (an object point at Z = 0 on a design whose reference gap is
    0: the point lies on the top mask) cannot be aimed at; the tracer still meets it at
    the source point, which passes (in a hole) or is absorbed (on the chrome).
    """
    masked = np.flatnonzero(path.slabs[:, 2] >= 0)
    ahead = masked[np.cumsum(path.slabs[:, 0])[masked] > 0]
    if ahead.size == 0:
        raise ValueError("importance sampling needs a mask a finite distance from the source")
    n_pre = int(ahead[0]) + 1
    d, n = path.slabs[:n_pre, 0], path.slabs[:n_pre, 1]
    m0 = int(path.slabs[n_pre - 1, 2])
    lat = path.lattice
    rows, ks = lat.all_sites()
    hx, hy = lat.centers(rows, ks)
    hx = hx + path.masks[m0, 3]
    hy = hy + path.masks[m0, 4]
    r = np.hypot(hx - source.x, hy - source.y)
    area = path.hole_area(m0)
    f = area / jacobian(r, d, n)
    return n_pre, hx, hy, area, f / f.sum()


def weight_bound(
    path: Path,
    source: Source,
    weights: np.ndarray | None = None,
    s2_max: float = float("inf"),
) -> float:
    """The largest weight an importance-sampled ray of :func:`hole_targets` can carry.

    A ray drawn through hole j of the first mask has the weight
    A / (q_j |J(r)|) / area_j (``launch``: etendue um^2 sr for an area source, power
    fraction for a point), times Fresnel and acceptance factors <= 1, where r is the
    lateral distance from its source point to its point in the hole. |J| grows with r
    (:func:`jacobian`), so the weight is at most A area_j / (q_j |J(r_min,j)|), r_min,j
    the least distance between the source and hole j. Holes that only rays outside the
    pixel's acceptance (|s|^2 > ``s2_max``) reach carry no weight and are left out.

    Parameters
    ----------
    path, source, weights : as for :func:`hole_targets` (the same table)
    s2_max : largest accepted |s|^2 of the rays (the pixel's acceptance cone)

    Returns
    -------
    float
        The bound (um^2 sr per ray for an area source); 0 where no hole is accepted.
    """
    n_pre, hx, hy, area, q = _geometric(path, source)
    if weights is not None and np.sum(weights) > 0:
        q = DEFENSIVE_SHARE * q + (1 - DEFENSIVE_SHARE) * weights / np.sum(weights)
    d, n = path.slabs[:n_pre, 0], path.slabs[:n_pre, 1]
    m0 = int(path.slabs[n_pre - 1, 2])
    circle, hw, hh = path.masks[m0, 0] == 1, path.masks[m0, 1], path.masks[m0, 2]
    gx = np.maximum(np.abs(hx - source.x) - source.width / 2, 0.0)
    gy = np.maximum(np.abs(hy - source.y) - source.height / 2, 0.0)
    if circle:  # from the source rectangle to the hole's centre, less its radius
        r_min = np.maximum(np.hypot(gx, gy) - hw, 0.0)
    else:
        r_min = np.hypot(np.maximum(gx - hw, 0.0), np.maximum(gy - hh, 0.0))
    reach = solve_rho(r_min, d, n)
    ok = (reach * reach <= s2_max) & (q > 0)
    if not ok.any():
        return 0.0
    a = 1.0 / (np.pi * float(path.slabs[0, 1]) ** 2) if source.is_point else source.area
    return float(np.max(a * area / (q[ok] * jacobian(r_min[ok], d, n))))
