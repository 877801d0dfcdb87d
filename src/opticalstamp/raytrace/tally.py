"""Monte Carlo tallies: running sums in ray order, estimates with standard errors.

Every sum is accumulated ray by ray in launch order (``np.add.at`` is unbuffered and
sequential), so a tally is bit-identical whatever the chunk size or thread count that
produced the rays. An estimate of an integral is sum(w) / n_samples; its standard
error is sqrt((sum(w^2)/n - mean^2) / n).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .launch import RayBatch


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


#: Id of the own path in every :class:`PathRegistry` (registered first).
OWN_PATH = 0


def is_own_path(batch: RayBatch, row: int, k: int) -> np.ndarray:
    """Whether each ray passed the own holes (row, k) of pixel (row, k) in every mask.

    Parameters
    ----------
    batch : RayBatch, rays with ``hole_row``, ``hole_k`` of shape (n, n_masks)
    row, k : the pixel's row (0 = A, 1 = B) and index

    Returns
    -------
    (n,) bool
    """
    return np.all((batch.hole_row == row) & (batch.hole_k == k), axis=1)


def _lex_key(cols: np.ndarray) -> np.ndarray:
    """Int64 keys of the rows of ``cols`` (n, m), ordered lexicographically, last column
    most significant: equal rows share a key. Mixed-radix over each column's range in
    this array; where the radices would overflow, the key so far is replaced by its rank.
    """
    key = np.zeros(cols.shape[0], np.int64)
    span = 1
    for m in range(cols.shape[1] - 1, -1, -1):
        v = cols[:, m]
        lo = int(v.min())
        r = int(v.max()) - lo + 1
        if span * r >= 1 << 62:
            key = np.unique(key, return_inverse=True)[1].reshape(-1).astype(np.int64)
            span = int(key.max()) + 1
        key = key * r + (v - lo)
        span *= r
    return key


class PathRegistry:
    """Compact int64 ids of hole sequences relative to pixel (row, k), any number of masks.

    A ray's hole sequence is, per mask from the sensor upward, ``(other_row, dk)``:
    whether its hole is in the other row of the lattice and its index offset
    dk = k_hole - k. The own path, ``((0, 0), ...)``, is registered first and has id
    :data:`OWN_PATH`; other sequences get ids 1, 2, ... in the order they are first met
    (within one batch, in lexicographic order of (dk, other_row) from the top mask down).
    Keep one registry per analysis so that ids are comparable across batches.

    Parameters
    ----------
    n_masks : int, masks of the path
    row, k : the pixel's row (0 = A, 1 = B) and index
    """

    def __init__(self, n_masks: int, row: int, k: int) -> None:
        self.n_masks = int(n_masks)
        self.row = int(row)
        self.k = int(k)
        self.sequences: list[tuple[tuple[int, int], ...]] = []
        self._ids: dict[tuple[tuple[int, int], ...], int] = {}
        self.id_of(((0, 0),) * self.n_masks)

    def __len__(self) -> int:
        return len(self.sequences)

    def id_of(self, seq: tuple[tuple[int, int], ...]) -> int:
        """The id of hole sequence ``seq`` (((other_row, dk), ...) per mask), registered
        where new."""
        i = self._ids.get(seq)
        if i is None:
            i = self._ids[seq] = len(self.sequences)
            self.sequences.append(seq)
        return i

    def ids(self, batch: RayBatch) -> np.ndarray:
        """Id of each ray's hole sequence, registering new sequences.

        Parameters
        ----------
        batch : RayBatch, rays with ``hole_row``, ``hole_k`` of shape (n, n_masks)

        Returns
        -------
        (n,) int64
        """
        if batch.hole_k.shape[1] != self.n_masks:
            raise ValueError(
                f"registry for {self.n_masks} masks, rays cross {batch.hole_k.shape[1]}"
            )
        if batch.hole_k.shape[0] == 0:
            return np.zeros(0, np.int64)
        dk = batch.hole_k.astype(np.int64) - self.k
        other = (batch.hole_row != self.row).astype(np.int64)
        key = _lex_key(2 * dk + other)
        _, first, inv = np.unique(key, return_index=True, return_inverse=True)
        lut = np.array(
            [
                self.id_of(tuple(zip(o, d, strict=True)))
                for o, d in zip(other[first].tolist(), dk[first].tolist(), strict=True)
            ],
            dtype=np.int64,
        )
        return lut[inv.reshape(-1)]

    def decode(self, path_id: int) -> list[tuple[int, int]]:
        """[(other_row, dk), ...] per mask (from the sensor upward) of a path id."""
        return list(self.sequences[path_id])


class KeyedSums:
    """Running per-key sums of w, w^2, counts, min/max of a ray attribute (ray order)."""

    def __init__(self) -> None:
        self.keys: dict[int, int] = {}
        self.s1 = np.zeros(0)
        self.s2 = np.zeros(0)
        self.count = np.zeros(0, np.int64)
        self.lo = np.zeros(0)
        self.hi = np.zeros(0)

    def _slots(self, uniq: np.ndarray) -> np.ndarray:
        """The slot of each key (new keys get new slots, the arrays grow)."""
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
        return slots

    def add(self, keys: np.ndarray, w: np.ndarray, attr: np.ndarray) -> np.ndarray:
        """Add rays; returns each ray's slot index."""
        uniq, inv = np.unique(keys, return_inverse=True)
        idx = self._slots(uniq)[inv]
        np.add.at(self.s1, idx, w)
        np.add.at(self.s2, idx, w * w)
        np.add.at(self.count, idx, 1)
        np.minimum.at(self.lo, idx, attr)
        np.maximum.at(self.hi, idx, attr)
        return idx

    def merge(self, keys, s1, s2, count, lo, hi) -> np.ndarray:
        """Add sums taken elsewhere (a GPU's), one row per distinct key; returns the
        keys' slots."""
        slots = self._slots(np.asarray(keys, np.int64))
        self.s1[slots] += s1
        self.s2[slots] += s2
        self.count[slots] += count
        self.lo[slots] = np.minimum(self.lo[slots], lo)
        self.hi[slots] = np.maximum(self.hi[slots], hi)
        return slots

    def get(self, key: int) -> int | None:
        return self.keys.get(key)


def object_plane(batch: RayBatch, z_um: float, n_obj: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Where reverse-traced rays meet the object plane ``z_um`` above the reference plane."""
    c = np.sqrt(n_obj**2 - batch.sx**2 - batch.sy**2)
    return batch.x + z_um * batch.sx / c, batch.y + z_um * batch.sy / c
