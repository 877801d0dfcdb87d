"""Monte Carlo tallies: running sums in ray order, estimates with standard errors.

Every sum is accumulated ray by ray in launch order (``np.add.at`` is unbuffered and
sequential), so a tally is bit-identical whatever the chunk size or thread count that
produced the rays. An estimate of an integral is sum(w) / n_samples; its standard
error is sqrt((sum(w^2)/n - mean^2) / n).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .trace import RayBatch


@dataclass(frozen=True)
class Estimate:
    """A Monte Carlo estimate and its standard error."""

    value: float
    se: float

    @property
    def rse(self) -> float:
        return self.se / self.value if self.value else float("inf")


def estimate(s1: float, s2: float, n: int) -> Estimate:
    if n <= 0:
        return Estimate(0.0, float("inf"))
    mean = s1 / n
    var = max(s2 / n - mean * mean, 0.0)
    return Estimate(mean, float(np.sqrt(var / n)))


def ratio_estimate(a: Estimate, b: Estimate, n: int) -> Estimate:
    """a / (a + b) for estimates of two mutually exclusive tallies over the same samples."""
    tot = a.value + b.value
    if tot <= 0:
        return Estimate(0.0, 0.0)
    f = b.value / tot
    cov = -a.value * b.value / n  # exclusive tallies: E[w_a w_b] = 0
    var = (a.value**2 * b.se**2 + b.value**2 * a.se**2 - 2 * a.value * b.value * cov) / tot**4
    return Estimate(f, float(np.sqrt(max(var, 0.0))))


PATH_BITS = 14
_DK_OFFSET = 1 << (PATH_BITS - 2)


def path_codes(batch: RayBatch, row: int, k: int) -> np.ndarray:
    """Integer code of each ray's hole sequence relative to pixel (row, k).

    Per mask: hole index offset dk = k_hole - k and whether the hole is in the other row.
    Up to four masks with |dk| < 2048 (codes are unique); own path has code
    :func:`own_code`.
    """
    dk = batch.hole_k.astype(np.int64) - k
    other = (batch.hole_row != row).astype(np.int64)
    if batch.hole_k.shape[1] > 4 or np.any(np.abs(dk) >= _DK_OFFSET):
        raise ValueError("path coding supports up to 4 masks and |dk| < 2048")
    per = (dk + _DK_OFFSET) * 2 + other
    shifts = np.arange(per.shape[1], dtype=np.int64) * PATH_BITS
    return (per << shifts).sum(axis=1)


def own_code(n_masks: int) -> int:
    return int(sum((_DK_OFFSET * 2) << (PATH_BITS * m) for m in range(n_masks)))


def decode_path(code: int, n_masks: int) -> list[tuple[int, int]]:
    """[(other_row, dk), ...] per mask (from the sensor upward) for a path code."""
    out = []
    for m in range(n_masks):
        per = (code >> (PATH_BITS * m)) & ((1 << PATH_BITS) - 1)
        out.append((per & 1, (per >> 1) - _DK_OFFSET))
    return out


class KeyedSums:
    """Running per-key sums of w, w^2, counts, min/max of a ray attribute (ray order)."""

    def __init__(self) -> None:
        self.keys: dict[int, int] = {}
        self.s1 = np.zeros(0)
        self.s2 = np.zeros(0)
        self.count = np.zeros(0, np.int64)
        self.lo = np.zeros(0)
        self.hi = np.zeros(0)

    def add(self, keys: np.ndarray, w: np.ndarray, attr: np.ndarray) -> np.ndarray:
        """Add rays; returns each ray's slot index."""
        uniq, inv = np.unique(keys, return_inverse=True)
        slots = np.empty(uniq.size, np.int64)
        for i, key in enumerate(uniq.tolist()):
            if key not in self.keys:
                self.keys[key] = len(self.keys)
            slots[i] = self.keys[key]
        grow = len(self.keys) - self.s1.size
        if grow > 0:
            self.s1 = np.concatenate([self.s1, np.zeros(grow)])
            self.s2 = np.concatenate([self.s2, np.zeros(grow)])
            self.count = np.concatenate([self.count, np.zeros(grow, np.int64)])
            self.lo = np.concatenate([self.lo, np.full(grow, np.inf)])
            self.hi = np.concatenate([self.hi, np.full(grow, -np.inf)])
        idx = slots[inv]
        np.add.at(self.s1, idx, w)
        np.add.at(self.s2, idx, w * w)
        np.add.at(self.count, idx, 1)
        np.minimum.at(self.lo, idx, attr)
        np.maximum.at(self.hi, idx, attr)
        return idx

    def get(self, key: int) -> int | None:
        return self.keys.get(key)


def object_plane(batch: RayBatch, z_um: float, n_obj: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Where reverse-traced rays meet the object plane ``z_um`` above the reference plane."""
    c = np.sqrt(n_obj**2 - batch.sx**2 - batch.sy**2)
    return batch.x + z_um * batch.sx / c, batch.y + z_um * batch.sy / c
