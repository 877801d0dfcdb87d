"""The wave engine's object side: from the object-side mask to the object planes.

The separable path (:mod:`.wave`) hands over the in-band terms leaving the stack: per
axis a short list of fields u_j (one per sequence of rows through the masks), each with
m coherent modes. Everything above the stack is free space (reference gap and object
medium, one reduced distance d), so each term is carried by its in-band spectrum and the
paraxial transfer function exp(-i pi lambda d f^2); the responsivity at a height is
R(X, Y) = sum_jl X_jl(X) Y_jl(Y), X_jl = sum_m u_jm conj(u_lm) (module docstring of
:mod:`.wave` for the normalisation). This module evaluates, at every Z, what the
analyses need, with three exact shortcuts:

* **Z-independent sums.** The integrated terms G_jl = integral u_j conj(u_l) do not
  depend on Z (the transfer function is unitary on the band, Parseval), so the light and
  the weights T = G of the other axis are computed once from the spectra, and so is the
  eigen-decomposition T = V diag(p) V^H that turns the line-spread function
  LSF_x = sum_jl T_jl X_jl into sum_k p_k sum_m |w_km|^2 with w_k = sum_j V_jk u_j: the
  rotation acts on the spectra once, not on the fields at every Z.
* **A grid at the intensity's rate.** The fields have band B, their products 2B: the
  intensities are exactly represented on a grid of N' >= 4 k_max + 2 points over the
  same period (k_max the highest in-band frequency index), about 2/3 of the fine grid's
  (whose step lambda / (6B) is set by the masks inside the stack). The line-spread
  functions are computed there and carried to the fine grid by exact band-limited
  (Fourier) interpolation; the central-cell integrals use the exact band-limited weights
  of the coarse grid.
* **Coherent modes of one axis (x-only path).** What a chart varying along x needs is
  LSF_x alone: an incoherent sum of the fields sqrt(p_k) w_km. Their mutual intensity
  is Z-independent in the spectral domain (the propagator is diagonal and unitary), so
  it is compressed once to its coherent modes holding all but ``mode_tol`` of the power
  (the L1 error of the LSF is at most that fraction of the light), and only those are
  propagated to each Z.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft
from scipy.linalg import blas, solve_triangular

from .arrays import fft_workers, gram_rows
from .wavebase import Plane, WaveSampling, in_band, object_grid

__all__ = [
    "ObjectSide",
    "axis_modes",
    "lsf_from",
    "lsf_x_at",
    "lsf_x_from",
    "marginals_at",
    "object_side",
    "responses_at",
    "x_modes",
]


@dataclass(frozen=True)
class ObjectSide:
    """The in-band terms leaving the stack, as spectra on the object grids.

    Attributes
    ----------
    grids : per axis the fine object grid (n,) (um, from the pixel's axis)
    spectra : per axis the in-band spectra (J, m, nb) of the J terms' m modes
    bins : per axis the signed frequency indices (nb,) of the in-band bins on the n-point
        grid (f = k / (n step))
    planes : per axis the stack's :class:`~.wavebase.Plane`
    sampling : the :class:`~.wavebase.WaveSampling`
    """

    grids: tuple[np.ndarray, np.ndarray]
    spectra: tuple[np.ndarray, np.ndarray]
    bins: tuple[np.ndarray, np.ndarray]
    planes: tuple[Plane, Plane]
    sampling: WaveSampling

    def transfer(self, a: int, z_mm: float) -> np.ndarray:
        """The paraxial transfer function of axis ``a`` to the object plane z_mm on the
        in-band bins: (nb,)."""
        smp, g, pl = self.sampling, self.grids[a], self.planes[a]
        d = pl.reduced(z_mm) - pl.heights[-1]
        f = self.bins[a] / (g.size * smp.step_um)
        return np.exp(-1j * np.pi * smp.wavelength_um * d * f * f)

    def fields(self, z_mm: float) -> list[np.ndarray]:
        """The terms' fields u_j on the object plane z_mm, per axis (J, n, m), on the fine
        grids."""
        out = []
        for a, (g, spec, k) in enumerate(zip(self.grids, self.spectra, self.bins, strict=True)):
            full = np.zeros(spec.shape[:2] + (g.size,), dtype=np.complex128)
            full[..., k % g.size] = spec * self.transfer(a, z_mm)
            out.append(sfft.ifft(full, axis=-1, workers=fft_workers()).transpose(0, 2, 1))
        return out

    def terms(self, z_mm: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per axis (x, X) with X_jl(x) (J, J, n) where the light is (:func:`_crop`)."""
        return [_crop(g, u) for g, u in zip(self.grids, self.fields(z_mm), strict=True)]

    def gram(self, a: int) -> np.ndarray:
        """G_jl = integral sum_m u_jm conj(u_lm) dx of axis ``a`` (J, J), at every Z (each
        axis's computed once: read-only)."""
        return self._grams[a]

    @functools.cached_property
    def _grams(self) -> tuple[np.ndarray, np.ndarray]:
        out = []
        for s, g in zip(self.spectra, self.grids, strict=True):
            gr = _gram_rows(s.reshape(s.shape[0], -1)) * (self.sampling.step_um / g.size)
            gr.flags.writeable = False
            out.append(gr)
        return tuple(out)

    def coarse(self, a: int) -> tuple[np.ndarray, int]:
        """The grid of axis ``a`` at the intensity's rate: (x (N',), N'), the same period
        as the fine grid, N' >= 4 k_max + 2 (or the fine grid where that is not fewer)."""
        g = self.grids[a]
        kmax = int(np.abs(self.bins[a]).max()) if self.bins[a].size else 0
        nc = sfft.next_fast_len(4 * kmax + 2)
        if nc >= g.size:
            return g, g.size
        return g[0] + np.arange(nc) * (g.size * self.sampling.step_um / nc), nc

    def on_coarse(
        self, a: int, spec: np.ndarray, z_mm: float, nc: int, buf: np.ndarray | None = None
    ) -> np.ndarray:
        """Spectra ``spec`` (..., nb) of axis ``a`` propagated to z_mm, as fields on the
        N'-point coarse grid (..., N'). ``buf``: a zeroed (..., N') array to reuse
        (only the in-band bins are written)."""
        n = self.grids[a].size
        full = np.zeros(spec.shape[:-1] + (nc,), dtype=np.complex128) if buf is None else buf
        full[..., self.bins[a] % nc] = spec * (self.transfer(a, z_mm) * (nc / n))
        return sfft.ifft(full, axis=-1, workers=fft_workers())


def object_side(
    keys: list, terms: dict, planes: tuple[Plane, Plane], x_stack: list, smp: WaveSampling, z_max
) -> ObjectSide:
    """The in-band spectra of the terms ``terms[key] = (ux (n_s, m_x), uy (n_s, m_y))`` on
    the stack grids ``x_stack``, on object grids wide enough for the band's reach up to
    ``z_max`` (mm)."""
    grids, spectra, bins = [], [], []
    for a, (pl, xs) in enumerate(zip(planes, x_stack, strict=True)):
        d_max = pl.reduced(float(z_max)) - pl.heights[-1]
        xf, off = object_grid(xs, d_max, smp)
        n = xf.size
        u = np.stack([terms[k][a].T for k in keys])  # (J, m, n_s)
        f = sfft.fftfreq(n, smp.step_um)
        k_in = np.flatnonzero(in_band(f, smp.wavelength_um, smp.band))
        # the fields zero-padded to n points by the transform itself, placed at ``off``
        # by the shift's phase on the in-band bins
        spec = sfft.fft(u, n=n, axis=-1, workers=fft_workers())[..., k_in]
        spec *= np.exp(-2j * np.pi * (k_in * off % n) / n)
        grids.append(xf)
        spectra.append(spec)
        bins.append(np.where(k_in > n // 2, k_in - n, k_in))
    return ObjectSide(tuple(grids), tuple(spectra), tuple(bins), planes, smp)


def _to_fine(lsf_c: np.ndarray, n: int) -> np.ndarray:
    """Real band-limited periodic samples on N' points carried to n points over the same
    period (exact Fourier interpolation; the band is below both grids' Nyquist rates)."""
    nc = lsf_c.size
    if nc == n:
        return lsf_c
    c = sfft.rfft(lsf_c, workers=fft_workers())
    out = np.zeros(n // 2 + 1, dtype=np.complex128)
    out[: c.size] = c
    if nc % 2 == 0:
        out[nc // 2] = 0.0  # the intensities' band ends below the coarse Nyquist bin
    return sfft.irfft(out, n=n, workers=fft_workers()) * (n / nc)


def _rotation(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """T = V diag(p) V^H (T Hermitian positive semi-definite): (p clipped at 0, V)."""
    p, v = np.linalg.eigh(t)
    return np.clip(p, 0.0, None), v


def responses_at(side: ObjectSide, zs: np.ndarray, cell: float):
    """At each Z: the line-spread functions of x and y on the fine grids (um sr per um),
    the light (um^2 sr, the same at every Z) and the share within the central cell.

    Returns (lsf_x (nz, nx), lsf_y (nz, ny), etendue (nz,), cells (nz,))."""
    g = [side.gram(0), side.gram(1)]
    e = float(np.sum(g[0] * g[1]).real)
    rot = [_rotation(g[1]), _rotation(g[0])]  # axis a is weighted by the other's Gram
    # w_k = sum_j V_jk u_j, on the spectra once
    ws = [np.tensordot(rot[a][1], side.spectra[a], axes=([0], [0])) for a in (0, 1)]
    coarse = [side.coarse(a) for a in (0, 1)]
    win = [cell_weights(x, cell) for x, _ in coarse]
    lsf = [np.zeros((zs.size, gr.size)) for gr in side.grids]
    cells = np.zeros(zs.size)
    for iz, z in enumerate(zs):
        inc = []
        for a in (0, 1):
            x, nc = coarse[a]
            w = side.on_coarse(a, ws[a], float(z), nc)  # (J, m, N')
            p = rot[a][0]
            inten = np.square(w.real) + np.square(w.imag)  # (J, m, N')
            lsf[a][iz] = _to_fine(
                np.tensordot(p, inten.sum(axis=1), axes=(0, 0)), side.grids[a].size
            )
            c = _gram_rows(w.reshape(w.shape[0], -1), np.tile(win[a], w.shape[1]))
            v = rot[a][1]
            inc.append(v.conj() @ c @ v.T)  # back from the rotated terms: C = conj(V) C_w V^T
        cells[iz] = float(np.sum(inc[0] * inc[1]).real) / e if e > 0 else 0.0
    return lsf[0], lsf[1], np.full(zs.size, e), cells


def lsf_x_at(side: ObjectSide, zs: np.ndarray) -> tuple[np.ndarray, float, int]:
    """The x line-spread functions alone at each Z (nz, nx) on the fine grid, the light
    (um^2 sr) and the number of coherent modes propagated (the x-only path: coherent
    modes of LSF_x's mutual intensity, all but ``mode_tol`` of the power)."""
    modes, light = x_modes(side)
    return lsf_x_from(side, modes, zs), light, modes.shape[0]


def x_modes(side: ObjectSide) -> tuple[np.ndarray, float]:
    """The coherent modes of LSF_x's mutual intensity as in-band spectra (q, nb), all but
    ``mode_tol`` of the power, and the light (um^2 sr): the Z-independent part of the
    x-only path (:func:`lsf_x_from` propagates them), by the pivoted Cholesky
    (:func:`_modes`), as the RMTF path has taken them since it was written."""
    rows, light = _axis_rows(side, 0)
    return _modes(rows, side.sampling.mode_tol), light


def _axis_rows(side: ObjectSide, a: int) -> tuple[np.ndarray, float]:
    """Rows (J m, nb) whose mutual intensity is axis ``a``'s line-spread function's,
    LSF_a = sum_jl T_jl sum_m u_jm conj(u_lm) with T the other axis's Gram (Z-independent),
    rotated to T's eigenvectors (T = V diag(p) V^H, rows sqrt(p_k) w_km with w_k = sum_j
    V_jk u_j), and the light (um^2 sr)."""
    g_other = side.gram(1 - a)
    light = float(np.sum(side.gram(a) * g_other).real)
    p, v = _rotation(g_other)
    w = np.tensordot(v, side.spectra[a], axes=([0], [0]))  # (J, m, nb)
    return (w * np.sqrt(p)[:, None, None]).reshape(-1, w.shape[-1]), light


#: What :func:`marginals_at` leaves out of each axis's mutual intensity (a fraction of the
#: light, to eigh's rounding, about the rows' count x eps): a model of scans is
#: differentiated by forward differences of 1e-3 assembly scales (the fit), and a mode that
#: comes and goes as the design moves shifts the model by at most this (the prototype: 101
#: and 42 modes of 248 and 176 fields; at 1e-10 69 and 32, and the benchmark's fit took
#: yet another path along its valley: docs/fit.md).
MARGINAL_TOL = 1e-14


def axis_modes(side: ObjectSide, a: int, tol: float | None = None) -> tuple[np.ndarray, float]:
    """The coherent modes of axis ``a``'s line-spread function's mutual intensity as
    in-band spectra (q, nb) (:func:`_axis_rows`), compressed to all but ``tol`` (default
    the sampling's ``mode_tol``) of the power (:func:`_eig_modes`), and the light
    (um^2 sr)."""
    rows, light = _axis_rows(side, a)
    return _eig_modes(rows, side.sampling.mode_tol if tol is None else tol), light


def marginals_at(side: ObjectSide, zs: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Both line-spread functions at each Z, (nz, nx) and (nz, ny) on the fine grids, and
    the light (um^2 sr): each axis by its own coherent modes (:func:`axis_modes`), without
    the central-cell shares. :func:`responses_at`'s marginals to ``MARGINAL_TOL`` of the
    light in L1, with a fraction of its transforms."""
    mx, light = axis_modes(side, 0, MARGINAL_TOL)
    my, _ = axis_modes(side, 1, MARGINAL_TOL)
    return lsf_from(side, 0, mx, zs), lsf_from(side, 1, my, zs), light


#: Bytes of the complex fields one batch of heights holds in :func:`lsf_x_from` on a
#: backend (heights x modes x coarse grid).
BATCH_BYTES = 1 << 28


def lsf_x_from(side: ObjectSide, modes: np.ndarray, zs: np.ndarray, bk=None) -> np.ndarray:
    """LSF_x (nz, nx) on the fine grid at each Z from the modes of :func:`x_modes`.

    ``bk``: None, one height at a time on the host (NumPy); a
    :class:`~.arrays.Backend` (the 2-D path's, a GPU's), the heights in batches of at
    most :data:`BATCH_BYTES` of fields on it, one transform per batch: the same sums,
    equal to rounding (tests/test_wave_circle.py)."""
    if bk is not None:
        return _lsf_x_batched(side, modes, zs, side.coarse(0)[1], bk)
    return lsf_from(side, 0, modes, zs)


def lsf_from(side: ObjectSide, a: int, modes: np.ndarray, zs: np.ndarray) -> np.ndarray:
    """Axis ``a``'s line-spread function (nz, n) on its fine grid at each Z from its
    coherent modes (:func:`axis_modes`), one height at a time on the host."""
    x, nc = side.coarse(a)
    n = side.grids[a].size
    out = np.zeros((zs.size, n))
    buf = np.zeros((modes.shape[0], nc), dtype=np.complex128)
    for iz, z in enumerate(zs):
        f = side.on_coarse(a, modes, float(z), nc, buf).view(np.float64)  # (q, 2 N')
        out[iz] = _to_fine(np.einsum("ij,ij->j", f, f).reshape(nc, 2).sum(axis=1), n)
    return out


def _lsf_x_batched(side: ObjectSide, modes: np.ndarray, zs: np.ndarray, nc: int, bk):
    """:func:`lsf_x_from` on the backend ``bk``, batches of heights at once."""
    xp, n = bk.xp, side.grids[0].size
    q = modes.shape[0]
    m, idx = bk.put(modes), bk.put(side.bins[0] % nc)
    tr = np.stack([side.transfer(0, float(z)) for z in zs]) * (nc / n)  # (nz, nb)
    per = max(1, BATCH_BYTES // (16 * q * nc))
    lsf_c = np.empty((zs.size, nc))
    for i in range(0, zs.size, per):
        t = bk.put(tr[i : i + per])
        full = xp.zeros((t.shape[0], q, nc), dtype=np.complex128)
        full[..., idx] = m[None, :, :] * t[:, None, :]
        f = bk.ifft(full, axis=-1)
        lsf_c[i : i + per] = bk.host((f.real * f.real + f.imag * f.imag).sum(axis=1))
    return np.stack([_to_fine(c, n) for c in lsf_c]).reshape(zs.size, n)


def _modes(a: np.ndarray, tol: float) -> np.ndarray:
    """Coherent modes (q, nb) with sum_k |modes_k . phi|^2 = sum_r |a_r . phi|^2 for every
    phi, to all but ``tol`` of the power sum |a|^2: a pivoted Cholesky factorisation of
    the rows' Gram G = a a^H stops when the rows left out of the pivots' span hold less
    than ``tol`` of the trace (the Nystrom approximation a ~ C a_P, C = L L_PP^-1, is a
    projection of the rows onto that span), then the eigenvectors of C^H C (q x q) mix
    the pivot rows into orthogonal modes. Only small dense problems: no eigensolver of
    the full Gram, whose threaded LAPACK call stalls on a loaded machine."""
    g = _gram_rows(a)
    r = g.shape[0]
    d = np.clip(g.diagonal().real.copy(), 0.0, None)
    total = d.sum()
    low = np.zeros((r, r), dtype=np.complex128)
    piv: list[int] = []
    while len(piv) < r and d.sum() > tol * total:
        i, k = int(np.argmax(d)), len(piv)
        col = (g[:, i] - (low[:, :k] * low[i, :k].conj()).sum(axis=1)) / np.sqrt(d[i])
        low[:, k] = col
        d = np.clip(d - np.abs(col) ** 2, 0.0, None)
        d[i] = 0.0
        piv.append(i)
    if not piv:
        return np.zeros((1, a.shape[1]), dtype=np.complex128)
    low = low[:, : len(piv)]
    c = solve_triangular(low[piv], low.T, trans="T", lower=True).T  # (r, q): c low_PP = low
    sig, v = np.linalg.eigh(c.conj().T @ c)
    sig = np.clip(sig, 0.0, None)
    return (np.sqrt(sig)[:, None] * v.conj().T) @ a[piv]


def _eig_modes(a: np.ndarray, tol: float) -> np.ndarray:
    """The leading coherent modes (q, nb) of the mutual intensity sum_r a_r a_r^H, the
    fewest whose left-out eigenvalues sum to at most ``tol`` of its trace: from the
    eigen-decomposition of the rows' Gram a a^H = U diag(s) U^H, modes U_k^H a (power
    s_k). What is left out is a positive semi-definite part, so a line-spread function
    from the modes lies below the exact one everywhere, by ``tol`` of the light in L1 at
    most, plus the eigenvalues' rounding (about the rows' count x eps of the trace; the
    pivoted Cholesky of :func:`_modes` projects the rows instead, whose cross terms with
    the left-out part move the LSF by ~sqrt(``tol``) pointwise: the RMTF path's, at its
    ``mode_tol``)."""
    s, u = np.linalg.eigh(_gram_rows(a))
    s = np.clip(s, 0.0, None)
    left = np.cumsum(s)  # ascending: left[k] = the sum of the k + 1 smallest
    q = s.size - int(np.searchsorted(left, tol * left[-1], side="right"))
    q = max(q, 1)
    return u[:, s.size - q :].conj().T @ a


def _gram_rows(a: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
    """G[j, l] = sum_n a[j, n] conj(a[l, n]) (times weight[n]) for a (J, n), in one BLAS
    call: unweighted by ``zherk`` (half the products; G Hermitian to the last bit)."""
    if weight is None:
        return gram_rows(a)
    return blas.zgemm(1.0, a.T, (a * weight[None, :]).T, trans_a=2).T  # (a^T)^H (w a)^T, transposed


def cell_weights(x: np.ndarray, cell: float) -> np.ndarray:
    """Weights w with sum_n g_n w_n = the integral of g over |x| <= cell / 2, exact for
    band-limited periodic samples g (:func:`~.wavebase.band_integral` as a vector: the
    intensities' band is below the grid's Nyquist rate; real, as the Nyquist bin of such
    g is 0)."""
    n = x.size
    nu = sfft.fftfreq(n, x[1] - x[0])
    a, b = -cell / 2 - x[0], cell / 2 - x[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        k = (np.exp(2j * np.pi * nu * b) - np.exp(2j * np.pi * nu * a)) / (2j * np.pi * nu)
    k = np.where(nu == 0, b - a, k)
    return (sfft.fft(k, workers=fft_workers()) / n).real  # sum_k ghat_k K_k = sum_n g_n w_n


def _crop(x: np.ndarray, u: np.ndarray, tail: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """(x, X) with X_jl(x) = sum_m u_j conj(u_l) on the part of x where the diagonal terms
    hold all but ``tail`` of their sum (the cross terms are bounded by them:
    |X_jl|^2 <= X_jj X_ll)."""
    env = (u.real**2 + u.imag**2).sum(axis=(0, 2))
    c = np.cumsum(env)
    if c[-1] <= 0:
        return x[:2], _cross(u[:, :2])
    c /= c[-1]
    i0 = max(int(np.searchsorted(c, tail)) - 1, 0)
    i1 = min(int(np.searchsorted(c, 1 - tail)) + 2, x.size)
    return x[i0:i1], _cross(u[:, i0:i1])


def _cross(u: np.ndarray) -> np.ndarray:
    """X[j, l, n] = sum_m u[j, n, m] conj(u[l, n, m]) for u (J, n, m): shape (J, J, n)."""
    t = np.ascontiguousarray(u.transpose(1, 0, 2))  # (n, J, m)
    return np.moveaxis(t @ t.conj().transpose(0, 2, 1), 0, -1)
