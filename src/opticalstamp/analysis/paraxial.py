"""The paraxial closed form of the own path for rectangular holes.

In the paraxial limit a ray of invariant direction s = n sin(theta) moves t s / n in a
slab of thickness t and index n, so the phase-space region of rays that pass the pixel and
every hole is an intersection of strips: the responsivity is separable, R(X, Y) =
r_x(X) r_y(Y), with r_x(X) the length of an intersection of intervals in s, piecewise
linear in X. Its total, G_x G_y, does not depend on Z. The traced LSFs these are checked
against, and :class:`~opticalstamp.analysis.lsf.FoldedLSF`, are in :mod:`.lsf`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..design import Design, square_holes
from ..raytrace.stack import lattice_of
from .lsf import FoldedLSF
from .tallies import fold_bins


@dataclass(frozen=True)
class _Axis:
    """One axis of the paraxial model, read from the design once.

    ``d`` (um): reduced heights of the pixel (0) and of each mask; ``half``, ``off``: their
    half widths and offsets along the axis; ``top``: the reduced height of the reference
    plane; ``n_obj``: the object medium's index.
    """

    d: np.ndarray
    half: np.ndarray
    off: np.ndarray
    top: float
    n_obj: float

    @classmethod
    def of(cls, design: Design, axis: int) -> _Axis:
        if any(m.shape == "circle" for m in design.masks):
            raise ValueError(
                "paraxial closed form needs rectangular holes (shape square/rectangle)"
            )
        s = design.sensor
        d, half, off = [0.0], [(s.sensitive_width_um, s.sensitive_height_um)[axis] / 2], [0.0]
        red = 0.0
        for sl in design.slabs:
            red += sl.thickness_um / design.index(sl.medium)
            m = sl.mask_top
            if m is not None:
                d.append(red)
                half.append((m.hole_width_um, m.hole_height_um)[axis] / 2)
                off.append((m.offset_x_um, m.offset_y_um)[axis])
        gap = design.reference_gap
        red += gap.thickness_um / design.index(gap.medium)
        n_obj = design.index(design.object_medium)
        return cls(np.array(d), np.array(half), np.array(off), red, n_obj)

    def levers(self, z_mm: float) -> np.ndarray:
        """Distance (reduced, um) from each plane up to the object plane at z_mm (>= 0)."""
        big_d = self.top + z_mm * 1000.0 / self.n_obj
        return big_d - self.d

    def at(self, z_mm: float) -> tuple[_Axis, np.ndarray, tuple[float, float]]:
        """The planes below the object plane with their levers, and the window in U.

        A mask in the object plane (lever 0: a reference gap of 0 at Z = 0, the document
        on the top mask) bounds U itself, |U - o| <= h, whatever the slope: it is left out
        of the strips in s and returned as the window ``(lo, hi)`` (infinite otherwise).
        """
        lev = self.levers(z_mm)
        flat = lev <= 0
        if not flat.any():
            return self, lev, (-np.inf, np.inf)
        keep = ~flat
        win = (
            float((self.off - self.half)[flat].max()),
            float((self.off + self.half)[flat].min()),
        )
        sub = _Axis(self.d[keep], self.half[keep], self.off[keep], self.top, self.n_obj)
        return sub, lev[keep], win


def paraxial_profile(design: Design, z_mm: float, u_um: np.ndarray, axis: int = 0) -> np.ndarray:
    """r(U): phase-space length in s of own-path rays meeting the object plane at U.

    ``u_um`` is measured from the pixel's axis along x (axis 0) or y (axis 1).
    The integral of r over U is the own path's 1-D etendue G (um), the same at every Z.
    """
    return _profile(_Axis.of(design, axis), z_mm, u_um)


def _profile(ax: _Axis, z_mm: float, u_um: np.ndarray) -> np.ndarray:
    sub, lev, (lo, hi) = ax.at(z_mm)
    u = np.asarray(u_um, dtype=np.float64)
    return np.where((lo <= u) & (u <= hi), _profile_at(sub, lev, u), 0.0)


def _profile_at(ax: _Axis, lev: np.ndarray, u_um: np.ndarray) -> np.ndarray:
    """r(U) for the levers ``lev``: max and min over the planes taken plane by plane
    (the same values as a reduction over a plane axis, without its short inner loop)."""
    u = np.asarray(u_um, dtype=np.float64)
    lo = hi = None
    for o, h, le in zip(ax.off, ax.half, lev, strict=True):
        a = (u - o - h) / le
        b = (u - o + h) / le
        lo = a if lo is None else np.maximum(lo, a)
        hi = b if hi is None else np.minimum(hi, b)
    return np.maximum(hi - lo, 0.0)


#: Steepest own-path slope |s| (n sin theta) up to which the paraxial closed form stands in
#: for the tracer unasked (the scan's ``--kernel auto``): tan and sin then differ by < 5 %.
PARAXIAL_MAX_SLOPE = 0.3


def paraxial_max_slope(design: Design) -> float:
    """Bound on the steepest own-path ray, |s| = n sin(theta), over both axes.

    A ray passing planes i and j (the pixel, each mask) has |s| <= (h_i + h_j +
    |o_i - o_j|) / |d_i - d_j| (half widths h, offsets o, reduced heights d); the least
    of these over every pair bounds the own path. The prototype's is 0.033 (the pixel
    and layer 1); a stack much thinner than its holes has one far above 1, where the
    paraxial model (slopes unbounded, tan = sin) no longer describes it.
    Circular holes count as their circumscribed squares.
    """
    sq = square_holes(design)
    out = 0.0
    for axis in (0, 1):
        ax = _Axis.of(sq, axis)
        i, j = np.triu_indices(ax.d.size, 1)
        bound = (ax.half[i] + ax.half[j] + np.abs(ax.off[i] - ax.off[j])) / (ax.d[j] - ax.d[i])
        out = max(out, float(bound.min()))
    return out


def paraxial_support(design: Design, z_mm: float, axis: int = 0) -> tuple[float, float]:
    """Edges of the paraxial own-path profile (um from the pixel's axis).

    r(U) > 0 where every lower limit (U - o_i - h_i) / L_i stays below every upper
    limit (U - o_j + h_j) / L_j; each pair is a linear inequality in U.
    """
    return _support(_Axis.of(design, axis), z_mm)


def _pairs(lev: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Levers L (> 0) and a[i, j] = 1/L_i - 1/L_j, with where |a| is large enough to
    divide by."""
    inv = 1 / lev
    a = inv[:, None] - inv[None, :]
    return lev, a, np.abs(a) >= 1e-15


def _support(ax: _Axis, z_mm: float) -> tuple[float, float]:
    sub, lev, win = ax.at(z_mm)
    return _support_of(sub, *_pairs(lev), win)


def _support_of(
    ax: _Axis, lev: np.ndarray, a: np.ndarray, ok: np.ndarray, window=(-np.inf, np.inf)
) -> tuple:
    rhs = ((ax.off + ax.half) / lev)[:, None] - ((ax.off - ax.half) / lev)[None, :]
    r = rhs[ok] / a[ok]
    up = a[ok] > 0
    hi = min(window[1], r[up].min(initial=np.inf))
    lo = max(window[0], r[~up].max(initial=-np.inf))
    return (float(lo), float(hi)) if lo < hi else (0.0, 0.0)


def _kinks(ax: _Axis, z_mm: float) -> np.ndarray:
    """Every U where the piecewise-linear profile can bend, within its support."""
    sub, lev, win = ax.at(z_mm)
    pairs = _pairs(lev)
    return _kinks_of(sub, *pairs, _support_of(sub, *pairs, win))


def _kinks_of(ax: _Axis, lev, a, ok, support: tuple[float, float]) -> np.ndarray:
    lo, hi = support
    pts = [np.array([lo, hi])]
    for si in (-1, 1):
        for sj in (-1, 1):
            u = ((ax.off + si * ax.half) / lev)[:, None] - ((ax.off + sj * ax.half) / lev)[None, :]
            u = u[ok] / a[ok]
            pts.append(u[(lo <= u) & (u <= hi)])
    return np.unique(np.concatenate(pts))


def paraxial_cumulative(design: Design, z_mm: float, u_um: np.ndarray, axis: int = 0):
    """Exact integral of r from -inf to U (r is linear between kinks)."""
    return _cumulative(_Axis.of(design, axis), z_mm, u_um)


def _cumulative(ax: _Axis, z_mm: float, u_um: np.ndarray) -> np.ndarray:
    return _Slice(ax, z_mm).cumulative(u_um)


class _Slice:
    """The paraxial profile of one axis at one Z: levers, support, kinks and the running
    integral at the kinks, computed once for every evaluation of :meth:`cumulative`."""

    def __init__(self, ax: _Axis, z_mm: float) -> None:
        ax, lev, win = ax.at(z_mm)  # a mask in the object plane: a window in U
        lev, a, ok = _pairs(lev)
        self.ax, self.lev = ax, lev
        self.support = _support_of(ax, lev, a, ok, win)
        k = _kinks_of(ax, lev, a, ok, self.support)
        rk = _profile_at(ax, lev, k)
        self.k, self.rk = k, rk
        self.cum = np.concatenate([[0.0], np.cumsum(np.diff(k) * (rk[1:] + rk[:-1]) / 2)])

    def cumulative(self, u_um: np.ndarray) -> np.ndarray:
        """Exact integral of r from -inf to U."""
        k, rk = self.k, self.rk
        u = np.clip(np.asarray(u_um, dtype=np.float64), k[0], k[-1])
        i = np.clip(np.searchsorted(k, u, side="right") - 1, 0, k.size - 1)
        return self.cum[i] + (u - k[i]) * (rk[i] + _profile_at(self.ax, self.lev, u)) / 2


class OwnPath:
    """The paraxial own path of one design, both axes read from it once: its profile's
    :class:`_Slice` (support, exact cumulative) at any Z, as :func:`paraxial_support` and
    :func:`paraxial_cumulative` give them (the same arithmetic), for a caller that asks
    for many heights or both of a slice's figures (the fit's spreads)."""

    def __init__(self, design: Design) -> None:
        self.axes = (_Axis.of(design, 0), _Axis.of(design, 1))

    def at(self, z_mm: float, axis: int) -> _Slice:
        """The profile of ``axis`` at ``z_mm``: ``.support`` (lo, hi) and
        ``.cumulative(u)``."""
        return _Slice(self.axes[axis], z_mm)


def paraxial_etendue_1d(design: Design, axis: int = 0) -> float:
    """G along one axis (um): the integral of :func:`paraxial_profile`, Z-independent."""
    return float(paraxial_cumulative(design, 0.0, np.array([np.inf]), axis)[0])


def paraxial_etendue(design: Design) -> float:
    """Own-path etendue (um^2 sr) in the paraxial limit: G_x G_y."""
    return paraxial_etendue_1d(design, 0) * paraxial_etendue_1d(design, 1)


def paraxial_lsf(design: Design, z_mm: float, x_um: np.ndarray) -> np.ndarray:
    """Own-path LSF (um sr per um) at X = x_um from the pixel's axis: r_x(X) G_y."""
    return paraxial_profile(design, z_mm, x_um, 0) * paraxial_etendue_1d(design, 1)


def paraxial_folded_lsf(design: Design, *, z_mm, periods_um) -> FoldedLSF:
    """Fold the paraxial own-path LSF onto each period (exact bin integrals)."""
    zs = np.asarray(z_mm, dtype=np.float64)
    per = np.asarray(periods_um, dtype=np.float64)
    nb = fold_bins(per)
    g_y = paraxial_etendue_1d(design, 1)
    ax = _Axis.of(design, 0)
    lat = lattice_of(design)
    rows = [(float(lat.row_x[r]), float(lat.row_y[r])) for r in range(design.sensor.rows)]
    slices = [_Slice(ax, float(z)) for z in zs]  # one per Z, for every period
    h = []
    for p, n in zip(per, nb, strict=True):
        du = p / n
        arr = np.zeros((len(rows), 1, zs.size, int(n)))
        bins = np.arange(n + 1)[None, :] * du
        for iz, sl in enumerate(slices):
            lo, hi = sl.support
            m0, m1 = int(np.floor(lo / p)) - 1, int(np.ceil(hi / p)) + 1
            edges = np.arange(m0, m1)[:, None] * p + bins
            cum = sl.cumulative(edges)
            folded = (np.diff(cum, axis=1) * g_y).sum(axis=0)
            arr[:, 0, iz] = folded
        h.append(arr)
    return FoldedLSF(zs, per, rows, h, "paraxial", 0, False, False)
