"""The forward model of a fit (issue 24): a design's parameters -> its images of charts.

Physical parameters (names as the search's ``--pin`` names them: layers and slabs
numbered from the object side, from 1):

* ``layerN.x``, ``layerN.y``: mask N's misregistration (um) against the sensor's pixels;
* ``slabN``: slab N's thickness (um);
* ``holeN`` (square holes) or ``holeN.x``, ``holeN.y`` (rectangles): hole size (um);
* ``pixel.x``, ``pixel.y``: the pixel's sensitive width and height (um);
* ``ref``: where Z = 0 really is, um above the reference plane as drawn (the light guide
  thicker than drawn: > 0); the fitted design's reference gap is the drawn one plus it.

A chart varying along x at height Z gives the merged line's column at x the value
b + (w - b) F(x), F the fraction of the pixel's own-path responsivity that falls on white
(the chart's white reflectance w and black b as the scanner's shading correction scales
them, ghost light's near-uniform background included); a straight edge likewise, with the
responsivity's spread along the edge's normal. The responsivity is the paraxial closed
form of the own path (:mod:`opticalstamp.analysis.paraxial`: separable, exact for
rectangular holes; what ``scan --kernel auto`` uses for them), its cumulative tabulated
at 0.25 um; along y it is smeared by the document's motion over the exposure (the box of
``exposure_duty`` x the line pitch, as the scan simulation does).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ..analysis.paraxial import OwnPath
from ..design import Design
from ..design.model import MIN_LENGTH_UM
from ..design.variants import replace
from ..raytrace.stack import output_pitch

#: Step (um) of the tabulated cumulative responsivity.
TABLE_UM = 0.25
#: Sub-positions of the motion smear (the scan simulation's midpoint rule).
SMEAR_SUBS = 9
#: Step (um) of the nodes of the cross spread of a slanted edge (times its slope).
CROSS_UM = 6.0


@dataclass(frozen=True)
class Param:
    """One physical parameter: its name, the design path it writes, the nominal value,
    its bounds and a typical scale (um) of assembly errors (multi-start spread, degeneracy
    scaling)."""

    name: str
    path: str
    nominal: float
    lo: float
    hi: float
    scale: float
    offset: bool = False  # the design's value is base + x (``ref``), else x
    base: float = 0.0


def design_params(design: Design) -> list[Param]:
    """Every physical parameter of a stamp with rectangular holes (see the module doc)."""
    s = design.sensor
    out = []
    masks = [i for i, sl in enumerate(design.slabs) if sl.mask_top is not None][::-1]
    for n, i in enumerate(masks, 1):
        m = design.slabs[i].mask_top
        base = f"slabs.{i}.mask_top"
        for ax in ("x", "y"):
            v = getattr(m, f"offset_{ax}_um")
            out.append(Param(f"layer{n}.{ax}", f"{base}.offset_{ax}_um", v, v - 40, v + 40, 3.0))
    nsl = len(design.slabs)
    for n in range(1, nsl + 1):
        t = design.slabs[nsl - n].thickness_um
        path = f"slabs.{nsl - n}.thickness_um"
        out.append(Param(f"slab{n}", path, t, MIN_LENGTH_UM, 3 * t, max(0.03 * t, 5.0)))
    for n, i in enumerate(masks, 1):
        m = design.slabs[i].mask_top
        base = f"slabs.{i}.mask_top"
        hi = s.row_pitch_um * 0.999
        if m.shape == "square":
            out.append(Param(f"hole{n}", f"{base}.size_um", m.size_um, 1.0, hi, 3.0))
        else:
            out.append(Param(f"hole{n}.x", f"{base}.width_um", m.width_um, 1.0, hi, 3.0))
            out.append(Param(f"hole{n}.y", f"{base}.height_um", m.height_um, 1.0, hi, 3.0))
    for ax, key in (("x", "sensitive_width_um"), ("y", "sensitive_height_um")):
        v = getattr(s, key)
        out.append(Param(f"pixel.{ax}", f"sensor.{key}", v, 1.0, s.pixel_pitch_um, 3.0))
    g = design.reference_gap.thickness_um
    out.append(
        Param("ref", "reference_gap.thickness_um", 0.0, -g, 5000.0, 200.0, offset=True, base=g)
    )
    return out


def with_params(design: Design, params: list[Param], values) -> Design:
    """The design with the parameters set (validated: DesignError names a bad field)."""
    changes = {}
    for p, v in zip(params, values, strict=True):
        changes[p.path] = float(p.base + v if p.offset else v)
    if "reference_gap.thickness_um" in changes:
        changes["reference_gap.thickness_um"] = max(changes["reference_gap.thickness_um"], 0.0)
    return replace(design, changes)


@dataclass(frozen=True)
class Spread:
    """The own path's responsivity at one Z, normalised, in the forms the charts need.

    ``u``: grid (um from the pixel's axis) of ``cx`` (cumulative along x, 0 to 1) and
    ``cy`` (cumulative along y of the motion-smeared spread of Y' = Y - sub, 0 to 1: the
    document point a pixel sees is y - Y'); ``half_um``: half width of the support.
    """

    u: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    half_um: float

    def widened(self, n: int) -> Spread:
        """This spread's table padded (its cumulatives 0 before, 1 after) out to k
        ``TABLE_UM``, |k| <= n (itself where it reaches that far); ``half_um`` kept."""
        pad = n - (self.u.size - 1) // 2
        if pad <= 0:
            return self
        u = np.arange(-n, n + 1) * TABLE_UM
        cx, cy = (np.pad(c, pad, constant_values=(0.0, 1.0)) for c in (self.cx, self.cy))
        return Spread(u, cx, cy, self.half_um)

    def nodes(self, cum: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions, weights) of a distribution from its cumulative on ``u``, on
        CROSS_UM bins of a fixed grid (each bin a node at its centre; the bins so fixed
        and never merged by mass, the model is smooth in the parameters: a fit's
        derivatives by differences need that)."""
        k0 = np.floor(self.u[0] / CROSS_UM)  # a fixed grid, as the table's
        edges = (k0 + np.arange(int(np.ceil((self.u[-1] - self.u[0]) / CROSS_UM)) + 2)) * CROSS_UM
        c = np.interp(edges, self.u, cum)
        w = np.diff(c)
        mid = (edges[1:] + edges[:-1]) / 2
        keep = w > 1e-9
        mid, w = mid[keep], w[keep]
        return mid, w / w.sum()


def spread(
    design: Design, z_mm: float, smear_um: float, reach_um: float = 0.0, own: OwnPath | None = None
) -> Spread:
    """The own path's spread of ``design`` at ``z_mm`` above its reference plane, tabulated
    on the fixed grid k ``TABLE_UM`` out to its support or ``reach_um``, whichever is
    wider. ``own``: ``design``'s :class:`~opticalstamp.analysis.paraxial.OwnPath`, read
    once for several heights (the same values)."""
    own = OwnPath(design) if own is None else own
    sx, sy = own.at(z_mm, 0), own.at(z_mm, 1)
    half = 0.0
    for lo, hi in (sx.support, sy.support):
        half = max(half, abs(lo), abs(hi))
    half = half + smear_um / 2 + 2 * TABLE_UM
    m = int(np.ceil(half / TABLE_UM))  # the support's table ...
    n = max(m, int(np.ceil(reach_um / TABLE_UM)))  # ... and the one asked for
    u = np.arange(-m, m + 1) * TABLE_UM  # on a fixed grid: no jump as the support moves
    cx = sx.cumulative(u)
    subs = ((np.arange(SMEAR_SUBS) + 0.5) / SMEAR_SUBS - 0.5) * smear_um
    # P(Y - sub <= v) = mean over sub of C_y(v + sub); C_y is exact on the table's grid
    # and linear between its points (0.25 um apart)
    pad = int(np.ceil(smear_um / 2 / TABLE_UM)) + 1
    uy = np.arange(-m - pad, m + pad + 1) * TABLE_UM
    cy_grid = sy.cumulative(uy)
    cy = np.mean([np.interp(u + s, uy, cy_grid) for s in subs], axis=0)
    gx, gy = cx[-1], cy[-1]
    if not (gx > 0 and gy > 0):
        raise ValueError(f"no own-path light reaches the pixel at Z = {z_mm:g} mm")
    # beyond the support the cumulatives are 0 and 1: padded, not computed
    return Spread(u, cx / gx, cy / gy, max(half, reach_um)).widened(n)


def chart_blurred(sp: Spread, pixel_um: float) -> Spread:
    """``sp`` as seen on a chart drawn in square pixels of ``pixel_um`` (0: an ideal
    chart, ``sp`` itself). Each pixel of the project's charts holds the mean of the ideal
    pattern over it (``chart bars``/``chart edge``: supersampled), held over the pixel;
    over where the pixel grid falls under the pattern's edges (a block's bars, a slanted
    edge's length), that is the ideal pattern convolved with the pixel's box twice: a
    triangle of half width ``pixel_um`` along x and y (variance pixel^2 / 6), which
    convolves each cumulative of the spread (the charts' blur and the optics' commute).
    The triangle is summed on the table's grid (``TABLE_UM``); the table grows by its
    half width each side."""
    if pixel_um <= 0:
        return sp
    k = int(np.ceil(pixel_um / TABLE_UM))
    w = np.clip(1.0 - np.abs(np.arange(-k, k + 1) * TABLE_UM) / pixel_um, 0.0, None)
    w /= w.sum()
    n = (sp.u.size - 1) // 2 + k
    wide = sp.widened(n + k)  # 0 before, 1 after: the convolution's ends
    cx, cy = (np.convolve(c, w, mode="valid") for c in (wide.cx, wide.cy))
    return Spread(np.arange(-n, n + 1) * TABLE_UM, cx, cy, sp.half_um + pixel_um)


def spreads(design: Design, zs, smear_um: float, phys=None) -> dict[float, Spread]:
    """The fast model (:func:`spread`, the paraxial own path) at each height: {Z: spread}
    (``phys``, the physical values that made ``design``, is not needed here)."""
    own = OwnPath(design)
    return {float(z): spread(design, float(z), smear_um, own=own) for z in zs}


def smear_of(design: Design) -> float:
    """The motion smear (um) along y over one exposure: duty x the merged line pitch."""
    return design.electronics.exposure_duty * output_pitch(design)


# -- charts -------------------------------------------------------------------------------
@numba.njit(cache=True)
def _cum(u: np.ndarray, c: np.ndarray, x: float) -> float:
    """``np.interp(x, u, c, left=0, right=1)`` on a uniform grid ``u`` (the fit's tables):
    the bracket found by division instead of a binary search, the same formula."""
    n = u.size
    if x < u[0]:
        return 0.0
    if x > u[n - 1]:
        return 1.0
    j = min(int((x - u[0]) / (u[1] - u[0])), n - 2)
    while j > 0 and x < u[j]:
        j -= 1
    while j < n - 2 and x >= u[j + 1]:
        j += 1
    if x == u[j + 1]:
        return c[j + 1]
    return (c[j + 1] - c[j]) / (u[j + 1] - u[j]) * (x - u[j]) + c[j]


@numba.njit(cache=True)
def _bar_sum(u, c, x, p, phase, n_k):
    out = np.empty(x.size)
    for j in range(x.size):
        k0 = np.floor((x[j] + u[0] - phase) / p) - 1
        s = 0.0
        for m in range(n_k):
            a = phase + (k0 + m) * p + p / 2 - x[j]
            s += _cum(u, c, a + p / 2) - _cum(u, c, a)
        out[j] = s
    return out


@numba.njit(cache=True)
def _edge_sum(u, c, d, cross, w):
    """sum_i w_i C(d_j - cross_i) for each d_j, C the cumulative ``c`` on the uniform grid
    ``u`` (0 before, 1 after: c[0] and c[-1]), linear between its nodes: the fit's
    hottest loop (each edge's pixels times the cross distribution's nodes). Branch-free:
    the argument clamped onto the table, its interval by one product, each interval's
    slope computed once (the last one 0); the sum in the nodes' order, so the same bits on
    every machine (no reassociation: 1.8x faster with it, but the vector width would
    choose the order). 1.6x faster than :func:`_cum`'s search; equal to it to 2e-15."""
    n = u.size
    u0, un = u[0], u[n - 1]
    inv = 1.0 / (u[1] - u[0])
    slope = np.zeros(n)
    for k in range(n - 1):
        slope[k] = (c[k + 1] - c[k]) / (u[k + 1] - u[k])
    out = np.empty(d.size)
    for j in range(d.size):
        s = 0.0
        dj = d[j]
        for i in range(w.size):
            x = min(max(dj - cross[i], u0), un)
            k = int((x - u0) * inv)
            s += w[i] * (c[k] + slope[k] * (x - u[k]))
        out[j] = s
    return out


def bar_fraction(sp: Spread, x_um: np.ndarray, period_um: float, phase_um: float):
    """White fraction seen by the columns at ``x_um`` of bars of ``period_um``, black on
    [phase + k P, phase + k P + P/2), white on the rest (a periodic chart)."""
    x = np.ascontiguousarray(x_um, dtype=np.float64)
    p = float(period_um)
    n_k = int(np.ceil((sp.u[-1] - sp.u[0]) / p)) + 3
    return _bar_sum(sp.u, sp.cx, x, p, float(phase_um), n_k)


def edge_fraction(sp: Spread, edge, pos_um: float, slope: float) -> np.ndarray:
    """White fraction seen by the pixels of an :class:`~.fitdata.EdgeRegion` whose line is
    across = pos + slope (along - ref).

    Axis 0 (x): a pixel at (x, y) sees the document at (x + X, y - Y'); white lies before
    the edge (x' < x_e(y')) when the dark side is after it: P(X + slope Y' < d),
    d = x_e(y) - x. Axis 1 (y): white where y' < y_e(x'): P(-Y' - slope X < d),
    d = y_e(x) - y.
    """
    if edge.axis == 0:
        d = pos_um + slope * (edge.y_um - edge.ref_um) - edge.x_um
        vals, w = sp.nodes(sp.cy)  # Y' nodes
        main_u, main_c = sp.u, sp.cx
        cross = slope * vals  # P(X < d - slope Y')
    else:
        d = pos_um + slope * (edge.x_um - edge.ref_um) - edge.y_um
        vals, w = sp.nodes(sp.cx)  # X nodes
        # -Y' has the cumulative 1 - C_y'(-m)
        main_u, main_c = -sp.u[::-1], 1.0 - sp.cy[::-1]
        cross = -slope * vals
    d = np.ascontiguousarray(np.broadcast_to(d, np.shape(edge.x_um)), dtype=np.float64)
    f = _edge_sum(
        np.ascontiguousarray(main_u, dtype=np.float64),
        np.ascontiguousarray(main_c, dtype=np.float64),
        d,
        np.ascontiguousarray(cross, dtype=np.float64),
        np.ascontiguousarray(w, dtype=np.float64),
    )
    return f if edge.dark_after else 1.0 - f
