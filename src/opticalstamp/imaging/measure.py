"""Measuring images: RMTF of bar charts (paper Eq. 1, Fig. 12) and slanted-edge SFR
(ISO 12233 e-SFR). Arrays are images indexed [row = y, col = x], values in [0, 1].
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..units import UM_PER_MM, dpi_of_period, pitch_of_dpi

#: width (um) of the envelope window that sets the local bar threshold (> 2 periods of
#: the coarsest paper chart, 508 um)
ENVELOPE_UM = 1200.0


def _profile(image: np.ndarray, axis: int, rows: tuple[int, int] | None) -> np.ndarray:
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2:
        raise ValueError(f"image must be 2-D grey (got shape {img.shape})")
    if axis == 1:  # bars vary along y: measure along rows of the transpose
        img = img.T
    r0, r1 = rows if rows is not None else (img.shape[0] // 4, max(img.shape[0] * 3 // 4, 1))
    if not 0 <= r0 < r1 <= img.shape[0]:
        raise ValueError(f"rows: need 0 <= start < stop <= {img.shape[0]} (got {rows})")
    return img[r0:r1].mean(axis=0)


def _rows(image: np.ndarray, axis: int, rows: tuple[int, int] | None) -> np.ndarray:
    """The rows that :func:`_profile` averages, as [row, position]."""
    img = np.asarray(image, dtype=np.float64)
    img = img.T if axis == 1 else img
    r0, r1 = rows if rows is not None else (img.shape[0] // 4, max(img.shape[0] * 3 // 4, 1))
    return img[r0:r1]


def _fundamental(
    p: np.ndarray, rows: np.ndarray, a: float, b: float, period_px: float
) -> tuple[float, float]:
    """Amplitude of the fundamental fitted over [a, b] of profile ``p`` and the contrast
    to noise 2 amplitude / sigma, sigma the rms along the bars (inf where there is no
    noise). The period is refined around ``period_px`` (from the crossings, which a
    coarse sampling biases) to the one of the largest fitted amplitude: a period off by
    a fraction e loses phase over the block and with it amplitude."""
    i = np.arange(int(np.ceil(a)), int(np.floor(b)) + 1)
    i = i[(i >= 0) & (i < p.size)]
    n_per = max(i.size / period_px, 1.0)
    best = 0.0
    for per in period_px * (1 + np.linspace(-0.5, 0.5, 41) / n_per):
        ph = 2 * np.pi * i / per
        m = np.column_stack([np.cos(ph), np.sin(ph), np.ones_like(ph)])
        coef = np.linalg.lstsq(m, p[i], rcond=None)[0]
        best = max(best, float(np.hypot(coef[0], coef[1])))
    sigma = float(rows[:, i].std(axis=0, ddof=1).mean()) if rows.shape[0] > 1 else 0.0
    # no noise to speak of (a noiseless chart: rounding only): contrast to noise unbounded
    return best, (2 * best / sigma if sigma > 1e-9 * max(best, 1e-12) else float("inf"))


def _crossings(p: np.ndarray, mid: np.ndarray) -> np.ndarray:
    d = p - mid
    i = np.flatnonzero(np.signbit(d[:-1]) != np.signbit(d[1:]))
    return i + d[i] / (d[i] - d[i + 1])  # sub-pixel positions


def measure_rmtf(
    image: np.ndarray,
    dpi: float,
    *,
    axis: int = 0,
    rows: tuple[int, int] | None = None,
    min_periods: int = 3,
    tolerance: float = 0.2,
    min_contrast: float = 1e-4,
) -> list[dict]:
    """Find the bar blocks of a chart image and measure RMTF = (Imax-Imin)/(Imax+Imin).

    The image is averaged over ``rows`` (default: the central half) into a profile along
    x (``axis`` 0; 1 for bars varying along y). The bars are the runs between crossings
    of the profile with the midpoint of its local envelope (max and min over
    :data:`ENVELOPE_UM`); consecutive periods (white + black run) of equal length
    (within ``tolerance``, at least 1.5 px) form a block. Imax and Imin are the maximum
    and minimum of the profile inside the block, leaving out its first and last bar
    (edge effects), as the paper does for Fig. 12; ``rmtf_bar_mean`` uses the mean of
    the per-bar extremes instead. Crossings where the local envelope's contrast
    (max - min)/(max + min) is below ``min_contrast`` are ripple on a flat field (a white
    margin's rounding), not bars, and are left out.

    Measures that restoration cannot fool (an RMTF pinned at 1 by overshoot clipped to
    [0, 1] can): ``amplitude``, the fundamental's amplitude fitted (least squares, a cos
    + b sin + c at the block's period) over the block's interior; ``amplitude_rel``, the
    same over the ideal's, 2/pi, the fundamental of black 0 and white 1 bars (what a
    perfect scanner band-limited to the image's grid reads); ``cnr``, contrast to noise,
    2 amplitude over the noise (the standard deviation along the bars, which are
    constant along them; the mean over the block's columns); ``overshoot``, how far the
    profile goes above white (1) or below black (0).

    Returns one dict per block: period_um, dpi (one bar = one dot), start_px, stop_px,
    n_periods, imax, imin, rmtf, rmtf_bar_mean, amplitude, amplitude_rel, cnr, overshoot.
    """
    if not dpi or dpi <= 0:
        raise ValueError(f"dpi must be > 0 (got {dpi})")
    p = _profile(image, axis, rows)
    block2d = _rows(image, axis, rows)
    px_um = pitch_of_dpi(dpi)
    win = max(3, int(round(ENVELOPE_UM / px_um)))
    hi = ndimage.maximum_filter1d(p, win, mode="nearest")
    lo = ndimage.minimum_filter1d(p, win, mode="nearest")
    mid = ndimage.uniform_filter1d((hi + lo) / 2, win, mode="nearest")
    c = _crossings(p, mid)
    env = (hi - lo)[c.astype(int)]
    c = c[env > min_contrast * np.maximum((hi + lo)[c.astype(int)], 1e-300)]
    # group by full periods (white + black run: immune to a threshold's duty-cycle bias)
    per = c[2:] - c[:-2]
    blocks, start = [], 0
    for i in range(1, per.size + 1):
        ref = np.median(per[start:i])
        if i < per.size and abs(per[i] - ref) <= max(tolerance * ref, 1.5):
            continue
        if i + 1 - start >= 2 * min_periods:
            blocks.append((start, i + 1))  # crossings c[start] ... c[i + 1]
        start = i
    out = []
    for s, e in blocks:
        # mean period from the interior crossings (the outer bars merge with the margin)
        period_px = float(2 * (c[e - 1] - c[s + 1]) / (e - s - 2))
        a, b = c[s + 1], c[e - 1]  # drop the first and last bar
        seg = p[int(np.ceil(a)) : int(np.floor(b)) + 1]
        if seg.size < 3:
            continue
        imax, imin = float(seg.max()), float(seg.min())
        ext_hi, ext_lo = [], []
        for j in range(s + 1, e - 1):
            bar = p[int(np.ceil(c[j])) : int(np.floor(c[j + 1])) + 1]
            if bar.size:
                white = bar.mean() > mid[int(c[j])]
                (ext_hi if white else ext_lo).append(bar.max() if white else bar.min())
        bm_hi = float(np.mean(ext_hi)) if ext_hi else imax
        bm_lo = float(np.mean(ext_lo)) if ext_lo else imin
        period = period_px * px_um
        fit = _fundamental(p, block2d, a, b, period_px)
        ideal = 2 / np.pi  # the band-limited chart's fundamental (black 0, white 1)
        out.append(
            {
                "period_um": period,
                "dpi": dpi_of_period(period),
                "start_px": float(c[s]),
                "stop_px": float(c[e]),
                "n_periods": (e - s) / 2,
                "imax": imax,
                "imin": imin,
                "rmtf": (imax - imin) / (imax + imin) if imax + imin > 0 else 0.0,
                "rmtf_bar_mean": (bm_hi - bm_lo) / (bm_hi + bm_lo) if bm_hi + bm_lo > 0 else 0.0,
                "amplitude": fit[0],
                "amplitude_rel": fit[0] / ideal,
                "cnr": fit[1],
                "overshoot": max(0.0, imax - 1.0, -imin),
            }
        )
    return out


# -- slanted-edge SFR ----------------------------------------------------------------------
def _centroids(img: np.ndarray, window: np.ndarray | None) -> np.ndarray:
    d = np.abs(np.diff(img, axis=1))  # [-1, 1] derivative between columns
    if window is not None:
        d = d * window
    x = np.arange(d.shape[1]) + 0.5
    s = d.sum(axis=1)
    return np.where(s > 0, (d * x).sum(axis=1) / np.where(s > 0, s, 1), np.nan)


def _transitions(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dark/light transitions in each row and in each column. Hysteresis at 25 % and 75 %
    of the 2-98 % percentile range keeps noise from counting: a row across one edge holds
    1, across a dark square or bar 2."""
    lo, hi = np.percentile(img, [2, 98])
    lab = np.where(img < lo + 0.25 * (hi - lo), -1, 0) + np.where(img > lo + 0.75 * (hi - lo), 1, 0)
    if not hi > lo:
        lab[:] = 0
    out = []
    for a in (lab, lab.T):
        idx = np.where(a != 0, np.arange(a.shape[1]), 0)
        np.maximum.accumulate(idx, axis=1, out=idx)
        f = np.take_along_axis(a, idx, axis=1)  # the last level reached, carried forward
        out.append(((f[:, 1:] != f[:, :-1]) & (f[:, :-1] != 0)).sum(axis=1))
    return out[0], out[1]


def _check_grey_levels(img: np.ndarray) -> None:
    """Refuse an image of two grey levels (1-bit, or thresholded): no SFR in it.

    A slanted edge sampled at two levels is a staircase set by the threshold, not by the
    blur: its oversampled ESF is a step wherever the threshold falls, and its "SFR" is
    that of the binarisation (about 1 everywhere; no MTF50). ISO 12233 needs grey levels.
    """
    lo, hi = img.min(), img.max()
    if lo < hi and not ((img > lo) & (img < hi)).any():
        raise ValueError(
            "the image holds only two grey levels (a 1-bit or thresholded image): its edge "
            "is a staircase set by the threshold, not by the blur, and has no SFR; measure "
            "a greyscale (8- or 16-bit) image"
        )


def sfr(
    image: np.ndarray,
    dpi: float,
    *,
    direction: str = "auto",
    oversample: int = 4,
    at_dpi=(100.0, 200.0),
) -> dict:
    """Spatial frequency response of a slanted edge (ISO 12233 e-SFR method).

    Steps: per-line edge centroids of the derivative (Hamming-windowed about a first
    line fit), a straight-line fit x_edge(y); every pixel's signed distance to the edge,
    perpendicular to it; an ESF binned at 1/``oversample`` pixel; LSF by a central
    difference, Hamming window centred on the LSF; |DFT| normalised at zero frequency,
    divided by the central difference's response sin(2 pi f d)/(2 pi f d) (capped at 10).

    ``direction``: "x" for a near-vertical edge (SFR along x), "y" for a near-horizontal
    edge (SFR along y), "auto" to choose by the stronger gradient; in "auto", an image
    whose rows and columns both cross two edges (a dark square, ``chart edge``) is
    measured on the square's left edge (:func:`square_edge_rois`; its region is returned
    as "roi", x0, y0, x1, y1).

    Returns freq_cy_per_mm, sfr, mtf50_cy_per_mm, sfr_at_dpi ({"100": ., "200": .} for
    the default ``at_dpi``, at the fundamental of those bar charts: 1/period),
    edge_angle_deg, direction. ``mtf50_cy_per_mm`` is NaN where the SFR stays at or above
    0.5 up to the sampling frequency (``mtf50_reached`` False: an edge sharper than the
    pixels can show; ``freq_cy_per_mm[-1]`` is how far it was followed).

    Raises
    ------
    ValueError
        No usable edge: none, more than one along ``direction``, too close to the grid
        or the border, or a profile without a single step (an SFR that would not be 1 at
        low frequency); or an image of two grey levels (1-bit or thresholded), which
        holds no SFR.
    """
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2 or min(img.shape) < 8:
        raise ValueError(f"image must be 2-D grey, at least 8 x 8 (got shape {img.shape})")
    if not dpi or dpi <= 0:
        raise ValueError(f"dpi must be > 0 (got {dpi})")
    if direction not in ("x", "y", "auto"):
        raise ValueError(f"direction must be x, y or auto (got {direction!r})")
    if not np.isfinite(img).all():
        raise ValueError("the image holds NaN or infinite values")
    _check_grey_levels(img)
    n_tr = dict(zip("xy", _transitions(img), strict=True))
    per_line = {k: float(np.median(n[n > 0])) if n.any() else 0.0 for k, n in n_tr.items()}
    if direction == "auto" and min(per_line.values()) > 1:  # a dark square: its left edge
        x0, y0, x1, y1 = square_edge_rois(img)["x"]
        r = sfr(img[y0:y1, x0:x1], dpi, direction="auto", oversample=oversample)
        if r["direction"] != "x":
            raise ValueError("the dark square's left edge is not usable for an SFR")
        return r | {"roi": [x0, y0, x1, y1]}
    if direction == "auto":
        gx = np.abs(np.diff(img, axis=1)).sum()
        gy = np.abs(np.diff(img, axis=0)).sum()
        direction = "x" if gx >= gy else "y"
    if per_line[direction] > 1:
        raise ValueError(
            f"the region holds more than one edge along {direction} ({per_line[direction]:g} "
            "per line): give a region around one edge, or use --direction both for a "
            "slanted dark square"
        )
    once = float(np.mean(n_tr[direction] == 1))
    if per_line[direction] and once < 0.95:
        raise ValueError(
            f"the edge does not cross the region from side to side ({once:.0%} of the lines "
            f"along {direction} cross it once, not 95 %): a corner or a second edge? give a "
            "region around one straight edge"
        )
    if direction == "y":
        img = img.T
    n_rows, n_cols = img.shape
    yrows = np.arange(n_rows, dtype=np.float64)
    cen = _centroids(img, None)
    ok = np.isfinite(cen)
    if ok.sum() < 4:
        raise ValueError("no edge found in the image")
    fit = np.polyfit(yrows[ok], cen[ok], 1)
    for _ in range(2):  # refine with a Hamming window about the fitted edge
        xc = np.polyval(fit, yrows)
        half = min(n_cols / 2, max(8.0, n_cols / 2))
        xx = np.arange(n_cols - 1) + 0.5
        t = np.clip((xx[None, :] - xc[:, None]) / half, -1, 1)
        win = 0.54 + 0.46 * np.cos(np.pi * t)
        cen = _centroids(img, win)
        ok = np.isfinite(cen)
        fit = np.polyfit(yrows[ok], cen[ok], 1)
    slope = fit[0]
    angle = float(np.degrees(np.arctan(slope)))
    if abs(slope) < 0.01:
        raise ValueError(
            f"edge angle {angle:.2f} deg is too close to the pixel grid for oversampling "
            "(slant it by 2-10 deg)"
        )
    cos_t = 1 / np.hypot(1.0, slope)
    xx = np.arange(n_cols, dtype=np.float64)
    dist = (xx[None, :] - np.polyval(fit, yrows)[:, None]) * cos_t  # perpendicular, px
    # use only the columns every line covers (a full band around the edge)
    lim = (min(np.polyval(fit, yrows).min(), n_cols - np.polyval(fit, yrows).max()) - 1) * cos_t
    lim = np.floor(lim)
    if lim < 4:
        raise ValueError("the edge runs too close to the image border")
    step = 1.0 / oversample
    nb = int(2 * lim / step)
    idx = np.floor((dist + lim) / step).astype(np.int64)
    sel = (idx >= 0) & (idx < nb)
    sums = np.bincount(idx[sel], weights=img[sel], minlength=nb)
    counts = np.bincount(idx[sel], minlength=nb)
    centres = -lim + (np.arange(nb) + 0.5) * step
    full = counts > 0
    if full.sum() < nb // 2:
        raise ValueError("too few samples along the edge to build an oversampled ESF")
    esf = np.interp(centres, centres[full], sums[full] / counts[full])
    lsf = np.zeros_like(esf)
    lsf[1:-1] = (esf[2:] - esf[:-2]) / 2
    lo, hi = np.percentile(img, [2, 98])
    if not abs(lsf.sum()) > 0.25 * (hi - lo):  # the step across the edge (0: none, or two)
        raise ValueError(
            "the profile across the edge has no single step (no edge, or two opposite ones)"
        )
    if lsf.sum() < 0:
        lsf = -lsf
    c0 = (lsf * np.arange(nb)).sum() / lsf.sum()
    t = np.clip((np.arange(nb) - c0) / (nb / 2), -1, 1)
    lsf = lsf * (0.54 + 0.46 * np.cos(np.pi * t))
    spec = np.abs(np.fft.rfft(lsf))
    spec = spec / spec[0]
    f_px = np.fft.rfftfreq(nb, d=step)  # cycles per pixel (perpendicular to the edge)
    arg = 2 * np.pi * f_px * step
    corr = np.ones_like(arg)
    nz = arg > 0
    corr[nz] = np.minimum(arg[nz] / np.sin(np.minimum(arg[nz], np.pi - 1e-9)), 10.0)
    s = spec * corr
    if not np.isfinite(s).all() or s[1] > 1.2:
        raise ValueError(
            f"the SFR is {s[1]:.3g} at its lowest frequency, not about 1: the region does not "
            "hold one clean edge"
        )
    keep = f_px <= 1.0  # up to the sampling frequency
    f_mm = f_px[keep] / pitch_of_dpi(dpi) * UM_PER_MM
    s = s[keep]
    below = np.flatnonzero(s < 0.5)
    if below.size and below[0] > 0:
        i = below[0]
        mtf50 = float(f_mm[i - 1] + (s[i - 1] - 0.5) / (s[i - 1] - s[i]) * (f_mm[i] - f_mm[i - 1]))
    else:
        mtf50 = float("nan")
    at = {f"{d:g}": float(np.interp(d / 50.8, f_mm, s)) for d in at_dpi}
    return {
        "direction": direction,
        "edge_angle_deg": angle,
        "freq_cy_per_mm": f_mm,
        "sfr": s,
        "mtf50_cy_per_mm": mtf50,
        "mtf50_reached": bool(np.isfinite(mtf50)),
        "sfr_at_dpi": at,
        "nyquist_cy_per_mm": UM_PER_MM / pitch_of_dpi(dpi) / 2,
        "oversample": oversample,
    }


def square_edge_rois(image: np.ndarray) -> dict[str, tuple[int, int, int, int]]:
    """Regions (x0, y0, x1, y1) around the left and top edges of a dark, slightly tilted
    square on a light field (the ISO 12233 slanted-square target, ``chart edge``): "x"
    holds a near-vertical edge (SFR along x), "y" a near-horizontal one (SFR along y)."""
    img = np.asarray(image, dtype=np.float64)
    lo, hi = np.percentile(img, [2, 98])
    if hi - lo <= 0:
        raise ValueError("no edge found in the image (it is uniform)")
    dark = img < (lo + hi) / 2
    ys, xs = np.nonzero(dark)
    if ys.size < 64:
        raise ValueError("no dark square found in the image")
    y0, y1 = (int(v) for v in np.percentile(ys, [1, 99]))
    x0, x1 = (int(v) for v in np.percentile(xs, [1, 99]))
    h, w = y1 - y0, x1 - x0
    if min(h, w) < 16:
        raise ValueError("the dark square is too small for a slanted-edge measurement")
    m = int(0.12 * max(h, w)) + 6
    n_y, n_x = img.shape
    return {
        "x": (max(0, x0 - m), y0 + h // 4, min(n_x, x0 + m), y1 - h // 4),
        "y": (x0 + w // 4, max(0, y0 - m), x1 - w // 4, min(n_y, y0 + m)),
    }


def sfr_xy(
    image: np.ndarray, dpi: float, oversample: int = 4, at_dpi=(100.0, 200.0)
) -> dict[str, dict]:
    """SFR along x and along y from a slanted dark square (:func:`square_edge_rois`)."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 2 and img.size and np.isfinite(img).all():
        _check_grey_levels(img)  # before looking for the square in a two-level image
    out = {}
    for axis, (x0, y0, x1, y1) in square_edge_rois(image).items():
        out[axis] = sfr(
            np.asarray(image)[y0:y1, x0:x1],
            dpi,
            direction=axis,
            oversample=oversample,
            at_dpi=at_dpi,
        ) | {"roi": [x0, y0, x1, y1]}
    return out
