"""The stack operator of the wave engine's 2-D path (:mod:`.wave2d`): source amplitudes
to the in-band spectrum above the object-side mask, and its adjoint, on a grid of its
own (:func:`operator_grid`), in pruned transforms run in place in reused work arrays."""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sfft

from .arrays import CPU, Backend
from .wavebase import in_band

__all__ = ["StackOperator", "gather_bins", "in_band_runs", "operator_grid", "scatter_bins"]


@dataclass
class StackOperator:
    """What the operator A needs: grids, source fields, transfer functions, masks, on the
    backend ``bk`` (:mod:`.arrays`: NumPy or CuPy arrays).

    A maps source amplitudes (k, n0y, n0x) to the in-band spectrum of the field after
    the object-side mask, (k, nb) over the in-band bins (``gky`` x ``gkx``, row-major),
    scaled so that its squared norm is the field's in-band power over the operator
    grid's dx dy (Parseval). Every field between two masks is band-limited (its transfer
    function is 0 outside the band), so the transforms are pruned: a spectrum is only
    ever needed, or only ever non-zero, on the in-band rows and columns, and each FFT
    pair costs (1 + in-band fraction) / 2 of a full 2-D pair.

    The operator runs on its own grid (``gx``, ``gy``: :func:`operator_grid`), the
    sampling's grid (``x``, ``y``) coarsened over the same period to the fewest points
    that still hold the in-band result exactly; the in-band bins are the same
    frequencies on both (``gkx``/``gky`` and ``kx``/``ky`` index them), so a mode's
    in-band spectrum times ``scale`` is the same mode on the sampling's grid, where
    :meth:`field` puts it.

    The work arrays that the transforms run in place in (:meth:`_buf`, on the CPU) are
    kept per thread: an operator may be used from several threads at once."""

    x: np.ndarray
    y: np.ndarray
    ux: object  # (ngx, n0x) source fields at the first mask, x, on the operator grid
    uy: object  # (ngy, n0y) (both None where ``first`` is given: ``sx``, ``sy`` instead)
    first: object | None  # exact-over-paraxial factor below the first mask (in band)
    masks: list
    steps: list  # transfer to mask i from mask i - 1 (i >= 1), on the in-band bins
    ky: object  # in-band FFT bins of y and of x on the sampling's grid
    kx: object
    bk: Backend = CPU
    top: object | None = None  # amplitude filter above the top mask on the in-band bins
    dtype: object = np.complex128  # of the operator's fields (complex64: "single")
    gx: np.ndarray | None = None  # the operator's grids (None: the sampling's)
    gy: np.ndarray | None = None
    gkx: object = None  # in-band FFT bins on the operator's grids
    gky: object = None
    sx: object = None  # the sources' in-band spectra (nx_in, n0x), (ny_in, n0y), where
    sy: object = None  # ``first`` projects them (the operator grid's DFT scale)

    runs: dict = field(default_factory=dict, repr=False, compare=False)  # bins as 2 runs
    bufs: dict = field(default_factory=dict, repr=False, compare=False)  # per thread

    def __post_init__(self):
        if self.gx is None:
            self.gx, self.gy, self.gkx, self.gky = self.x, self.y, self.kx, self.ky

    def _run(self, name: str) -> tuple[int, int]:
        if name not in self.runs:
            grid = {"kx": self.x, "ky": self.y, "gkx": self.gx, "gky": self.gy}[name]
            self.runs[name] = in_band_runs(self.bk.host(getattr(self, name)), grid.size)
        return self.runs[name]

    @property
    def sources(self) -> tuple[int, int]:
        """The source points along y and x, (n0y, n0x)."""
        a, b = (self.uy, self.ux) if self.first is None else (self.sy, self.sx)
        return a.shape[1], b.shape[1]

    @property
    def scale(self) -> float:
        """Operator-grid in-band spectra -> the sampling grid's (the same field)."""
        cells = (self.x.size * self.y.size) / (self.gx.size * self.gy.size)
        return math.sqrt(cells)

    @property
    def cell(self) -> float:
        """The operator grid's dx dy (um^2)."""
        return float((self.gx[1] - self.gx[0]) * (self.gy[1] - self.gy[0]))

    def _buf(self, name: str, k: int, shape: tuple[int, int]):
        """A work array (k, *shape) of the operator's type, kept for the next batch of
        this thread: the transforms run in place in memory already mapped (a fresh array
        of tens of MB is page-faulted in anew each time); None where the backend takes
        whole blocks (a GPU: CuPy copies a view before transforming it, and its memory
        pool reuses memory anyway)."""
        if not self.bk.batch:
            return None
        mine = self.bufs.setdefault(threading.get_ident(), {})
        b = mine.get(name)
        if b is None or b.shape[0] < k or b.shape[1:] != shape:
            b = mine[name] = self.bk.xp.empty((k, *shape), dtype=self.dtype)
        return b if b.shape[0] == k else b[:k]

    def _spec(self, f, norm: str | None = None):
        """Fields (k, ngy, ngx) -> their spectra on the in-band bins (k, ny_in, nx_in);
        ``f`` is overwritten."""
        xp, bk = self.bk.xp, self.bk
        half = self._buf("half", f.shape[0], (self.gy.size, self.gkx.size))
        a = bk.fft(f, axis=-1, norm=norm, overwrite=True)
        a = gather_bins(xp, a, self._run("gkx"), -1, out=half)
        return gather_bins(xp, bk.fft(a, axis=-2, norm=norm, overwrite=True), self._run("gky"), -2)

    def _field(self, s, norm: str | None = None, fine: bool = False):
        """In-band spectra (k, ny_in, nx_in) -> the fields (k, ngy, ngx) on the operator
        grid, in a work array that the next call reuses (``fine``: (k, ny, nx) on the
        sampling's grid, of the same period, a new array)."""
        xp, bk = self.bk.xp, self.bk
        x, y, kx, ky = ("x", "y", "kx", "ky") if fine else ("gx", "gy", "gkx", "gky")
        nx, ny, k = getattr(self, x).size, getattr(self, y).size, s.shape[0]
        half = None if fine else self._buf("half", k, (ny, s.shape[-1]))
        a = scatter_bins(xp, s, self._run(ky), ny, -2, out=half)
        a = bk.ifft(a, axis=-2, norm=norm, overwrite=True)
        full = None if fine else self._buf("full", k, (ny, nx))
        a = scatter_bins(xp, a, self._run(kx), nx, -1, out=full)
        return bk.ifft(a, axis=-1, norm=norm, overwrite=True)

    def _batches(self, fn, a):
        """``fn`` on ``a`` in the backend's batches along the first axis, joined."""
        n = self.bk.batch or a.shape[0]
        if n >= a.shape[0]:
            return fn(a)
        parts = [fn(a[i : i + n]) for i in range(0, a.shape[0], n)]
        if isinstance(parts[0], tuple):
            return tuple(self.bk.xp.concatenate(p) for p in zip(*parts, strict=True))
        return self.bk.xp.concatenate(parts)

    def _top(self, w):
        """Source amplitudes w (k, n0y, n0x) -> the fields just below the top mask."""
        xp = self.bk.xp
        w = w.astype(self.dtype, copy=False)
        if self.first is not None:  # in the band: the sources' spectra, projected
            s = xp.einsum("ya,kab,xb->kyx", self.sy, w, self.sx, optimize=True)
            f = self._field(s * self.first)
        else:
            f = xp.einsum("ya,kab,xb->kyx", self.uy, w, self.ux, optimize=True)
        for m, h in zip(self.masks[:-1], self.steps, strict=True):
            f *= m
            f = self._field(self._spec(f) * h)
        return f

    def forward(self, w, *, with_power: bool = False):
        """Source amplitudes w (k, n0y, n0x) -> in-band spectra after the top mask;
        ``with_power``: also the power each field sends beyond the band there (k,), over
        dx dy: the power through the mask by the midpoint rule with its cells'
        transmission (sum |u|^2 M, as the separable path's budget counts it: |M|^2 = M
        for a sharp mask) less the in-band power."""
        return self._batches(lambda v: self._forward(v, with_power), w)

    def _forward(self, w, with_power: bool):
        f = self._top(w)
        through = None
        if with_power:
            a = abs(f)
            a *= a
            a *= self.masks[-1]
            through = a.sum(axis=(1, 2), dtype=np.float64)
        f *= self.masks[-1]
        out = self._spec(f, norm="ortho").reshape(f.shape[0], -1)
        out = out.astype(np.complex128)
        lost = through - (abs(out) ** 2).sum(axis=1) if with_power else None
        if self.top is not None:
            out = out * self.top
        return (out, lost) if with_power else out

    def adjoint(self, o):
        """In-band spectra (k, nb) -> source amplitudes (k, n0y, n0x)."""
        return self._batches(self._adjoint, o)

    def _adjoint(self, o):
        xp = self.bk.xp
        o = o if self.top is None else o * self.top.conj()
        o = o.astype(self.dtype, copy=False)
        g = self._field(o.reshape(o.shape[0], self.gky.size, self.gkx.size), norm="ortho")
        g *= self.masks[-1]
        for m, h in zip(self.masks[-2::-1], self.steps[::-1], strict=True):
            g = self._field(self._spec(g) * h.conj())
            g *= m
        if self.first is not None:  # the adjoint of _top's first step
            s = self._spec(g) * (self.first.conj() / (self.gx.size * self.gy.size))
            b = xp.einsum("ya,kyx,xb->kab", self.sy.conj(), s, self.sx.conj(), optimize=True)
        else:
            b = xp.einsum("ya,kyx,xb->kab", self.uy.conj(), g, self.ux.conj(), optimize=True)
        return b.astype(np.complex128)

    def field(self, o):
        """The band-limited field (ny, nx) on the sampling's grid of an in-band spectrum
        on that grid's scale (a mode of :func:`~.wave2d.coherent_modes` as it is)."""
        o = o.astype(np.complex128).reshape(1, self.ky.size, self.kx.size)
        return self._field(o, norm="ortho", fine=True)[0]


def in_band_runs(k, n: int) -> tuple[int, int]:
    """In-band FFT bins ``k`` (host) of an ``n``-point grid as their two runs: (p, q),
    k = 0..p-1 then n-q..n-1 (ValueError where they are not)."""
    k = np.asarray(k)
    off = np.flatnonzero(k != np.arange(k.size))
    p = int(off[0]) if off.size else k.size
    q = k.size - p
    if not np.array_equal(k, np.r_[np.arange(p), np.arange(n - q, n)]):
        raise ValueError("in-band bins: not the runs 0..p-1 and n-q..n-1")
    return p, q


def gather_bins(xp, a, runs: tuple[int, int], axis: int, out=None):
    """``a`` on the in-band bins along ``axis`` (their two ``runs``, copied; into
    ``out`` where given)."""
    p, q = runs
    if out is None:
        shape = list(a.shape)
        shape[axis] = p + q
        out = xp.empty(tuple(shape), dtype=a.dtype)
    av, ov = xp.moveaxis(a, axis, -1), xp.moveaxis(out, axis, -1)
    ov[..., :p] = av[..., :p]
    ov[..., p:] = av[..., av.shape[-1] - q :]
    return out


def scatter_bins(xp, s, runs: tuple[int, int], n: int, axis: int, out=None):
    """In-band values ``s`` (bins of ``runs`` along ``axis``) on all ``n`` bins, 0
    elsewhere (into ``out`` where given)."""
    p, q = runs
    shape = list(s.shape)
    shape[axis] = n
    a = xp.empty(tuple(shape), dtype=s.dtype) if out is None else out
    av, sv = xp.moveaxis(a, axis, -1), xp.moveaxis(s, axis, -1)
    av[..., :p] = sv[..., :p]
    av[..., p : n - q] = 0
    av[..., n - q :] = sv[..., p:]
    return a


def operator_grid(x: np.ndarray, wavelength_um: float, band: float) -> np.ndarray:
    """The fewest points over the period of the grid ``x`` on which the stack operator is
    exact (``x`` itself where it has no more).

    With m the largest in-band bin (|lambda f| < band) and M the largest bin of a
    mask's low-passed transmission (|lambda f| <= 2 band), a field times a mask has
    bins up to m + M, and only its in-band part is kept: it is free of aliases where
    n > 2m + M; the power through a mask, sum |u|^2 M, has bins up to 2m + M and is the
    integral where n > 2m + M; the mask itself needs n > 2M. The sampling's step
    lambda / (6 band) holds the whole product (n ~ 6m): this grid, n ~ 4m, holds what
    is kept, on about (4/6)^2 = 0.44 of the points (0.46 on the circular prototype's
    1650-point grid: 1120, the next FFT-friendly length)."""
    n, dx = x.size, float(x[1] - x[0])
    f = np.abs(sfft.fftfreq(n, dx)) * (n * dx)  # |bin|
    m = int(round(f[in_band(f / (n * dx), wavelength_um, band)].max()))
    # the mask's bins as mask_field_2d takes them, and one more where |lambda f| = 2 band
    # might round either way on another grid
    big = int(round(f[np.abs(wavelength_um * f / (n * dx)) <= 2 * band * (1 + 1e-9)].max()))
    need = sfft.next_fast_len(max(2 * m + big + 1, 2 * big + 1))
    if need >= n:
        return x
    return x[0] + np.arange(need) * (n * dx / need)
