"""Line-spread functions of the used pixels on the object plane, folded onto chart periods.

A bar chart that varies along x only (paper Eq. 1, Fig. 11) sees a pixel through the
x-marginal of its responsivity map, the *line-spread function* LSF(X) = integral of
R(X, Y) dY (um sr per um of X). For a chart of period P only the LSF folded modulo P
matters: h_P(phi) = sum_m LSF(phi + m P). Both ways to get it are here:

* :func:`traced_folded_lsf` reverse-traces each pixel row once (exact 3-D tracer,
  importance sampling, own and ghost paths, optional Fresnel losses) and folds every ray
  onto every period at every object distance in one compiled pass. Rays are dealt into
  ``n_batches`` interleaved batches (ray id modulo n_batches), which gives the standard
  errors of anything computed from the folded LSF.
* :func:`paraxial_lsf` is the closed form of the own path for rectangular holes in the
  paraxial limit (displacement t s / n in a slab of thickness t and index n for the
  invariant direction s = n sin(theta)): the phase-space region of rays that pass the
  pixel and every hole is an intersection of strips, so R is separable,
  R(X, Y) = r_x(X) r_y(Y), with r_x(X) the length of an intersection of intervals in s,
  piecewise linear in X. Its total, G_x G_y, does not depend on Z.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np

from ..defaults import MAP_MAX_BINS, RAYS_LSF, RAYS_MAP
from ..design import Design, square_holes
from ..raytrace.pixel import PixelTracer, Sampling, tracer_for
from ..raytrace.stack import lattice_of
from ..validate import check_memory

#: Target width of the bins of a folded LSF (um); each period gets round(P / this) bins.
FOLD_BIN_UM = 0.5


@dataclass(frozen=True)
class FoldedLSF:
    """LSFs of the used pixels folded onto chart periods.

    Attributes
    ----------
    z_mm : (nz,) object distances above the reference plane (mm)
    periods_um : (np,) chart periods (um)
    rows : list of (x_um, y_um) of the traced pixel of each row (k = 0)
    h : list over periods of arrays (n_rows, n_batches, nz, n_bins_p): etendue
        (um^2 sr) per bin of phase phi = (X - x_pixel) mod P, summed over batches it is
        the full estimate
    method : "trace" or "paraxial"
    n_rays : rays per row (trace) or 0
    ghosts, fresnel : what light is included
    slope_power : (len(SLOPE_EDGES) - 1,) etendue (um^2 sr) per bin of |dX/dZ|, the
        lateral slope along x of the light in the object medium (traced; None where not
        tallied): how fast its image moves with Z (:func:`fast_light`)
    """

    z_mm: np.ndarray
    periods_um: np.ndarray
    rows: list[tuple[float, float]]
    h: list[np.ndarray]
    method: str
    n_rays: int
    ghosts: bool
    fresnel: bool
    slope_power: np.ndarray | None = None

    @property
    def n_batches(self) -> int:
        return self.h[0].shape[1]


#: bins of the lateral slope |dX/dZ| of the light in the object medium (the last bin
#: takes every slope beyond)
SLOPE_EDGES = np.linspace(0.0, 4.0, 161)


def fast_light(lsf: FoldedLSF) -> dict | None:
    """How fast the light's image moves with Z: ``slope`` (lower edges of SLOPE_EDGES)
    and ``beyond``, the fraction of the light whose lateral slope |dX/dZ| in the object
    medium exceeds each. Light of slope t moves one chart period P in Z = P / t: ghost
    copies of a periodic chart (slopes far from the own path's) make the RMTF oscillate
    with that period in Z, which a coarser grid aliases (:func:`~opticalstamp.analysis.
    rmtf.crossing_brackets` sets its step from this). None where not tallied."""
    if lsf.slope_power is None or lsf.slope_power.sum() <= 0:
        return None
    beyond = np.cumsum(lsf.slope_power[::-1])[::-1] / lsf.slope_power.sum()
    return {"slope": SLOPE_EDGES[:-1].tolist(), "beyond": beyond.tolist()}


def _slopes(b, w: np.ndarray, n_obj: float) -> np.ndarray:
    """Etendue per bin of SLOPE_EDGES of the rays ``b`` (weights ``w``)."""
    keep = w != 0
    sx, sy = b.sx[keep], b.sy[keep]
    c = np.sqrt(np.maximum(n_obj * n_obj - sx * sx - sy * sy, 1e-300))
    t = np.minimum(np.abs(sx) / c, SLOPE_EDGES[-1] * (1 - 1e-12))
    return np.histogram(t, SLOPE_EDGES, weights=w[keep])[0]


@numba.njit(parallel=True, cache=True)
def _fold(x, sx, sy, w, batch, x0, z_um, n_obj, periods, n_bins, out):  # pragma: no cover
    """out[p, b, iz, bin] += w for each ray; prange over z (no write conflicts)."""
    for iz in numba.prange(z_um.size):
        z = z_um[iz]
        for i in range(x.size):
            wi = w[i]
            if wi == 0.0:
                continue
            c = np.sqrt(n_obj * n_obj - sx[i] * sx[i] - sy[i] * sy[i])
            xo = x[i] + z * sx[i] / c - x0
            for p in range(periods.size):
                per = periods[p]
                phi = xo - np.floor(xo / per) * per
                j = int(phi / per * n_bins[p])
                if j >= n_bins[p]:
                    j = n_bins[p] - 1
                out[p, batch[i], iz, j] += wi


def _bins(periods_um: np.ndarray) -> np.ndarray:
    return np.maximum(8, np.round(periods_um / FOLD_BIN_UM)).astype(np.int64)


def row_pixels(design: Design) -> list[tuple[int, int]]:
    """(row, k = 0) of the traced pixel of each row of used pixels."""
    return [(r, 0) for r in range(design.sensor.rows)]


def traced_folded_lsf(
    design: Design,
    *,
    z_mm,
    periods_um,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    ghosts: bool = True,
    fresnel: bool = False,
    n_batches: int = 16,
    chunk: int = 1 << 20,
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
) -> FoldedLSF:
    """Fold each row's traced LSF onto every period at every Z (one trace per row).

    ``sampling`` replaces ``n_rays``, ``seed``, ``fresnel`` and ``chunk`` (its ray count,
    where None, is ``n_rays``; rounded up to a multiple of ``n_batches``). ``tracer``: a
    PixelTracer of this design whose pilot runs to reuse (other analyses of the same
    pixels share them); the sampling is still this call's.
    """
    s = _lsf_sampling(sampling, n_rays, seed, fresnel, chunk, n_batches)
    (lsf,) = _traced_folds(design, (ghosts,), z_mm, periods_um, s, n_batches, progress, tracer)
    return lsf


def traced_folded_lsf_pair(
    design: Design,
    *,
    z_mm,
    periods_um,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    fresnel: bool = False,
    n_batches: int = 16,
    chunk: int = 1 << 20,
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
) -> tuple[FoldedLSF, FoldedLSF]:
    """All light and the own path alone, folded from one trace per row.

    The parameters are those of :func:`traced_folded_lsf`. Each ray is folded twice:
    with its weight, and with its weight where it followed the own path (the tracer's
    own-path mask, :attr:`~opticalstamp.raytrace.pixel.PixelBatch.own`) and 0 elsewhere.

    Returns
    -------
    (FoldedLSF, FoldedLSF)
        Own and ghost light, and the own path only: bit for bit what
        ``traced_folded_lsf(..., ghosts=True)`` and ``(..., ghosts=False)`` return for
        the same arguments, for the cost of one trace.
    """
    s = _lsf_sampling(sampling, n_rays, seed, fresnel, chunk, n_batches)
    both, own = _traced_folds(
        design, (True, False), z_mm, periods_um, s, n_batches, progress, tracer
    )
    return both, own


def folded_subset(lsf: FoldedLSF, z_mm, periods_um) -> FoldedLSF | None:
    """``lsf`` at the given distances and periods only (in the order given), or None where
    ``lsf`` lacks one of them.

    Each (Z, period) of a traced fold is tallied on its own from the same rays in the same
    order, so the subset is bit for bit what the same trace folded onto these distances
    and periods alone gives (same rays, seed, light and Fresnel option).
    """
    zs = np.asarray(z_mm, dtype=np.float64)
    per = np.asarray(periods_um, dtype=np.float64)
    iz = [np.flatnonzero(lsf.z_mm == z) for z in zs]
    ip = [np.flatnonzero(lsf.periods_um == p) for p in per]
    if any(i.size == 0 for i in iz + ip):
        return None
    iz = np.array([i[0] for i in iz])
    h = [np.ascontiguousarray(lsf.h[int(i[0])][:, :, iz, :]) for i in ip]
    return replace(lsf, z_mm=zs, periods_um=per, h=h)


def _lsf_sampling(
    sampling: Sampling | None, n_rays: int, seed: int, fresnel: bool, chunk: int, n_batches: int
) -> Sampling:
    """The sampling of a folded LSF, its ray count rounded up to a multiple of n_batches."""
    if sampling is None:
        sampling = Sampling(n_rays, seed, fresnel, chunk)
    sampling = sampling.or_rays(n_rays)
    return replace(sampling, n_rays=int(np.ceil(sampling.n_rays / n_batches)) * n_batches)


def _traced_folds(
    design: Design,
    kinds: tuple[bool, ...],
    z_mm,
    periods_um,
    sampling: Sampling,
    n_batches: int,
    progress: bool,
    tracer: PixelTracer | None,
) -> list[FoldedLSF]:
    """One trace per row, folded once per entry of ``kinds`` (True: ghost light too)."""
    n_rays = sampling.n_rays
    tr = tracer_for(design, sampling, tracer)
    zs = np.asarray(z_mm, dtype=np.float64)
    per = np.asarray(periods_um, dtype=np.float64)
    nb = _bins(per)
    hs = [[np.zeros((design.sensor.rows, n_batches, zs.size, int(n))) for n in nb] for _ in kinds]
    slope_tallies = [np.zeros(SLOPE_EDGES.size - 1) for _ in kinds]  # over the rows
    rows = []
    for row, k in row_pixels(design):
        src = tr.source((row, k))
        rows.append((src.x, src.y))
        outs = [np.zeros((per.size, n_batches, zs.size, int(nb.max()))) for _ in kinds]
        slopes = [np.zeros(SLOPE_EDGES.size - 1) for _ in kinds]
        on_gpu = None  # the same tallies on the device, where a GPU keeps the rays
        for pb in tr.trace((row, k), progress=progress):
            b = pb.rays
            if b.device is not None:
                from . import cuda_tallies as gpu

                on_gpu = on_gpu or [gpu.zeros(out.shape) for out in outs]
                for ghosts, res in zip(kinds, on_gpu, strict=True):
                    gpu.fold(pb, not ghosts, zs * 1000.0, tr.n_obj, per, nb, n_batches, res)
                continue
            batch = (b.ids % n_batches).astype(np.int64)
            for ghosts, out, sl in zip(kinds, outs, slopes, strict=True):
                w = pb.w if ghosts else pb.w * pb.own
                _fold(b.x, b.sx, b.sy, w, batch, src.x, zs * 1000.0, tr.n_obj, per, nb, out)
                sl += _slopes(b, w, tr.n_obj) / n_rays
        for out, res in zip(outs, on_gpu or (), strict=False):  # nothing on the CPU
            out += res.copy_to_host()
        for tally, sl in zip(slope_tallies, slopes, strict=True):
            tally += sl if on_gpu is None else np.nan  # not tallied on the device
        for h, out in zip(hs, outs, strict=True):
            for p in range(per.size):
                # each batch holds n_rays / n_batches samples: scale so batches sum to the mean
                h[p][row] = out[p, :, :, : nb[p]] / n_rays
    return [
        FoldedLSF(
            zs,
            per,
            rows,
            h,
            "trace",
            n_rays,
            ghosts,
            sampling.fresnel,
            None if np.isnan(sl).any() else sl / len(rows),
        )
        for ghosts, h, sl in zip(kinds, hs, slope_tallies, strict=True)
    ]


# -- paraxial closed form ------------------------------------------------------------------
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
    nb = _bins(per)
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


# -- 2-D responsivity maps for the scan simulation ----------------------------------------
@numba.njit(parallel=True, cache=True)
def _maps(
    x,
    y,
    sx,
    sy,
    w,
    own,
    x0,
    y0,
    z_um,
    n_obj,
    fine_lo,
    fine_bin,
    coarse_lo,
    coarse_bin,
    fine,
    coarse,
):  # pragma: no cover
    """fine[iz, iy, ix] += own-path w; coarse[iz, iy, ix] += ghost w (prange over z)."""
    nfy, nfx = fine.shape[1], fine.shape[2]
    ncy, ncx = coarse.shape[1], coarse.shape[2]
    for iz in numba.prange(z_um.size):
        z = z_um[iz]
        for i in range(x.size):
            wi = w[i]
            if wi == 0.0:
                continue
            c = np.sqrt(n_obj * n_obj - sx[i] * sx[i] - sy[i] * sy[i])
            xo = x[i] + z * sx[i] / c - x0
            yo = y[i] + z * sy[i] / c - y0
            if own[i]:
                jx = int(np.floor((xo - fine_lo) / fine_bin))
                jy = int(np.floor((yo - fine_lo) / fine_bin))
                if 0 <= jx < nfx and 0 <= jy < nfy:
                    fine[iz, jy, jx] += wi
            else:
                jx = int(np.floor((xo - coarse_lo[1]) / coarse_bin))
                jy = int(np.floor((yo - coarse_lo[0]) / coarse_bin))
                if 0 <= jx < ncx and 0 <= jy < ncy:
                    coarse[iz, jy, jx] += wi


@dataclass(frozen=True)
class TracedMaps:
    """Responsivity maps of one pixel (etendue per bin, um^2 sr) at several Z.

    ``own`` (nz, n, n) on a fine grid of ``fine_bin_um`` starting at ``fine_lo_um`` in x and
    y from the pixel's axis; ``ghost`` (nz, ny, nx) on a coarse grid of
    ``coarse_bin_um`` starting at ``coarse_lo_um`` (y, x).
    """

    z_mm: np.ndarray
    own: np.ndarray
    fine_lo_um: float
    fine_bin_um: float
    ghost: np.ndarray
    coarse_lo_um: tuple[float, float]
    coarse_bin_um: float
    n_rays: int


def traced_maps(
    design: Design,
    *,
    z_mm,
    row: int = 0,
    n_rays: int = RAYS_MAP,
    seed: int = 0,
    fresnel: bool = False,
    fine_bin_um: float = 4.0,
    half_um: float | None = None,
    coarse_bin_um: float = 500.0,
    coarse_half_um: tuple[float, float] = (10_000.0, 45_000.0),
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
) -> TracedMaps:
    """Own-path maps (fine) and ghost maps (coarse) of pixel (row, 0) at every Z.

    ``sampling`` replaces ``n_rays``, ``seed`` and ``fresnel`` (its ray count, where None,
    is ``n_rays``). ``tracer``: a PixelTracer of this design whose pilot runs to reuse
    (other analyses of the same pixel share them); the sampling is still this call's.
    """
    (maps,) = traced_map_sets(
        design,
        z_sets=[z_mm],
        row=row,
        n_rays=n_rays,
        seed=seed,
        fresnel=fresnel,
        fine_bin_um=fine_bin_um,
        half_um=half_um,
        coarse_bin_um=coarse_bin_um,
        coarse_half_um=coarse_half_um,
        progress=progress,
        sampling=sampling,
        tracer=tracer,
    )
    return maps


def traced_map_sets(
    design: Design,
    *,
    z_sets,
    row: int = 0,
    n_rays: int = RAYS_MAP,
    seed: int = 0,
    fresnel: bool = False,
    fine_bin_um: float = 4.0,
    half_um: float | None = None,
    coarse_bin_um: float = 500.0,
    coarse_half_um: tuple[float, float] = (10_000.0, 45_000.0),
    progress: bool = False,
    sampling: Sampling | None = None,
    tracer: PixelTracer | None = None,
) -> list[TracedMaps]:
    """:func:`traced_maps` for several sets of Z from one trace of the pixel.

    Parameters
    ----------
    z_sets : sequence of sequences of object distances (mm)
    others : as :func:`traced_maps`; where ``half_um`` is None, each set's fine grid
        covers the own-path spot at that set's largest Z, on bins of ``fine_bin_um`` or,
        for a spot wider than ``MAP_MAX_BINS`` of them (a stack too thin to confine the
        light), on that many coarser bins (``TracedMaps.fine_bin_um`` says which)

    Returns
    -------
    list of TracedMaps
        One per set, bit for bit what ``traced_maps(z_mm=z_sets[i], ...)`` returns: the
        same rays are binned onto each set's grids.
    """
    if sampling is None:
        sampling = Sampling(n_rays, seed, fresnel)
    sampling = sampling.or_rays(n_rays)
    tr = tracer_for(design, sampling, tracer)
    src = tr.source((row, 0))
    ncy = int(np.ceil(2 * coarse_half_um[0] / coarse_bin_um))
    ncx = int(np.ceil(2 * coarse_half_um[1] / coarse_bin_um))
    coarse_lo = np.array([-ncy * coarse_bin_um / 2, -ncx * coarse_bin_um / 2])
    sets = []  # per set: Z (mm), fine grid start and bin, fine and coarse tallies
    for z_mm in z_sets:
        zs = np.asarray(z_mm, dtype=np.float64)
        half = _own_half_width(design, float(zs.max())) if half_um is None else half_um
        # a spot wider than MAP_MAX_BINS bins (a stack too thin to confine the light):
        # coarser bins, never a grid that does not fit in memory
        fine_bin = max(fine_bin_um, 2 * half / MAP_MAX_BINS)
        nf = int(np.ceil(2 * half / fine_bin))
        fine_lo = -nf * fine_bin / 2
        check_memory(
            8.0 * zs.size * max(nf * nf, ncy * ncx),
            f"the responsivity maps of {zs.size} object distances",
        )
        sets.append(
            (zs, fine_lo, fine_bin, np.zeros((zs.size, nf, nf)), np.zeros((zs.size, ncy, ncx)))
        )
    on_gpu = None  # the same maps on the device, where a GPU keeps the rays
    for pb in tr.trace((row, 0), progress=progress):
        b = pb.rays
        if b.device is not None:
            from . import cuda_tallies as gpu

            on_gpu = on_gpu or [(gpu.zeros(f.shape), gpu.zeros(c.shape)) for *_, f, c in sets]
            for (zs, fine_lo, fine_bin, _, _), (fine, coarse) in zip(sets, on_gpu, strict=True):
                gpu.maps(
                    pb, zs * 1000.0, tr.n_obj, fine_lo, fine_bin, coarse_lo,
                    coarse_bin_um, fine, coarse,
                )  # fmt: skip
            continue
        for zs, fine_lo, fine_bin, fine, coarse in sets:
            _maps(
                b.x,
                b.y,
                b.sx,
                b.sy,
                pb.w,
                pb.own,
                src.x,
                src.y,
                zs * 1000.0,
                tr.n_obj,
                fine_lo,
                fine_bin,
                coarse_lo,
                coarse_bin_um,
                fine,
                coarse,
            )
    for (*_, fine, coarse), dev in zip(sets, on_gpu or (), strict=False):  # none on a CPU
        fine += dev[0].copy_to_host()
        coarse += dev[1].copy_to_host()
    return [
        TracedMaps(
            zs,
            fine / sampling.n_rays,
            fine_lo,
            fine_bin,
            coarse / sampling.n_rays,
            (float(coarse_lo[0]), float(coarse_lo[1])),
            coarse_bin_um,
            sampling.n_rays,
        )
        for zs, fine_lo, fine_bin, fine, coarse in sets
    ]


def _own_half_width(design: Design, z_mm: float) -> float:
    """Half width (um) enclosing the own-path spot at z_mm (paraxial bound + 20 % margin).

    For circular holes the bound of the circumscribed squares is used."""
    sq = square_holes(design)
    lo, hi = paraxial_support(sq, z_mm, 0)
    lo_y, hi_y = paraxial_support(sq, z_mm, 1)
    return 1.2 * max(abs(lo), abs(hi), abs(lo_y), abs(hi_y)) + 10.0
