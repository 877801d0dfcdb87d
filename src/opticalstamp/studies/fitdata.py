"""What a fit reads from a scanner's images of the project's charts (issue 24).

An image is a shading-corrected scan (values in [0, 1], [line = y, column = x], on the
merged line's pitch) of one of the project's charts at a known height:

* bar blocks (``chart bars``, found as :func:`~opticalstamp.imaging.measure.measure_rmtf`
  finds them): each block's *waveform* along x, the mean over the lines of the block of
  every column inside it, away from its ends (where the white margin enters);
* a slanted dark square (``chart edge``, its left and top edges found as
  :func:`~opticalstamp.imaging.measure.square_edge_rois` finds them): every pixel of the
  regions around the two edges, the edge spread along x and along y.

Each datum carries its variance from the image's own noise: the variance of one line's
pixel, a + b v (shot noise grows with the signal v; the sensor's gain and read noise,
measured here from the scatter along the bars or over the flat parts of the edge
regions), and the shading correction's error, common to a column: its white and dark
references are means of ``calibration_lines`` lines, so a column's value v carries
(v^2 s_white^2 + (1 - v)^2 s_dark^2) / calibration_lines that no averaging over lines
removes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..imaging.measure import measure_rmtf, square_edge_rois
from ..units import pitch_of_dpi

#: Lines of the white and dark references of a scanner's shading correction (the scan
#: simulation's default, :class:`~opticalstamp.imaging.scan.ScanSettings`).
CALIBRATION_LINES = 32


@dataclass(frozen=True)
class BarBlock:
    """One bar block's waveform.

    Attributes
    ----------
    period_um : the period measured (start of the fit's period)
    phase_um : x (um) where a black bar starts, from the fundamental (start of the fit)
    x_um : (n,) centres of the columns fitted (um from the image's left edge)
    value : (n,) mean over the block's lines of each column
    var : (n,) variance of each mean (one line's noise / lines + shading reference's)
    """

    period_um: float
    phase_um: float
    x_um: np.ndarray
    value: np.ndarray
    var: np.ndarray


@dataclass(frozen=True)
class EdgeRegion:
    """The pixels around one straight edge of the slanted dark square.

    Attributes
    ----------
    axis : 0, an edge across x (near-vertical: its spread is along x); 1, across y
    x_um, y_um : (n,) pixel centres (um from the image's top-left corner)
    value : (n,) pixel values
    var : (n,) their variances
    pos_um, slope : the edge's line, start of the fit: x = pos + slope (y - ref) for
        axis 0, y = pos + slope (x - ref) for axis 1
    ref_um : the reference coordinate of that line (the region's centre)
    dark_after : True where the dark side is the side of larger x (axis 0) or y (axis 1)
    """

    axis: int
    x_um: np.ndarray
    y_um: np.ndarray
    value: np.ndarray
    var: np.ndarray
    pos_um: float
    slope: float
    ref_um: float
    dark_after: bool


@dataclass(frozen=True)
class Observation:
    """One image: its chart's features at a height.

    ``z_mm``: the height the experimenter set, from the scanner's top surface (the
    design's reference plane as drawn). ``kind``: "bars" or "edge"; ``blocks`` or
    ``edges`` hold the data. ``noise``: (a, b) of one pixel's variance a + b v.
    ``chart_um``: the pixel (um) the chart was drawn in (0: an ideal chart;
    :func:`~.fitmodel.chart_blurred`).
    """

    name: str
    kind: str
    z_mm: float
    dpi: float
    blocks: tuple[BarBlock, ...] = ()
    edges: tuple[EdgeRegion, ...] = ()
    noise: tuple[float, float] = (0.0, 0.0)
    chart_um: float = 0.0

    @property
    def items(self) -> tuple:
        """Its chart's features: the bar blocks or the edge regions, by ``kind``."""
        return self.blocks if self.kind == "bars" else self.edges

    @property
    def n_data(self) -> int:
        return sum(b.value.size for b in self.blocks) + sum(e.value.size for e in self.edges)


def _noise_line(v: np.ndarray, var: np.ndarray) -> tuple[float, float]:
    """(a, b) of var = a + b v fitted to per-column variances (b >= 0, a > 0)."""
    ok = np.isfinite(var) & np.isfinite(v)
    if ok.sum() < 3 or np.ptp(v[ok]) < 1e-6:
        a = float(np.median(var[ok])) if ok.any() else 1e-8
        return max(a, 1e-12), 0.0
    b, a = np.polyfit(v[ok], var[ok], 1)
    b = max(float(b), 0.0)
    a = float(np.median(var[ok] - b * v[ok]))
    return max(a, 1e-12), b


def _calibration_var(v, noise: tuple[float, float], calibration_lines: int) -> np.ndarray:
    a, b = noise
    v = np.asarray(v, dtype=np.float64)
    return (v * v * (a + b) + (1 - v) ** 2 * a) / calibration_lines


def _fundamental(x: np.ndarray, p: np.ndarray, period: float) -> tuple[float, float, float]:
    """(amplitude, phase of a black bar's start, period) of the best fundamental near
    ``period`` (a fine search, as measure_rmtf refines its period)."""
    n_per = max(np.ptp(x) / period, 1.0)
    best = (-1.0, 0.0, period)
    for per in period * (1 + np.linspace(-0.5, 0.5, 81) / n_per):
        ph = 2 * np.pi * x / per
        m = np.column_stack([np.cos(ph), np.sin(ph), np.ones_like(ph)])
        c = np.linalg.lstsq(m, p, rcond=None)[0]
        amp = float(np.hypot(c[0], c[1]))
        if amp > best[0]:
            # white bars centred at phi + 3P/4 (black on [phi, phi + P/2))
            psi = np.arctan2(c[1], c[0])
            best = (amp, float((psi / (2 * np.pi) - 0.75) * per % per), float(per))
    return best


def bar_observation(
    image: np.ndarray,
    dpi: float,
    z_mm: float,
    *,
    name: str = "image",
    margin_um: float = 600.0,
    calibration_lines: int = CALIBRATION_LINES,
) -> Observation:
    """The bar blocks of a chart image as waveforms to fit.

    Parameters
    ----------
    image : [line, column] shading-corrected values
    dpi : the image's resolution (the merged line's)
    z_mm : height of the chart above the scanner's top surface (mm)
    margin_um : columns closer than this to a block's first or last crossing are left
        out (the block's ends see the white margin; the bars inside are periodic)
    calibration_lines : lines of the scanner's shading references

    Raises
    ------
    ValueError
        No bar block in the image.
    """
    img = np.asarray(image, dtype=np.float64)
    found = measure_rmtf(img, dpi)
    if not found:
        raise ValueError("no bar block found (as measure-rmtf finds them)")
    pitch = pitch_of_dpi(dpi)
    r0, r1 = img.shape[0] // 4, max(img.shape[0] * 3 // 4, 1)
    rows = img[r0:r1]
    n_lines = rows.shape[0]
    kept, cols, means, vars_ = [], [], [], []
    for b in found:
        lo = b["start_px"] + (margin_um + b["period_um"]) / pitch
        hi = b["stop_px"] - (margin_um + b["period_um"]) / pitch
        c = np.arange(int(np.ceil(lo)), int(np.floor(hi)) + 1)
        c = c[(c >= 0) & (c < img.shape[1])]
        if c.size * pitch < 3 * b["period_um"]:  # too short a block to tell its shape
            continue
        kept.append(b)
        cols.append(c)
        means.append(rows[:, c].mean(axis=0))
        vars_.append(rows[:, c].var(axis=0, ddof=1) if n_lines > 1 else np.zeros(c.size))
    if not cols:
        raise ValueError("no bar block wide enough to fit (3 periods inside its ends)")
    allm, allv = np.concatenate(means), np.concatenate(vars_)
    noise = _noise_line(allm, allv) if n_lines > 1 else (1e-8, 0.0)
    blocks = []
    for b, c, m in zip(kept, cols, means, strict=True):
        x = (c + 0.5) * pitch
        var = (noise[0] + noise[1] * m) / n_lines + _calibration_var(m, noise, calibration_lines)
        _, phase, per = _fundamental(x, m, b["period_um"])
        blocks.append(BarBlock(per, phase, x, m, var))
    return Observation(name, "bars", float(z_mm), float(dpi), blocks=tuple(blocks), noise=noise)


def _edge_line(sub: np.ndarray, axis: int) -> tuple[float, float, bool, float, float]:
    """(pos, slope, dark_after, white, dark) of the edge in a region, pixel units, from
    each line's crossing of the half level (axis 0: lines are rows, the edge crosses
    columns)."""
    a = sub if axis == 0 else sub.T
    lo, hi = np.percentile(a, [5, 95])
    mid = (lo + hi) / 2
    dark_after = a[:, -3:].mean() < a[:, :3].mean()
    t, pos = [], []
    for i, line in enumerate(a):
        d = line - mid
        j = np.flatnonzero(np.signbit(d[:-1]) != np.signbit(d[1:]))
        if j.size == 1:
            k = j[0]
            t.append(i)
            pos.append(k + d[k] / (d[k] - d[k + 1]))
    if len(t) < 4:
        raise ValueError("no straight edge found in the dark square's region")
    slope, p0 = np.polyfit(t, pos, 1)
    return float(p0), float(slope), bool(dark_after), float(hi), float(lo)


def edge_observation(
    image: np.ndarray,
    dpi: float,
    z_mm: float,
    *,
    name: str = "image",
    flat_um: float = 400.0,
    keep_um: float = 600.0,
    calibration_lines: int = CALIBRATION_LINES,
) -> Observation:
    """The left (spread along x) and top (along y) edges of a slanted dark square.

    ``flat_um``: pixels farther than this from the edge's line are its flat parts, whose
    scatter gives the noise (a + b v from the white and the dark side); ``keep_um``: the
    pixels fitted are those nearer than this to it (the spread and the levels each side).

    Raises
    ------
    ValueError
        No dark square with usable edges.
    """
    img = np.asarray(image, dtype=np.float64)
    rois = square_edge_rois(img)
    pitch = pitch_of_dpi(dpi)
    regions, flats = [], []
    for axis, key in ((0, "x"), (1, "y")):
        x0, y0, x1, y1 = rois[key]
        sub = img[y0:y1, x0:x1]
        if min(sub.shape) < 8:
            raise ValueError("the dark square's edge region is too small")
        p0, slope, dark_after, white, dark = _edge_line(sub, axis)
        yy, xx = np.meshgrid(np.arange(y0, y1), np.arange(x0, x1), indexing="ij")
        xu, yu = (xx.ravel() + 0.5) * pitch, (yy.ravel() + 0.5) * pitch
        n_along = sub.shape[0] if axis == 0 else sub.shape[1]
        ref = ((y0 if axis == 0 else x0) + n_along / 2) * pitch
        # the line in um: across = pos + slope (along - ref), pos at the region's centre
        start = (x0 if axis == 0 else y0) * pitch
        pos = start + (p0 + 0.5 + slope * (n_along / 2 - 0.5)) * pitch
        across, along = (xu, yu) if axis == 0 else (yu, xu)
        dist = across - (pos + slope * (along - ref))
        v = sub.ravel()
        far = np.abs(dist) > flat_um
        side = dist > 0
        flat = []
        for s in (True, False):
            sel = far & (side == s)
            if sel.sum() > 3:
                flat.append((float(v[sel].mean()), float(v[sel].var(ddof=1))))
        flats.extend(flat)
        near = np.abs(dist) < keep_um
        regions.append((axis, xu[near], yu[near], v[near], pos, slope, ref, dark_after))
    if len(flats) < 2:
        raise ValueError("the edge regions hold no flat white and dark parts to measure noise")
    m = np.array([f[0] for f in flats])
    s2 = np.array([f[1] for f in flats])
    # one pixel's variance a + b v; its scatter over the flat parts already holds the
    # columns' shading error (different columns), so no calibration term is added
    noise = _noise_line(m, s2)
    edges = []
    for axis, xu, yu, v, pos, slope, ref, dark_after in regions:
        var = noise[0] + noise[1] * np.clip(v, 0, None)
        edges.append(EdgeRegion(axis, xu, yu, v, var, pos, slope, ref, dark_after))
    del calibration_lines  # the flat parts' scatter holds it (see above)
    return Observation(name, "edge", float(z_mm), float(dpi), edges=tuple(edges), noise=noise)


def observation(
    image: np.ndarray,
    dpi: float,
    z_mm: float,
    *,
    name: str = "image",
    calibration_lines: int = CALIBRATION_LINES,
    chart_dpi: float | None = None,
) -> Observation:
    """Bar blocks where the image holds them, else a slanted dark square's edges.
    ``chart_dpi``: the resolution a slanted edge was drawn at (its pixels' blur is then
    part of the model, :func:`~.fitmodel.chart_blurred`); None: an ideal chart. Refused
    for bars: a block whose period is a whole number of the chart's pixels (the
    project's 100/150/200-dpi blocks at 2400 or 4800 dpi; its 247-dpi one is not) has
    every edge at one phase of them, so no average blur describes it (docs/fit.md).

    Raises
    ------
    ValueError
        Neither a bar block nor a slanted dark square: no chart of the project's.
    """
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2 or min(img.shape) < 16:
        raise ValueError(f"expected a grey image of 16 x 16 pixels or more (got {img.shape})")
    if chart_dpi is not None and not chart_dpi > 0:
        raise ValueError(f"chart_dpi: must be > 0 (got {chart_dpi!r})")
    chart = {} if chart_dpi is None else {"chart_um": float(pitch_of_dpi(chart_dpi))}
    try:
        o = bar_observation(img, dpi, z_mm, name=name, calibration_lines=calibration_lines)
    except ValueError as bar_err:
        try:
            o = edge_observation(img, dpi, z_mm, name=name, calibration_lines=calibration_lines)
        except ValueError as edge_err:
            raise ValueError(
                f"no chart found: {bar_err}; and no slanted dark square ({edge_err})"
            ) from None
    if chart and o.kind == "bars":
        raise ValueError(
            "chart_dpi: modelled for a slanted edge only (it crosses the chart's pixels at "
            "every phase); a bar block's edges lie at one phase of them, which no average "
            "blur describes: draw the bars finer, or leave CHART_DPI out"
        )
    return replace(o, **chart)
