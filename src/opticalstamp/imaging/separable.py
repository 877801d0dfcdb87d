"""Separable weighted sums of an image at arbitrary sample positions (compiled passes).

A 1-D *tap table* (start index i0 (n,), weights w (n, taps)) says that sample s is
sum_t w[s, t] img[i0[s] + t]; indices outside the image count as zero (the caller adds
what lies outside). :func:`y_pass` applies a table along rows, :func:`x_pass` along
columns; both run in parallel over output rows with contiguous inner loops.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(parallel=True, cache=True)
def _y_pass(img, i0, w, out):  # pragma: no cover
    n_rows, n_cols = img.shape
    for s in numba.prange(i0.size):
        for t in range(w.shape[1]):
            i = i0[s] + t
            wt = w[s, t]
            if i < 0 or i >= n_rows or wt == 0.0:
                continue
            for c in range(n_cols):
                out[s, c] += wt * img[i, c]


@numba.njit(parallel=True, cache=True)
def _x_pass(img, c0, w, out):  # pragma: no cover
    n_rows, n_cols = img.shape
    for r in numba.prange(n_rows):
        for s in range(c0.size):
            acc = 0.0
            for t in range(w.shape[1]):
                c = c0[s] + t
                if 0 <= c < n_cols:
                    acc += w[s, t] * img[r, c]
            out[r, s] = acc


def y_pass(img: np.ndarray, i0: np.ndarray, w: np.ndarray) -> np.ndarray:
    """[sample, col] = sum_t w[sample, t] img[i0[sample] + t, col] (float32 out)."""
    out = np.zeros((i0.size, img.shape[1]), np.float32)
    _y_pass(img, i0.astype(np.int64), w.astype(np.float32), out)
    return out


def x_pass(img: np.ndarray, c0: np.ndarray, w: np.ndarray) -> np.ndarray:
    """[row, sample] = sum_t w[sample, t] img[row, c0[sample] + t] (float64 out)."""
    out = np.zeros((img.shape[0], c0.size), np.float64)
    _x_pass(np.ascontiguousarray(img), c0.astype(np.int64), w.astype(np.float64), out)
    return out


def inside(i0: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    """Sum of each sample's weights that fall on the image (indices 0 ... n - 1)."""
    idx = i0[:, None] + np.arange(w.shape[1])[None, :]
    return np.where((idx >= 0) & (idx < n), w, 0.0).sum(axis=1)


def box_taps(centers_um: np.ndarray, width_um: float, pixel_um: float):
    """Tap table averaging pixels of ``pixel_um`` over [c - width/2, c + width/2]."""
    c = np.asarray(centers_um, dtype=np.float64)
    i0 = np.floor((c - width_um / 2) / pixel_um).astype(np.int64)
    n_t = int(np.ceil(width_um / pixel_um)) + 2
    idx = i0[:, None] + np.arange(n_t)[None, :]
    lo = np.maximum(idx * pixel_um, (c - width_um / 2)[:, None])
    hi = np.minimum((idx + 1) * pixel_um, (c + width_um / 2)[:, None])
    return i0, np.clip(hi - lo, 0, None) / width_um
