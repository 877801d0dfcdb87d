"""2-D linear convolution of real arrays by FFT, on SciPy's FFT module alone.

``scipy.signal.fftconvolve`` computes the same, but importing ``scipy.signal`` (which
imports ``scipy.stats``) takes about 1.4 s on SciPy 1.17: over a third of a small
``opticalstamp scan``, and paid again by every process a report, a study or a fit spawns.
The convolution the scans need is a few lines of ``scipy.fft``: the same transforms on the
same lengths, so the same values to the last bit where no axis has length 1
(tests/test_convolve.py checks it against ``scipy.signal.fftconvolve``)."""

from __future__ import annotations

import numpy as np
from scipy import fft as sfft

__all__ = ["fft_convolve"]


def fft_convolve(a: np.ndarray, b: np.ndarray, mode: str = "full") -> np.ndarray:
    """The 2-D linear convolution of the real arrays ``a`` and ``b``, computed in float64:
    ``"full"`` (shape a + b - 1) or ``"same"`` (the full result's centre, ``a``'s shape,
    cut as ``scipy.signal.fftconvolve`` cuts it)."""
    if np.iscomplexobj(a) or np.iscomplexobj(b):
        raise TypeError("fft_convolve takes real arrays")
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2:
        raise ValueError("fft_convolve takes 2-D arrays")
    if mode not in ("full", "same"):
        raise ValueError(f"mode must be 'full' or 'same', not {mode!r}")
    if a.size == 0 or b.size == 0:
        raise ValueError("fft_convolve takes non-empty arrays")
    full = tuple(int(m + n - 1) for m, n in zip(a.shape, b.shape, strict=True))
    fast = tuple(sfft.next_fast_len(n, real=True) for n in full)
    spec = sfft.rfft2(a, fast) * sfft.rfft2(b, fast)
    out = sfft.irfft2(spec, fast)[: full[0], : full[1]]
    if mode == "full":
        return out.copy()
    start = [(f - n) // 2 for f, n in zip(full, a.shape, strict=True)]
    return out[start[0] : start[0] + a.shape[0], start[1] : start[1] + a.shape[1]].copy()
