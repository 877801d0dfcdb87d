"""Exact ray tracing through a gradient-index rod-lens array (numba kernel and driver).

Rays are traced in reverse, from a pixel on the sensor (z = 0) up to the document
reference, as the stamp's are (by reciprocity the landing distribution of the rays that
get through is the pixel's responsivity on the object, and their weight sum its etendue).

Each ray: a point on the pixel's sensitive area and an invariant direction s = (sx, sy)
(the tangential optical direction, n sin(theta) (cos phi, sin phi), constant across
planar z-normal interfaces) drawn uniformly in the disk |s| <= s_max, i.e. Lambertian
(s_max = 1 is the whole hemisphere; a smaller s_max is importance sampling of the
directions a rod can accept, see :func:`direction_bound`). Path: air to the rods'
bottom faces (the image-side working distance); the ray enters the rod whose graded
core contains it (any other landing hits skin or resin and is absorbed); flat face,
exact 3-D Snell: s is kept, the axial optical direction beta = sqrt(n(r)^2 - |s|^2) is
invariant inside the rod; the ray equation d/dz (beta dr/dz) = grad(n^2) / 2 is solved

* in closed form for the pure parabolic profile (h4 = h6 = h8 = 0): each transverse
  coordinate is a harmonic oscillator in z with omega = n0 g / beta (skew rays
  included), and the largest radius along the rod is found exactly;
* by a fixed-step 4th-order Runge-Kutta integrator for h4, h6, h8 (radius checked at
  every step; tested against the closed form);

a ray whose radius exceeds r0 anywhere in the rod is absorbed. At the top face the ray
leaves into air (total internal reflection if |s| >= 1), crosses the air gap and the
cover glass, and is recorded on the document reference plane.

Fresnel (optional): unpolarised transmittance (Ts + Tp) / 2 of each of the four faces,
each face taken separately (skew rays turn their plane of incidence inside a rod, so
the stamp's exact s/p bookkeeping over parallel planes does not apply).

Random numbers: the stamp's counter-based generator (:func:`.kernel.uniform_pair`); ray
i draws from (seed, i) only, and its pixel is i mod n_pixels, so results are identical
for any chunk size or thread count.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from ..design.rodlens import RodLensDesign
from .kernel import fresnel_sp, seed_key, uniform_pair
from .launch import progress_bar

THROUGH, MISSED_CORE, LEFT_CORE, TIR_EXIT = 0, 1, 2, 3
STATUS_NAMES = ("through", "missed_core", "left_core", "tir_exit")
#: Runge-Kutta step: at most this phase (radians of the ray's oscillation) per step; the
#: path between steps is checked against the core radius by cubic Hermite interpolation.
RK_PHASE_STEP = 0.06
#: Importance bound on |s|: this margin times the largest guided |s| of the profile.
DIRECTION_MARGIN = 1.25
CHUNK = 1 << 20
_STREAM = 7  # generator stream of the rod tracer (the stamp's uses 0..)
_JIT = dict(cache=True, nogil=True, error_model="numpy")

# geometry vector layout (float64)
(
    _L_IMG,
    _Z0,
    _PITCH,
    _R0,
    _N0,
    _G,
    _H4,
    _H6,
    _H8,
    _ROWS,
    _RX0,
    _RY0,
    _RX1,
    _RY1,
    _NSTEP,
    _GAP,
    _T_GLASS,
    _N_GLASS,
) = range(18)
_N_GEO = 18


@nb.njit(inline="always", **_JIT)
def _n2(r2, geo):
    """n(r)^2 for r^2 = ``r2``."""
    gg = geo[_G] * geo[_G] * r2
    return geo[_N0] ** 2 * (1.0 - gg + gg * gg * (geo[_H4] + gg * (geo[_H6] + gg * geo[_H8])))


@nb.njit(inline="always", **_JIT)
def _force(x, y, beta, geo):
    """d(p)/dz = grad(n^2) / (2 beta) at (x, y)."""
    g2 = geo[_G] * geo[_G]
    gg = g2 * (x * x + y * y)
    f = -1.0 + gg * (2.0 * geo[_H4] + gg * (3.0 * geo[_H6] + gg * 4.0 * geo[_H8]))
    k = geo[_N0] ** 2 * g2 * f / beta
    return k * x, k * y


@nb.njit(inline="always", **_JIT)
def _parabolic(x, y, sx, sy, beta, geo):
    """Closed form over the rod; returns (inside, x, y, px, py) at the top face."""
    n0g = geo[_N0] * geo[_G]
    om = n0g / beta
    t_end = om * geo[_Z0]
    ax, bx = x, sx / n0g
    ay, by = y, sy / n0g
    a = 0.5 * (ax * ax + bx * bx + ay * ay + by * by)
    b = 0.5 * (ax * ax + ay * ay - bx * bx - by * by)
    c = ax * bx + ay * by
    amp = math.sqrt(b * b + c * c)
    r0sq = geo[_R0] * geo[_R0]
    ct, st = math.cos(t_end), math.sin(t_end)
    xe = ax * ct + bx * st
    ye = ay * ct + by * st
    if a + amp > r0sq:  # the ellipse leaves the core somewhere: is it within [0, t_end]?
        phi = math.atan2(c, b)  # r^2 is largest at 2t = phi (mod 2 pi)
        if phi < 0.0:
            phi += 2.0 * math.pi
        if 2.0 * t_end >= phi or xe * xe + ye * ye > r0sq:
            return False, xe, ye, 0.0, 0.0
    px = -ax * n0g * st + sx * ct
    py = -ay * n0g * st + sy * ct
    return True, xe, ye, px, py


@nb.njit(inline="always", **_JIT)
def _leaves(x0, y0, dx0, dy0, x1, y1, dx1, dy1, h, r0sq):
    """Does the cubic Hermite path between two RK steps leave the core (r^2 > r0sq)?

    Checked at the quarter points; with the step below the path's error is far below
    the core's radius resolution.
    """
    for t in (0.25, 0.5, 0.75):
        h00 = (1 + 2 * t) * (1 - t) ** 2
        h10 = t * (1 - t) ** 2
        h01 = t * t * (3 - 2 * t)
        h11 = t * t * (t - 1)
        x = h00 * x0 + h10 * h * dx0 + h01 * x1 + h11 * h * dx1
        y = h00 * y0 + h10 * h * dy0 + h01 * y1 + h11 * h * dy1
        if x * x + y * y > r0sq:
            return True
    return False


@nb.njit(inline="always", **_JIT)
def _integrate(x, y, sx, sy, beta, geo):
    """RK4 over the rod for the full profile; returns (inside, x, y, px, py)."""
    n = int(geo[_NSTEP])
    h = geo[_Z0] / n
    ib = 1.0 / beta
    r0sq = geo[_R0] * geo[_R0]
    px, py = sx, sy
    for _ in range(n):
        k1x, k1y = px * ib, py * ib
        f1x, f1y = _force(x, y, beta, geo)
        x2, y2 = x + 0.5 * h * k1x, y + 0.5 * h * k1y
        p2x, p2y = px + 0.5 * h * f1x, py + 0.5 * h * f1y
        f2x, f2y = _force(x2, y2, beta, geo)
        x3, y3 = x + 0.5 * h * p2x * ib, y + 0.5 * h * p2y * ib
        p3x, p3y = px + 0.5 * h * f2x, py + 0.5 * h * f2y
        f3x, f3y = _force(x3, y3, beta, geo)
        x4, y4 = x + h * p3x * ib, y + h * p3y * ib
        p4x, p4y = px + h * f3x, py + h * f3y
        f4x, f4y = _force(x4, y4, beta, geo)
        xn = x + h / 6.0 * (k1x + 2.0 * p2x * ib + 2.0 * p3x * ib + p4x * ib)
        yn = y + h / 6.0 * (k1y + 2.0 * p2y * ib + 2.0 * p3y * ib + p4y * ib)
        pxn = px + h / 6.0 * (f1x + 2.0 * f2x + 2.0 * f3x + f4x)
        pyn = py + h / 6.0 * (f1y + 2.0 * f2y + 2.0 * f3y + f4y)
        if xn * xn + yn * yn > r0sq or _leaves(x, y, k1x, k1y, xn, yn, pxn * ib, pyn * ib, h, r0sq):
            return False, xn, yn, pxn, pyn
        x, y, px, py = xn, yn, pxn, pyn
    return True, x, y, px, py


@nb.njit(inline="always", **_JIT)
def _face(n1, n2, s2):
    """Unpolarised Fresnel transmittance of a z-normal face for |s|^2 = s2."""
    c1 = math.sqrt(max(n1 * n1 - s2, 0.0)) / n1
    c2 = math.sqrt(max(n2 * n2 - s2, 0.0)) / n2
    ts, tp = fresnel_sp(n1, n2, c1, c2)
    return 0.5 * (ts + tp)


@nb.njit(inline="always", **_JIT)
def _rod_of(x, y, geo):
    """(axis x, axis y) of the rod whose core holds (x, y); (nan, nan) if none."""
    pitch = geo[_PITCH]
    r0sq = geo[_R0] * geo[_R0]
    for r in range(int(geo[_ROWS])):
        rx = geo[_RX0 + 2 * r]
        ry = geo[_RY0 + 2 * r]
        k = math.floor((x - rx) / pitch + 0.5)
        ax = rx + k * pitch
        dx, dy = x - ax, y - ry
        if dx * dx + dy * dy <= r0sq:
            return ax, ry
    return math.nan, math.nan


@nb.njit(inline="always", **_JIT)
def _trace_rod(x, y, sx, sy, geo, closed, fresnel):
    """One ray from the sensor plane to the document reference.

    Returns status, x, y, sx, sy, weight at the reference plane.
    """
    s2 = sx * sx + sy * sy
    c = math.sqrt(1.0 - s2)
    x += geo[_L_IMG] * sx / c
    y += geo[_L_IMG] * sy / c
    ax, ay = _rod_of(x, y, geo)
    if math.isnan(ax):
        return MISSED_CORE, x, y, sx, sy, 0.0
    lx, ly = x - ax, y - ay
    n_in2 = _n2(lx * lx + ly * ly, geo)
    beta = math.sqrt(n_in2 - s2)
    w = _face(1.0, math.sqrt(n_in2), s2) if fresnel else 1.0
    if closed:
        inside, lx, ly, px, py = _parabolic(lx, ly, sx, sy, beta, geo)
    else:
        inside, lx, ly, px, py = _integrate(lx, ly, sx, sy, beta, geo)
    x, y = ax + lx, ay + ly
    if not inside:
        return LEFT_CORE, x, y, px, py, 0.0
    p2 = px * px + py * py
    if p2 >= 1.0:
        return TIR_EXIT, x, y, px, py, 0.0
    if fresnel:
        w *= _face(math.sqrt(_n2(lx * lx + ly * ly, geo)), 1.0, p2)
    c = math.sqrt(1.0 - p2)
    x += geo[_GAP] * px / c
    y += geo[_GAP] * py / c
    t = geo[_T_GLASS]
    if t > 0.0:
        ng = geo[_N_GLASS]
        cg = math.sqrt(ng * ng - p2)
        x += t * px / cg
        y += t * py / cg
        if fresnel:
            w *= _face(1.0, ng, p2) * _face(ng, 1.0, p2)
    return THROUGH, x, y, px, py, w


@nb.njit(parallel=True, **_JIT)
def run_rods(
    key,
    start,
    n,
    pix_x,
    half_w,
    half_h,
    s_max,
    geo,
    closed,
    fresnel,
    o_st,
    o_x,
    o_y,
    o_sx,
    o_sy,
    o_w,
):
    """Trace rays start .. start + n - 1; ray i comes from pixel (start + i) mod n_pixels."""
    npix = pix_x.size
    for i in nb.prange(n):
        gid = start + i
        u1, u2 = uniform_pair(key, gid, 0)
        u3, u4 = uniform_pair(key, gid, 1)
        x = pix_x[gid % npix] + (2.0 * u1 - 1.0) * half_w
        y = (2.0 * u2 - 1.0) * half_h
        rho = s_max * math.sqrt(u3)
        ph = 2.0 * math.pi * u4
        st, xo, yo, sxo, syo, wo = _trace_rod(
            x, y, rho * math.cos(ph), rho * math.sin(ph), geo, closed, fresnel
        )
        o_st[i] = st
        o_x[i] = xo
        o_y[i] = yo
        o_sx[i] = sxo
        o_sy[i] = syo
        o_w[i] = wo


@nb.njit(**_JIT)
def trace_rod_rays(x, y, sx, sy, geo, closed, fresnel, o_st, o_x, o_y, o_sx, o_sy, o_w):
    """Trace given rays (positions on the sensor plane, invariant directions)."""
    for i in range(x.size):
        st, xo, yo, sxo, syo, wo = _trace_rod(x[i], y[i], sx[i], sy[i], geo, closed, fresnel)
        o_st[i] = st
        o_x[i] = xo
        o_y[i] = yo
        o_sx[i] = sxo
        o_sy[i] = syo
        o_w[i] = wo


# -- driver -----------------------------------------------------------------------------
def geometry(design: RodLensDesign, *, integrate: bool | None = None) -> tuple[np.ndarray, bool]:
    """The kernel's geometry vector and whether the closed form applies.

    ``integrate``: force the Runge-Kutta integrator (True) or the closed form (False,
    only for a pure parabolic profile); default: closed form exactly when h4 = h6 = h8 = 0.
    """
    a = design.array
    parabolic = a.h4 == 0 and a.h6 == 0 and a.h8 == 0
    closed = parabolic if integrate is None else not integrate
    if closed and not parabolic:
        raise ValueError("the closed form holds only for h4 = h6 = h8 = 0")
    geo = np.zeros(_N_GEO)
    axes = a.axes()
    geo[_L_IMG] = a.working_um
    geo[_Z0] = a.length_um
    geo[_PITCH] = 2 * a.rod_radius_um
    geo[_R0] = a.core_radius_um
    geo[_N0] = a.n0
    geo[_G] = a.g_per_um
    geo[[_H4, _H6, _H8]] = a.h4, a.h6, a.h8
    geo[_ROWS] = len(axes)
    for r, (rx, ry) in enumerate(axes):
        geo[_RX0 + 2 * r] = rx
        geo[_RY0 + 2 * r] = ry
    # the fastest oscillation (smallest beta, about n(r0)) sets the step
    beta_min = math.sqrt(
        max(float(a.index_squared(a.core_radius_um)) - direction_bound(design) ** 2, 1e-6)
    )
    phase = a.n0 * a.g_per_um / beta_min * a.length_um
    geo[_NSTEP] = max(8, math.ceil(phase / RK_PHASE_STEP))
    geo[_GAP] = design.air_gap_um
    if design.cover_glass is not None:
        geo[_T_GLASS] = design.cover_glass.thickness_um
        geo[_N_GLASS] = design.glass_index
    return geo, closed


def direction_bound(design: RodLensDesign) -> float:
    """s_max: no ray with a larger |s| can cross the rod inside its core.

    For the parabolic profile a guided ray's transverse optical direction never exceeds
    NA = sqrt(n0^2 - n(r0)^2) (its orbit is an ellipse within r0, and |p| = n0 g times
    the orbit's semi-axis). For h4, h6, h8 the same quantity from the profile's extremes,
    times DIRECTION_MARGIN; tests check that accepted rays stay well inside the bound.
    """
    a = design.array
    n2 = a.index_squared(np.linspace(0.0, a.core_radius_um, 257))
    return min(1.0, DIRECTION_MARGIN * math.sqrt(float(n2.max() - n2.min())))


@dataclass(frozen=True)
class RodRays:
    """Rays that reached the document reference plane, and the launch bookkeeping.

    Attributes
    ----------
    ids : (n,) int64, global ray index (its pixel is ids mod n_pix)
    x, y : (n,) float64, landing on the document reference plane (um)
    sx, sy : (n,) float64, invariant direction in air above it
    w : (n,) float64, Fresnel weight (1 without Fresnel)
    pixel_x_um : (n_pix,) centres of the launching pixels
    n_per_pixel : (n_pix,) int64, rays launched from each pixel
    ray_etendue : float, etendue (um^2 sr) one launched ray stands for
    ledger : dict, launched rays by fate
    """

    ids: np.ndarray
    x: np.ndarray
    y: np.ndarray
    sx: np.ndarray
    sy: np.ndarray
    w: np.ndarray
    pixel_x_um: np.ndarray
    n_per_pixel: np.ndarray
    ray_etendue: float
    ledger: dict
    seed: int
    fresnel: bool

    @property
    def pixel(self) -> np.ndarray:
        """(n,) index into ``pixel_x_um`` of each ray's pixel."""
        return self.ids % self.pixel_x_um.size

    def ray_weights(self) -> np.ndarray:
        """(n,) etendue (um^2 sr) each ray carries toward its pixel's total (its Fresnel
        weight times the etendue one of that pixel's launched rays stands for)."""
        return self.w * self.ray_etendue * (self.n_per_pixel.sum() / self.n_per_pixel)[self.pixel]

    def etendue_per_pixel(self) -> np.ndarray:
        """Etendue (um^2 sr) each pixel collects from a uniform Lambertian object."""
        tot = np.bincount(self.pixel, weights=self.w, minlength=self.pixel_x_um.size)
        return tot * self.ray_etendue * self.n_per_pixel.sum() / self.n_per_pixel

    def landing_x(self, height_um, glass_index: float = 1.0) -> np.ndarray:
        """x (um) where each ray meets the plane ``height_um`` above the reference.

        Negative heights lie inside the cover glass (index ``glass_index``).
        """
        n = 1.0 if height_um >= 0 else glass_index
        s2 = self.sx**2 + self.sy**2
        return self.x + height_um * self.sx / np.sqrt(n * n - s2)

    def landing_y(self, height_um, glass_index: float = 1.0) -> np.ndarray:
        n = 1.0 if height_um >= 0 else glass_index
        s2 = self.sx**2 + self.sy**2
        return self.y + height_um * self.sy / np.sqrt(n * n - s2)


def trace_rods(
    design: RodLensDesign,
    pixel_x_um,
    *,
    n_rays: int,
    seed: int = 0,
    fresnel: bool = False,
    point: bool = False,
    s_max: float | None = None,
    integrate: bool | None = None,
    chunk: int = CHUNK,
    progress: bool = False,
) -> RodRays:
    """Trace ``n_rays`` rays in reverse from the pixels centred at ``pixel_x_um`` (y = 0).

    ``point``: a point source at each pixel centre (the PSF), else the sensitive area.
    ``s_max``: bound on the launch directions (default :func:`direction_bound`).
    Memory is bounded by ``chunk``; a progress bar is shown when ``progress``
    (:func:`~.launch.progress_bar`).
    """
    pix = np.ascontiguousarray(pixel_x_um, dtype=np.float64).ravel()
    if pix.size == 0 or n_rays < pix.size:
        raise ValueError("trace_rods: need at least one ray per pixel")
    geo, closed = geometry(design, integrate=integrate)
    smax = direction_bound(design) if s_max is None else float(s_max)
    sen = design.sensor
    hw, hh = (0.0, 0.0) if point else (sen.width_um / 2, sen.height_um / 2)
    area = 1.0 if point else sen.width_um * sen.height_um
    key = seed_key(seed, _STREAM)
    keep: list[tuple] = []
    counts = np.zeros(len(STATUS_NAMES), dtype=np.int64)
    bar = progress_bar(total=n_rays, unit="ray", unit_scale=True, leave=False, progress=progress)
    for start in range(0, n_rays, chunk):
        n = min(chunk, n_rays - start)
        st = np.empty(n, np.int8)
        out = [np.empty(n) for _ in range(5)]
        run_rods(key, start, n, pix, hw, hh, smax, geo, closed, fresnel, st, *out)
        counts += np.bincount(st, minlength=len(STATUS_NAMES))
        ok = np.flatnonzero(st == THROUGH)
        keep.append((start + ok, *(o[ok] for o in out)))
        bar.update(n)
    bar.close()
    cols = [np.concatenate(c) for c in zip(*keep, strict=True)]
    q, r = divmod(n_rays, pix.size)
    per_pixel = q + (np.arange(pix.size) < r).astype(np.int64)
    return RodRays(
        *cols,
        pixel_x_um=pix,
        n_per_pixel=per_pixel,
        ray_etendue=area * math.pi * smax**2 / n_rays,
        ledger=dict(zip(STATUS_NAMES, (int(c) for c in counts), strict=True)),
        seed=seed,
        fresnel=fresnel,
    )
