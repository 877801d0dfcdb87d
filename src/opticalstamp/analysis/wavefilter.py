"""Angular filters of the wave engine: Fresnel losses and the pixel's acceptance cone.

The transverse invariant s = n sin(theta) is conserved through the planar stack, so both
are filters on the angular spectrum, functions of |s| = sqrt(s_x^2 + s_y^2):

* **Fresnel losses.** A planar interface between indices n1 and n2 transmits the power
  T_s(s), T_p(s) of the s and p polarisations (``raytrace/kernel.py::_fresnel_sp``). A
  filter acts on the field as the amplitude sqrt(T) at the interface's plane. Filters
  and free-space propagation commute, masks and filters do not: the interfaces are
  grouped by the masks between them (group 0 below the sensor-side mask, group i
  between masks i - 1 and i, the last group above the object-side mask: the reference
  gap and the object medium). An interface at the plane of a mask (a mask on a glass
  face under an air gap) comes after the mask, as in the tracer. Within a group no mask
  changes the directions, so the plane of incidence holds and the group transmits
  (prod T_s + prod T_p) / 2, as the tracer computes it for the whole stack; across a
  mask the scalar engine treats the light as unpolarised again (the tracer keeps s and
  p through the masks: the two differ by (T_s1 - T_p1)(T_s2 - T_p2) / 4 for two
  interfaces in different groups, below 1e-4 in a band of 0.35 at air-glass
  interfaces). Multiple reflections between the interfaces are left out, as in the
  tracer.
* **The acceptance cone.** The pixel accepts |s| <= n0 sin(half-angle), n0 the index of
  the medium next to it (``raytrace/pixel.py::acceptance_s2``): in reverse, the pixel's
  points emit only those directions, a 0/1 filter on their spectra (with group 0).

The separable path needs each group's filter G(s_x, s_y) as a short sum of separable
terms sum_t a_t(s_x) b_t(s_y) on the band |s_x|, |s_y| < B. The smooth Fresnel part is
taken from the SVD of G sampled on the band (Nystrom-extended to the grids' frequency
bins), with the fewest terms whose largest error over every bin is below ``FILTER_TOL``
of the filter's peak (measured on the bins against the exact filter and recorded). The
cone's disk is not low-rank (its SVD converges slowly: 1 % of the power left out at 8
terms, 0.2 % at 32); it is a staircase of ``CONE_STEPS`` strips of whole rows of s_y
bins (equal steps in angle along the rim), each times a row of s_x bins that carries,
over the strip, exactly the power of the disk on those bins (1 out to a chord, the next
pair of bins at a fractional amplitude). The cone's etendue is kept exactly; what moves
is the shape of its rim, by up to a strip's step in s (the power of the difference
from the disk, ``power_error``, is 1.5 % of the disk's at 16 strips and halves with each
doubling). Where nothing changes the index and the cone holds the band, every filter
is 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..design import Design

#: Largest error of the separable Fresnel filter over the band, relative to its peak.
FILTER_TOL = 1e-5
#: Strips of the acceptance cone's staircase over the cone's rim inside the band.
CONE_STEPS = 16
#: Samples per axis of the band for the SVD (Nystrom nodes).
SVD_NODES = 161


def fresnel_sp(n1: float, n2: float, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Power transmittances (T_s, T_p) of a planar interface n1 -> n2 for |s| = ``s``
    (0 where |s| >= min(n1, n2): total internal reflection one way or evanescent)."""
    s = np.asarray(s, dtype=np.float64)
    ok = s < min(n1, n2)
    ss = np.where(ok, s, 0.0)
    c1 = np.sqrt(1 - (ss / n1) ** 2)
    c2 = np.sqrt(1 - (ss / n2) ** 2)
    rs = (n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2)
    rp = (n2 * c1 - n1 * c2) / (n2 * c1 + n1 * c2)
    return np.where(ok, 1 - rs * rs, 0.0), np.where(ok, 1 - rp * rp, 0.0)


def interfaces(design: Design) -> list[tuple[int, float, float]]:
    """The index changes on the way up: (group, n1, n2) each, group = the number of
    masks below the interface or at its plane (the module docstring)."""
    media = [design.index(sl.medium) for sl in design.slabs]
    group, out = [], []
    n_masks = 0
    for sl in design.slabs:
        n_masks += sl.mask_top is not None
        group.append(n_masks)
    if design.reference_gap.thickness_um > 0:
        media.append(design.index(design.reference_gap.medium))
        group.append(n_masks)
    media.append(design.index(design.object_medium))
    for i in range(len(media) - 1):
        if media[i] != media[i + 1]:
            out.append((group[i], float(media[i]), float(media[i + 1])))
    return out


def group_transmittance(pairs: list[tuple[float, float]], s: np.ndarray) -> np.ndarray:
    """Power transmittance (prod T_s + prod T_p) / 2 of interfaces ``pairs`` [(n1, n2)]
    with no mask between them, for |s| = ``s``."""
    ps = np.ones_like(np.asarray(s, dtype=np.float64))
    pp = ps.copy()
    for n1, n2 in pairs:
        ts, tp = fresnel_sp(n1, n2, s)
        ps, pp = ps * ts, pp * tp
    return 0.5 * (ps + pp)


def cone_cut(design: Design) -> float:
    """|s| of the pixel's acceptance cone in the medium next to it (inf: none)."""
    cut = design.sensor.acceptance_half_angle_deg
    if cut >= 90.0:
        return math.inf
    return float(design.index(design.slabs[0].medium) * math.sin(math.radians(cut)))


@dataclass(frozen=True)
class SeparableFilter:
    """A filter on the angular spectrum as sum_t a_t(s_x) b_t(s_y).

    Attributes
    ----------
    a, b : (K, nx), (K, ny) the terms on the bins of each axis (0 outside the band)
    info : plain data: ``group``, ``interfaces`` [(n1, n2)], ``cone`` (|s| or None),
        ``terms`` K, ``max_error`` (largest |G - sum_t a_t b_t| over the band's bins,
        relative to max G), ``power_error`` (sum |G - ...|^2 / sum G^2 over the bins)
    """

    a: np.ndarray
    b: np.ndarray
    info: dict = field(default_factory=dict)


def _svd_terms(g, band: float, sx: np.ndarray, sy: np.ndarray, sub, k_max: int = 8):
    """Separable terms of the smooth filter g(s_x, s_y) on the bins ``sx``, ``sy``: the
    SVD of g on SVD_NODES nodes per axis, Nystrom-extended to the bins, the fewest terms
    within FILTER_TOL of the peak on the bins ``sub`` (a regular subset). Returns
    (a (K, nx), b (K, ny), error, g on the subset)."""
    nodes = np.linspace(-band, band, SVD_NODES)
    u, sig, vt = np.linalg.svd(g(nodes[:, None], nodes[None, :]))
    gx = g(sx[:, None], nodes[None, :])  # (nx, nodes)
    gy = g(nodes[:, None], sy[None, :])  # (nodes, ny)
    exact = g(sx[sub[0]][:, None], sy[sub[1]][None, :])
    peak = float(np.abs(exact).max())
    k_max = min(k_max, int(np.sum(sig > sig[0] * 1e-14)))
    for k in range(1, k_max + 1):
        # g(x, y) ~ g(x, nodes) V S^-1 U^T g(nodes, y), rank k
        a = (gx @ vt[:k].T / np.sqrt(sig[:k])).T
        b = (u[:, :k].T @ gy) / np.sqrt(sig[:k])[:, None]
        err = float(np.abs(a[:, sub[0]].T @ b[:, sub[1]] - exact).max()) / peak
        if err <= FILTER_TOL:
            break
    return a, b, err, exact


def _staircase(cut: float, band: float, steps: int) -> list[tuple[float, float]]:
    """Strips (y_lo, y_hi) over 0 <= |s_y| < min(cut, band): ``steps`` equal steps in
    angle along the disk's rim inside the band, and one strip below them where the disk
    holds the band's whole width."""
    top = min(cut, band)
    flat = math.sqrt(max(cut * cut - band * band, 0.0))
    phi = np.linspace(math.asin(min(flat / cut, 1.0)), math.asin(top / cut), steps + 1)
    ys = ([0.0] if flat <= 0 else [0.0, flat]) + list(cut * np.sin(phi)[1:])
    return [(lo, hi) for lo, hi in zip(ys[:-1], ys[1:], strict=True) if hi > lo]


def _cone_terms(cut: float, band: float, sx: np.ndarray, sy: np.ndarray, steps: int):
    """The cone's disk |s| <= ``cut`` on the bins as strips of whole rows of s_y (the
    strips of :func:`_staircase`), each times a row of s_x whose power over the strip
    is the disk's on those bins exactly: 1 out to a chord, the next pair of bins at the
    amplitude that carries the remainder. Returns (ca (K, nx), cb (K, ny))."""
    ax, ay = np.abs(sx), np.abs(sy)
    levels, mult = np.unique(ax, return_counts=True)  # |s_x| of the bins, and how many
    cum = np.cumsum(mult)
    ca, cb = [], []
    for lo, hi in _staircase(cut, band, steps):
        rows = (ay >= lo) & (ay < hi) & (ay <= cut)
        if not rows.any():
            continue
        chords = np.sqrt(np.clip(cut * cut - ay[rows] ** 2, 0.0, None))
        counts = cum[np.searchsorted(levels, chords, side="right") - 1]  # bins with |s_x| <= chord
        mean = counts.mean()  # the disk's bins per row over the strip
        j = int(np.searchsorted(cum, mean + 1e-9, side="right"))  # levels wholly inside
        row = (ax < levels[j]).astype(float) if j < levels.size else np.ones(sx.size)
        if j < levels.size:
            inside = cum[j - 1] if j else 0
            row[ax == levels[j]] = np.sqrt(max(mean - inside, 0.0) / mult[j])
        ca.append(row)
        cb.append(rows.astype(float))
    return np.array(ca), np.array(cb)


def separable_filter(
    design: Design,
    group: int,
    band: float,
    sx: np.ndarray,
    sy: np.ndarray,
    *,
    cone: bool = True,
    fresnel: bool = True,
) -> SeparableFilter | None:
    """Group ``group``'s filter (amplitude) on the bins s_x = ``sx``, s_y = ``sy`` (the
    grids' in-band frequencies times lambda), as a :class:`SeparableFilter`; None where
    it is 1 over the band (no index change in the group, no cone cutting into it)."""
    pairs = [(n1, n2) for g, n1, n2 in interfaces(design) if g == group] if fresnel else []
    cut = cone_cut(design) if (cone and group == 0) else math.inf
    cuts = cut < band * math.sqrt(2.0)
    if not pairs and not cuts:
        return None
    # the errors on every bin, or on a regular subset of at most ~1000 per axis
    sub = (slice(None, None, -(-sx.size // 1024)), slice(None, None, -(-sy.size // 1024)))
    if pairs:

        def g(x, y):
            return np.sqrt(group_transmittance(pairs, np.hypot(x, y)))

        a, b, err, exact = _svd_terms(g, band, sx, sy, sub)
    else:
        a, b, err = np.ones((1, sx.size)), np.ones((1, sy.size)), 0.0
        exact = np.ones((sx[sub[0]].size, sy[sub[1]].size))
    info = {"group": group, "interfaces": pairs, "cone": None, "terms": int(a.shape[0])}
    if cuts:
        ca, cb = _cone_terms(cut, band, sx, sy, CONE_STEPS)
        a = (ca[:, None, :] * a[None]).reshape(-1, sx.size)
        b = (cb[:, None, :] * b[None]).reshape(-1, sy.size)
        exact = exact * (np.hypot(sx[sub[0]][:, None], sy[sub[1]][None, :]) <= cut)
        info |= {"cone": cut, "terms": int(a.shape[0]), "cone_strips": int(ca.shape[0])}
    approx = a[:, sub[0]].T @ b[:, sub[1]]
    peak = float(np.abs(exact).max())
    den = float(np.sum(exact**2))
    info["max_error"] = float(np.abs(approx - exact).max()) / peak if peak > 0 else 0.0
    info["power_error"] = float(np.sum((approx - exact) ** 2)) / den if den > 0 else 0.0
    info["fresnel_max_error"] = err
    return SeparableFilter(a, b, info)
