"""Depth of field from sampled RMTF curves (paper section 4, Fig. 11): the first
crossing of the threshold, its range under the Monte Carlo error, the spurious ranges past
it, and where a curve must be sampled more finely so that no crossing hides between two
samples. Pure functions on arrays of Z (mm), RMTF and its standard error."""

from __future__ import annotations

import numpy as np

from ..defaults import DOF_THRESHOLD


def depth_of_field(z_mm: np.ndarray, rmtf: np.ndarray, threshold: float = DOF_THRESHOLD) -> float:
    """First Z (mm) where the RMTF falls below ``threshold``, interpolated linearly
    between the samples on either side (paper section 4: the largest Z up to which the
    RMTF stays >= threshold).

    0 if RMTF starts below the threshold; the last Z if it never drops below. A dip that
    falls between two samples is found only on samples that resolve it: see
    :func:`refine_points`, which :func:`rmtf` applies.
    """
    z = np.asarray(z_mm, dtype=np.float64)
    r = np.asarray(rmtf, dtype=np.float64)
    if r[0] < threshold:
        return 0.0
    below = np.flatnonzero(r < threshold)
    if below.size == 0:
        return float(z[-1])
    return _crossing(z, r, int(below[0]), threshold)


def dof_bounds(
    z_mm: np.ndarray,
    rmtf: np.ndarray,
    se: np.ndarray,
    threshold: float = DOF_THRESHOLD,
    k: float = 2.0,
) -> list[float]:
    """[low, high] (mm): the depth of field of the curves ``rmtf - k se`` and
    ``rmtf + k se``, the range that the figure's Monte Carlo error leaves open (k = 2:
    about 95 %). A shallow dip that noise may or may not take below the threshold opens
    the range up to the next crossing, where a single figure would flip with the seed."""
    r, e = np.asarray(rmtf, dtype=np.float64), np.asarray(se, dtype=np.float64)
    return [
        depth_of_field(z_mm, r - k * e, threshold),
        depth_of_field(z_mm, r + k * e, threshold),
    ]


def _crossing(z: np.ndarray, r: np.ndarray, i: int, threshold: float) -> float:
    """Z where the RMTF crosses ``threshold`` between samples i - 1 and i (linear)."""
    return float(z[i - 1] + (r[i - 1] - threshold) / (r[i - 1] - r[i]) * (z[i] - z[i - 1]))


def spurious_ranges(
    z_mm: np.ndarray, rmtf: np.ndarray, threshold: float = DOF_THRESHOLD
) -> list[list[float]]:
    """Ranges [from, to] of Z (mm) past the depth of field where the RMTF is back at or
    above the threshold; each end is the crossing interpolated linearly between samples
    (the last Z where the RMTF is still over the threshold there).

    The RMTF (paper Eq. 1) is a modulation, blind to the sign of the contrast: past a zero
    of the transfer function the bars come back reversed (dark where the chart is light),
    *spurious resolution*; with ghost light, ghost copies of the periodic chart add in
    and out of phase with the direct image as Z changes. Such ranges are reported and
    never counted in the depth of field (:func:`depth_of_field` stops at the first
    crossing).
    """
    z = np.asarray(z_mm, dtype=np.float64)
    r = np.asarray(rmtf, dtype=np.float64)
    below = np.flatnonzero(r < threshold)
    if below.size == 0:
        return []
    out: list[list[float]] = []
    start = None
    for i in range(int(below[0]) + 1, z.size):
        if r[i] >= threshold and start is None:
            start = _crossing(z, r, i, threshold)
        if start is not None and r[i] < threshold:
            out.append([start, _crossing(z, r, i, threshold)])
            start = None
    if start is not None:
        out.append([start, float(z[-1])])
    return out


#: an interval is refined where its samples lie within this many standard errors (plus
#: the room the curve's curvature leaves) of the threshold ...
REFINE_K_SE = 3.0
#: ... or where the curve changes by more than this between two samples (a jump)
REFINE_JUMP = 0.15


def refine_points(
    z_mm: np.ndarray,
    rmtf: np.ndarray,
    se: np.ndarray,
    threshold: float = DOF_THRESHOLD,
    *,
    steps: int = 8,
    k_se: float = REFINE_K_SE,
    jump: float = REFINE_JUMP,
    step_for_margin=None,
) -> np.ndarray:
    """Z (mm) to sample between the samples of one RMTF curve so that no crossing of
    ``threshold`` hides between them: ``steps - 1`` points inside every interval that

    - crosses the threshold (the depth of field, the ends of spurious ranges);
    - comes near it: the sample nearer the threshold is within ``k_se`` standard errors
      plus a quarter of the curve's second difference there (twice the most a smooth
      curve of that curvature departs from the straight line between the samples: the
      room it has to dip through the threshold and back unseen);
    - jumps: the curve changes by more than ``jump`` (ghost copies of the periodic
      chart moving in and out of phase: the curve is not resolved there).

    and, with ``step_for_margin`` (margin -> the Z step that resolves the curve to within
    that margin, from how fast the light's image moves with Z:
    :func:`~opticalstamp.analysis.lsf.fast_light`), every interval up to the
    first crossing subdivided to at most the step for its margin over the threshold
    (at most ``steps`` subdivisions per interval, as the other rules): samples that look smooth may
    be an oscillation aliased by the grid, and the first crossing is the depth of field.

    Returns the new Z, ascending, none of them already a sample. Applied again to the
    refined samples it refines further (:func:`rmtf` makes ``passes`` such rounds).
    """
    z = np.asarray(z_mm, dtype=np.float64)
    r = np.asarray(rmtf, dtype=np.float64)
    e = np.asarray(se, dtype=np.float64)
    if z.size < 2 or steps < 2:
        return np.zeros(0)
    dr = np.abs(np.diff(r))
    curv = np.zeros(dr.size)  # the second difference at either end of each interval
    if r.size > 2:
        d2 = np.abs(np.diff(r, 2))
        curv = np.maximum(np.r_[d2[:1], d2], np.r_[d2, d2[-1:]])
    above = r >= threshold
    both_above = above[:-1] & above[1:]
    gap = np.where(
        both_above,
        np.minimum(r[:-1], r[1:]) - threshold,
        threshold - np.maximum(r[:-1], r[1:]),
    )  # >= 0 where both samples are on one side; < 0 where the interval crosses
    band = k_se * np.maximum(e[:-1], e[1:]) + 0.25 * curv
    flag = (gap < 0) | (gap <= band) | (dr > jump)
    n_sub = np.where(flag, steps, 1)
    if step_for_margin is not None:
        first = np.flatnonzero(gap < 0)
        upto = first[0] + 1 if first.size else z.size - 1
        step = step_for_margin(np.abs(gap[:upto]))
        need = np.minimum(np.ceil(np.diff(z)[:upto] / step), steps)
        n_sub[:upto] = np.maximum(n_sub[:upto], need.astype(int))
    new = [np.linspace(z[i], z[i + 1], n + 1)[1:-1] for i, n in enumerate(n_sub) if n > 1]
    if not new:
        return np.zeros(0)
    pts = np.unique(np.concatenate(new).round(9))
    return pts[~np.isin(pts, z.round(9))]


def dof_text(res: dict, key: str | None = None) -> str:
    """The depth of field of an RMTF result (as ``RMTFResult.to_dict()``) for chart
    ``key`` (default: its depth-of-field chart) as an engineer reads it: "2.46 mm",
    "≥ 4.50 mm" where the curve never falls below the threshold in the range computed,
    "0 mm (RMTF < 0.3 already at Z = 0 mm)" where it starts below."""
    key = _key(res["dof_dpi"]) if key is None else key
    v, thr = res["dof_mm"][key], res["dof_threshold"]
    if res.get("dof_open_ended", {}).get(key):
        return f"≥ {v:.2f} mm"
    r0 = res["rmtf_max"][key][0]
    if v == 0.0 and r0 < thr:
        return f"0 mm (RMTF < {thr:g} already at Z = {res['z_mm'][0]:g} mm)"
    lo, hi = res.get("dof_range_mm", {}).get(key, (v, v))
    if hi - lo >= 0.01:
        return f"{v:.2f} mm ({lo:.2f}–{hi:.2f} at ±2 SE)"
    return f"{v:.2f} mm"


def _key(dpi: float) -> str:
    return f"{dpi:g}"


def dof_rule(res: dict, line_dpi: float | None = None) -> str:
    """The rule of an RMTF result's depth of field in words: "RMTF on the 200-dpi chart
    (2/3 of the design's 300 dpi) >= 0.3"."""
    chart = f"{res['dof_dpi']:g}-dpi chart"
    if line_dpi is not None:
        frac = res["dof_dpi"] / line_dpi
        chart += f" (2/3 of the design's {line_dpi:g} dpi)" if abs(frac - 2 / 3) < 0.01 else ""
    light = "" if res.get("ghosts", True) else ", own path only"
    line = "" if res.get("shading", True) else ", raw merged line"
    return f"RMTF on the {chart}{light}{line} ≥ {res['dof_threshold']:g}"


def dof_lines(res: dict, line_dpi: float | None = None) -> list[str]:
    """What an RMTF result says of its depth of field, as lines of text: the figure with
    its rule and range, the other charts, and where the curve comes back over the
    threshold (spurious resolution, ghost copies of the periodic chart), with why."""
    key = _key(res["dof_dpi"])
    thr = res["dof_threshold"]
    if (res.get("meta") or {}).get("no_light"):
        return [
            "no light reaches the pixels through this design (every RMTF is 0 for want of a "
            "signal, not of contrast): no depth of field; see `opticalstamp ghosts`"
        ]
    out = [f"depth of field ({dof_rule(res, line_dpi)}): {dof_text(res, key)}"]
    others = [k for k in res["dof_mm"] if k != key]
    if others:
        out.append("  other charts: " + ", ".join(f"{k} dpi {dof_text(res, k)}" for k in others))
    back = res.get("spurious_mm", {}).get(key, [])
    if back:
        spans = ", ".join(f"{a:.2f}–{b:.2f}" for a, b in back)
        why = (
            "ghost copies of the periodic chart landing beside the direct image add in and "
            "out of phase as Z changes, and past a zero of the transfer function bars come "
            "back reversed; a real page is not periodic"
            if res.get("ghosts", True)
            else "past a zero of the transfer function the bars come back reversed"
        )
        out.append(
            f"  RMTF back ≥ {thr:g} at Z = {spans} mm, past the depth of field and not "
            f"counted in it (spurious resolution: {why}; the curve was sampled finely there)"
        )
    return out
