"""The own-path etendue of rectangular holes, exact and deterministic (no rays).

A ray leaves the pixel's sensitive area at (x0, y0) with invariant direction
s = rho (cos phi, sin phi) (rho = n sin(theta), the same in every slab). Up to the exit
plane of slab i it has moved a_i (cos phi, sin phi) with the *reach*
a_i(rho) = rho sum_{j <= i} t_j / sqrt(n_j^2 - rho^2) (exact refraction). For a fixed
direction, every test the tracer makes on the way is an interval for x0 and one for y0:
the sensitive area, the own hole of each mask (its misregistration included) and the
edge of the plates on every exit plane (:data:`~opticalstamp.raytrace.stack.PLATE_MARGIN_UM`).
The rays of that direction that follow the own path therefore start in a rectangle of
area L_x(cos phi) L_y(sin phi), each side the length of an intersection of intervals:

    L_x(c) = max(0, min_i (u_i - a_i c) - max_i (l_i - a_i c)),

piecewise linear in c = cos phi (and L_y in sin phi), with its kinks where two of the
lines l_i - a_i c, u_i - a_i c cross. The etendue (measure dx dy dsx dsy, um^2 sr) is

    G = integral_0^rho_max rho F(rho) Theta(rho) d rho,
    Theta(rho) = integral_0^2pi L_x(cos phi) L_y(sin phi) d phi.

For each rho, Theta is summed in closed form between consecutive kinks (a product of
a + b cos phi and c + d sin phi). What is left, the integral over rho, is Gauss-Legendre
on panels that end where a kink line becomes tangent to the circle |s| = rho (there
Theta has a (rho - rho*)^(3/2) term; a cubic change of variable on each panel smooths
it). rho_max is the smallest of: total internal reflection (the smallest index of the
slabs, the reference gap and the object medium, as the tracer kills those rays), the
pixel's acceptance cone (:func:`~opticalstamp.raytrace.pixel.acceptance_s2`) and the
support of the own path. F is 1, or with ``fresnel`` the unpolarised transmittance of
the whole stack, (prod T_s + prod T_p) / 2, a function of rho alone (the tracer's rule).

In the paraxial limit (a_i = rho sum t_j / n_j) L_x depends on s_x alone and G is the
closed form G_x G_y of :func:`~opticalstamp.analysis.paraxial.paraxial_etendue`; exact
refraction moves rays slightly further (t s / sqrt(n^2 - s^2) > t s / n), so G is a
little smaller: 0.046 % for the paper's prototype.
"""

from __future__ import annotations

import numpy as np

from ..design import Design
from ..raytrace.pixel import acceptance_s2
from ..raytrace.stack import Path, reverse_path
from ..validate import InputError

#: Gauss-Legendre nodes per panel of the integral over |s| (the default resolution).
ORDER = 12
#: Panels between consecutive breakpoints of |s| are cut at most this wide (in |s|).
MAX_PANEL = 0.05


def rectangular_holes(design: Design) -> bool:
    """Whether every mask of ``design`` has rectangular (or square) holes."""
    return all(m.shape != "circle" for m in design.masks)


def own_etendue(
    design: Design,
    *,
    pixel: tuple[int, int] = (0, 0),
    fresnel: bool = False,
    order: int = ORDER,
) -> float:
    """Own-path etendue (um^2 sr) of a used pixel, by deterministic quadrature.

    The exact value of what :func:`~opticalstamp.analysis.ghosts.analyse_ghosts`
    estimates as ``etendue_own_um2sr`` (same stack, exact refraction, total internal
    reflection, the pixel's acceptance cone, the plates' edges), for rectangular holes.

    Parameters
    ----------
    design : Design, with rectangular or square holes in every mask
    pixel : (row, k), the used pixel (row 0 = A, 1 = B; k = 0 is mid-array)
    fresnel : include unpolarised Fresnel transmission losses at every interface
    order : Gauss-Legendre nodes per panel of the integral over |s| (the default gives
        about 1e-7 relative accuracy on the presets; doubling it checks convergence)

    Returns
    -------
    float
        G (um^2 sr): the power the pixel receives through its own holes from a uniform
        Lambertian object of unit radiance.

    Raises
    ------
    ValueError
        For circular holes (their own-path light is traced).
    InputError
        For a pixel that is not a used pixel of the design.
    """
    if not rectangular_holes(design):
        raise ValueError("own_etendue needs rectangular holes (this design has circles)")
    path = reverse_path(design)
    lat, (row, k) = path.lattice, pixel
    if not (0 <= row < lat.n_rows and lat.k_lo <= k <= lat.k_hi):
        raise InputError(f"pixel: no used pixel ({row}, {k})")
    geo = _Geometry.of(design, path, pixel)
    rho_max = min(geo.n_min, np.sqrt(acceptance_s2(design, geo.n[0])), geo.support())
    if rho_max <= 0:
        return 0.0
    edges = np.unique(np.concatenate([[0.0, rho_max], geo.tangencies(rho_max)]))
    edges = _refined(edges, MAX_PANEL)
    t, wt = np.polynomial.legendre.leggauss(order)
    t = (t + 1) / 2
    step = t * t * (3 - 2 * t)  # cubic change of variable: flat at both panel ends
    jac = 6 * t * (1 - t) * wt / 2
    lo, width = edges[:-1, None], np.diff(edges)[:, None]
    rho = (lo + width * step).ravel()
    w = (width * jac).ravel()
    f = rho * _theta(geo, rho)
    if fresnel:
        f = f * transmittance(path, rho)
    return float(np.sum(w * f))


def transmittance(path: Path, rho: np.ndarray) -> np.ndarray:
    """Unpolarised Fresnel transmittance of the whole path at |s| = rho, shape of rho.

    (prod T_s + prod T_p) / 2 over every interface where the index changes (the slabs in
    order, then the medium after the last one), as the ray kernel applies it; rho must be
    below every index.
    """
    rho = np.asarray(rho, dtype=np.float64)
    n = np.append(path.slabs[:, 1], path.index_out)
    ps = np.ones_like(rho)
    pp = np.ones_like(rho)
    for n1, n2 in zip(n[:-1], n[1:], strict=True):
        if n1 == n2:
            continue
        a, b = np.sqrt(n1 * n1 - rho * rho), np.sqrt(n2 * n2 - rho * rho)  # n cos(theta)
        rs = (a - b) / (a + b)
        a2, b2 = n2 * n2 * a, n1 * n1 * b  # n2 cos1 and n1 cos2, times n1 n2
        rp = (a2 - b2) / (a2 + b2)
        ps = ps * (1 - rs * rs)
        pp = pp * (1 - rp * rp)
    return 0.5 * (ps + pp)


class _Geometry:
    """The own path's intervals: plane 0 the sensitive area, plane i >= 1 the exit plane
    of slab i - 1 (its own hole where it has a mask, and the plates' edges).

    ``lo[axis, i]``, ``hi[axis, i]``: the interval of x0 (axis 0) or y0 (axis 1), from the
    pixel's centre, that passes plane i for a ray of zero reach; ``d``, ``n``: the slabs'
    thicknesses (um) and indices; ``n_min``: the index below which rays are not totally
    internally reflected anywhere on the way.
    """

    def __init__(self, lo, hi, masked, d, n, n_min):
        self.lo, self.hi, self.masked = lo, hi, masked
        self.d, self.n, self.n_min = d, n, n_min

    @classmethod
    def of(cls, design: Design, path: Path, pixel: tuple[int, int]) -> _Geometry:
        row, k = pixel
        cx, cy = path.lattice.centers(row, k)
        c = np.array([float(cx), float(cy)])
        s = design.sensor
        half = np.array([s.sensitive_width_um, s.sensitive_height_um]) / 2
        lo, hi, masked = [-half], [half], []
        for i, m in enumerate(path.slabs[:, 2]):
            a = -path.limits - c  # the plates' edges, |x| <= limit, from the pixel
            b = path.limits - c
            if m >= 0:
                _, hw, hh, ox, oy = path.masks[int(m)]
                masked.append(i + 1)
                a = np.maximum(a, np.array([ox - hw, oy - hh]))
                b = np.minimum(b, np.array([ox + hw, oy + hh]))
            lo.append(a)
            hi.append(b)
        d, n = path.slabs[:, 0].copy(), path.slabs[:, 1].copy()
        n_min = float(min(n.min(), path.index_out))
        return cls(np.array(lo).T, np.array(hi).T, np.array(masked, int), d, n, n_min)

    def reach(self, rho: np.ndarray) -> np.ndarray:
        """a_i(rho) (um) of every plane, shape (rho.size, n_planes); a_0 = 0."""
        rho = np.atleast_1d(np.asarray(rho, dtype=np.float64))
        step = self.d / np.sqrt(self.n**2 - rho[:, None] ** 2)
        return rho[:, None] * np.concatenate([np.zeros((rho.size, 1)), np.cumsum(step, 1)], 1)

    def lines(self, axis: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every pair (p, q) of the 2 n_planes lines of one axis on different planes:
        (v_p - v_q, plane of p, plane of q), each shape (n_pairs,)."""
        k = self.lo.shape[1]
        v = np.concatenate([self.lo[axis], self.hi[axis]])
        plane = np.concatenate([np.arange(k), np.arange(k)])
        p, q = np.triu_indices(2 * k, 1)
        keep = plane[p] != plane[q]
        p, q = p[keep], q[keep]
        return v[p] - v[q], plane[p], plane[q]

    def support(self) -> float:
        """An upper bound of |s| over the own path: the sensitive area and each hole must
        overlap once shifted by the reach, a_i(rho) <= |corner-to-corner distance|."""
        m = self.masked
        span = np.hypot(*(np.maximum(self.hi[:, m], -self.lo[:, m]) + self.hi[:, :1]))
        return float(self._solve(span, m, np.zeros(m.size, int)).min())

    def tangencies(self, rho_max: float) -> np.ndarray:
        """|s| below ``rho_max`` where a kink line of L_x or L_y is tangent to the circle
        |s| = rho: a_p(rho) - a_q(rho) = +-(v_p - v_q), one root per pair (monotone)."""
        out = []
        for axis in (0, 1):
            dv, p, q = self.lines(axis)
            hi, lo = np.maximum(p, q), np.minimum(p, q)
            ok = np.abs(dv) > 0
            r = self._solve(np.abs(dv[ok]), hi[ok], lo[ok])
            out.append(r[r < rho_max])
        return np.concatenate(out)

    def _solve(self, target: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """rho where a_i(rho) - a_j(rho) = target (i > j), by bisection: the difference
        grows from 0 (rho = 0) to infinity (rho = the smallest index between the planes)."""
        lo = np.zeros(target.size)
        n_cap = np.array([self.n[jj:ii].min() for ii, jj in zip(i, j, strict=True)])
        hi = np.minimum(n_cap, self.n_min)
        for _ in range(64):
            mid = 0.5 * (lo + hi)
            with np.errstate(divide="ignore", invalid="ignore"):
                a = self.reach(mid)
                diff = a[np.arange(mid.size), i] - a[np.arange(mid.size), j]
            big = ~(diff <= target)  # inf or nan where mid rounds to the cap: beyond it
            hi = np.where(big, mid, hi)
            lo = np.where(big, lo, mid)
        return 0.5 * (lo + hi)


def _refined(edges: np.ndarray, widest: float) -> np.ndarray:
    """``edges`` with every gap wider than ``widest`` cut into equal parts."""
    out = [edges[:1]]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        m = max(1, int(np.ceil((b - a) / widest)))
        out.append(np.linspace(a, b, m + 1)[1:])
    return np.concatenate(out)


def _theta(geo: _Geometry, rho: np.ndarray) -> np.ndarray:
    """Theta(rho) = integral over phi of L_x(cos phi) L_y(sin phi) (um^2), shape of rho.

    Exact for each rho: the kinks of L_x (in cos phi) and of L_y (in sin phi) cut
    [0, 2 pi) into arcs on which L_x = ax + bx cos phi and L_y = ay + by sin phi.
    """
    a = geo.reach(rho)  # (N, K)
    cuts = [np.zeros((rho.size, 1)), np.full((rho.size, 1), 2 * np.pi)]
    for axis in (0, 1):
        dv, p, q = geo.lines(axis)
        with np.errstate(divide="ignore", invalid="ignore"):
            c = dv / (a[:, p] - a[:, q])  # v_p - a_p c = v_q - a_q c
        c = np.where(np.abs(c) <= 1, c, np.nan)
        base = np.arccos(c) if axis == 0 else np.arcsin(c)
        other = 2 * np.pi - base if axis == 0 else np.pi - base
        cuts += [np.mod(base, 2 * np.pi), np.mod(other, 2 * np.pi)]
    phi = np.concatenate(cuts, axis=1)
    phi = np.sort(np.where(np.isnan(phi), 2 * np.pi, phi), axis=1)  # padding: empty arcs
    p1, p2 = phi[:, :-1], phi[:, 1:]
    mid = 0.5 * (p1 + p2)
    ax_, bx = _side(geo, a, 0, np.cos(mid))
    ay, by = _side(geo, a, 1, np.sin(mid))
    c1, c2, s1, s2 = np.cos(p1), np.cos(p2), np.sin(p1), np.sin(p2)
    arcs = (
        ax_ * ay * (p2 - p1)
        + ax_ * by * (c1 - c2)
        + bx * ay * (s2 - s1)
        + bx * by * (s2 * s2 - s1 * s1) / 2
    )
    return arcs.sum(axis=1)


def _side(geo: _Geometry, a: np.ndarray, axis: int, c: np.ndarray):
    """(alpha, beta) with L = alpha + beta c on the arc around ``c`` (N, M); 0 where shut.

    L(c) = min_i (hi_i - a_i c) - max_i (lo_i - a_i c): the active lines at the arc's
    midpoint are the active lines over the whole arc.
    """
    ac = a[:, None, :] * c[:, :, None]  # (N, M, K)
    up = geo.hi[axis] - ac
    dn = geo.lo[axis] - ac
    iu = np.argmin(up, axis=2)[..., None]
    il = np.argmax(dn, axis=2)[..., None]
    length = np.take_along_axis(up, iu, 2) - np.take_along_axis(dn, il, 2)
    open_ = length[..., 0] > 0
    a_b = np.broadcast_to(a[:, None, :], ac.shape)
    alpha = geo.hi[axis][iu[..., 0]] - geo.lo[axis][il[..., 0]]
    beta = np.take_along_axis(a_b, il, 2)[..., 0] - np.take_along_axis(a_b, iu, 2)[..., 0]
    return np.where(open_, alpha, 0.0), np.where(open_, beta, 0.0)
