"""The full 2-D path of the wave engine: any hole shape, the exact angular spectrum.

The same physics and normalisation as :mod:`.wave` (read its docstring), on a 2-D grid:
each slab multiplies the spectrum by exp(2 pi i t sqrt((n / lambda)^2 - |f|^2)) (the
exact, non-paraxial angular spectrum, Matsushima & Shimobaba 2009, band-limited by the
domain; ``propagator="paraxial"`` gives exp(-i pi lambda t |f|^2 / n) instead), each
mask multiplies the field by its transmission on the real lattice, rectangles or
circles, low-passed exactly to twice the band from its analytic Fourier transform (a
rectangle's sinc product, a disk's jinc), so no edge is snapped to the grid.

The pixel's incoherent light is carried by coherent modes: the operator A from the
source points (Gauss-Legendre nodes over the sensitive area) to the field after the
object-side mask is sampled with random source vectors (a randomized range finder,
Halko, Martinsson & Tropp 2011) until a fresh block of vectors finds less than ``tol`` of
its power outside the range found; the range's coherent modes (eigenvectors of
Q A A^H Q^H) carry the light up to the object plane. The missing power is the estimator
itself: for Gaussian vectors w, E |(I - Q Q^H) A w|^2 = |(I - Q Q^H) A|_F^2.

The source fields at the first mask are the separable closed forms of
:func:`.wave.point_sources` (a square band), corrected by the exact-over-paraxial phase
of the slabs below the first mask (a smooth factor, so the DFT does not see the band's
hard edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from scipy import fft as sfft

from ..design import Design
from ..raytrace.stack import lattice_of, output_pitch
from ..validate import InputError
from .arrays import CPU, Backend, fft_workers, wave_backend
from .wave2dgrid import Layer, angular_filters, layers_of, mask_field_2d, transfer
from .wave2dop import StackOperator, in_band_runs, operator_grid
from .wavebase import (
    WaveSampling,
    band_integral,
    gauss_legendre,
    in_band,
    object_grid,
    pixel_record,
    point_sources,
    response_summary,
    stack_grid,
    wave_sampling,
)

PROPAGATORS = ("exact", "paraxial")
#: Relative power the randomized range finder may leave out, and its block of vectors.
RANGE_TOL = 1e-6
BLOCK = 16
#: The loosest range-finder tolerance a wavelength of small weight gets (:func:`range_tol`).
MAX_RANGE_TOL = 1e-3


def range_tol(weight: float, tol: float = RANGE_TOL) -> float:
    """The range finder's tolerance for a wavelength that enters a light's sum with
    ``weight`` (the weights summing to 1): ``tol / weight``, at most
    :data:`MAX_RANGE_TOL`, as :func:`~.wavespectral.spectral_samplings` scales the mode
    compression's. What a wavelength leaves out then counts in the sum as about ``tol``
    of the sum's power, whatever its weight (where the wavelengths' powers are alike):
    the sum of n wavelengths leaves out about n ``tol`` of its power (sum_i w_i
    range_tol(w_i) = 6.4e-6 in white light), and up to twice that, since the range
    finder's stop (an estimate from one block of vectors, not a bound) and the modes'
    truncation each spend it; where every wavelength at ``tol`` would spend as much on
    the light's faint ends as on its peak (the circular prototype's 0.757 um, weight
    4e-4: 8 blocks of vectors at 1e-6, 4 at 1e-3)."""
    return tol if weight >= 1.0 else min(MAX_RANGE_TOL, tol / weight)


#: The operator's floating point: "single" (complex64 FFTs, 3x faster on a 2-core CPU;
#: relative error ~2e-7 of the fields, measured) or "double".
PRECISIONS = MappingProxyType(
    {"single": (np.complex64, np.float32), "double": (np.complex128, np.float64)}
)


def _stack(
    design,
    pixel,
    smp: WaveSampling,
    propagator: str,
    bk: Backend = CPU,
    fresnel: bool = False,
    precision: str = "single",
) -> tuple[StackOperator, list[Layer]]:
    if precision not in PRECISIONS:
        raise InputError(f"precision: one of {', '.join(PRECISIONS)} (got {precision!r})")
    cdt, rdt = PRECISIONS[precision]
    lam, b = smp.wavelength_um, smp.band
    reach = 2 * lattice_of(design).pitch + 4 * (smp.margin_um + design.reference_plane_um * b)
    layers = layers_of(design, pixel, reach)
    s = design.sensor
    src = [(-s.sensitive_width_um / 2, s.sensitive_width_um / 2)]
    src.append((-s.sensitive_height_um / 2, s.sensitive_height_um / 2))
    top = layers[-1].reduced
    x, y = stack_grid(src[0], top, smp), stack_grid(src[1], top, smp)
    gx, gy = operator_grid(x, lam, b), operator_grid(y, lam, b)

    def bins(g):
        return np.flatnonzero(in_band(sfft.fftfreq(g.size, g[1] - g[0]), lam, b))

    ky, kx, gky, gkx = bins(y), bins(x), bins(gy), bins(gx)
    filt = angular_filters(design, gx, gy, lam, fresnel, (gky, gkx))  # on the in-band bins
    filt = [None if f is None else bk.put(f) for f in filt]
    first = None
    if propagator == "exact":
        first = transfer(
            gx, gy, layers[0].slabs, lam, b, propagator, relative=True, bins=(gky, gkx), xp=bk.xp
        )
    if filt[0] is not None:  # a filter commutes with free space: anywhere below mask 1
        first = filt[0] if first is None else first * filt[0]
    first = None if first is None else first.astype(cdt)
    # the sources: where ``first`` projects them into the band, their in-band spectra on
    # the sampling's grid (so the operator's grid changes nothing); else their fields
    # on the operator's grid
    fields = []
    for g, (lo, hi), npts in zip(
        (gx, gy) if first is None else (x, y), src, smp.source_points, strict=True
    ):
        x0, w = gauss_legendre(lo, hi, npts)
        fields.append(point_sources(g, x0, lam * w, lam, layers[0].reduced, b))
    masks = []
    for lay in layers:
        r_i = lay.reduced * b + smp.margin_um + max(max(h.hw, h.hh) for h in lay.holes)
        near = [
            h
            for h in lay.holes
            if src[0][0] - r_i < h.cx < src[0][1] + r_i and src[1][0] - r_i < h.cy < src[1][1] + r_i
        ]
        masks.append(mask_field_2d(gx, gy, near, b, lam, bk).astype(rdt))
    steps = []
    for i, lay in enumerate(layers[1:], start=1):
        h = transfer(gx, gy, lay.slabs, lam, b, propagator, bins=(gky, gkx), xp=bk.xp)
        steps.append((h if filt[i] is None else h * filt[i]).astype(cdt))
    ux, uy = (None, None) if first is not None else (bk.put(f.astype(cdt)) for f in fields)
    top = None if filt[-1] is None else filt[-1].ravel()
    runs = {
        name: in_band_runs(k, g.size)
        for name, k, g in (("kx", kx, x), ("ky", ky, y), ("gkx", gkx, gx), ("gky", gky, gy))
    }
    if runs["kx"] != runs["gkx"] or runs["ky"] != runs["gky"]:  # the same frequencies
        raise ValueError("in-band bins: the operator's grid and the sampling's differ")
    st = StackOperator(
        x, y, ux, uy, first, masks, steps, bk.put(ky), bk.put(kx), bk, top, cdt,
        gx=gx, gy=gy, gkx=bk.put(gkx), gky=bk.put(gky), runs=runs,
    )  # fmt: skip
    if first is not None:  # the sampling grid's spectra at the operator grid's scale
        sx = sfft.fft(fields[0], axis=0, workers=fft_workers())[kx] * (gx.size / x.size)
        sy = sfft.fft(fields[1], axis=0, workers=fft_workers())[ky] * (gy.size / y.size)
        st.sx, st.sy = bk.put(sx.astype(cdt)), bk.put(sy.astype(cdt))
    return st, layers


def coherent_modes(
    st: StackOperator, *, tol: float = RANGE_TOL, block: int = BLOCK, seed: int = 0, max_modes=4096
) -> tuple[object, dict]:
    """Coherent modes of the in-band light after the top mask: (r, nb) in-band spectra
    on the sampling's grid (:class:`~.wave2dop.StackOperator`, on its backend) whose
    fields' intensities add up to the pixel's responsivity (um^2 sr per um^2), and what
    the range finder did.

    Blocks of complex Gaussian source vectors are pushed through A until a fresh block
    finds, on average, less than ``tol`` of the mean power of A w outside the range kept
    (an unbiased estimate of the relative Frobenius power left out); then B = E^H A by
    the adjoint, and the eigenvectors of B B^H give the modes, the weakest dropped while
    their power stays below ``tol``. The same vectors estimate the light the masks send
    beyond the band (E |(1 - P_band) A_full w|^2 = |(1 - P_band) A_full|_F^2):
    ``info["lost_to_band"]`` and its standard error (um^2 sr; counted, not propagated).
    """
    bk, xp = st.bk, st.bk.xp
    rng = np.random.default_rng(seed)
    n0y, n0x = st.sources
    basis = _Rows(xp)  # the orthonormal rows found, block by block
    total, missing, tries = 0.0, np.inf, 0
    lost: list[np.ndarray] = []
    step2 = st.cell
    while missing > tol * total and basis.rank < max_modes:
        w = rng.standard_normal((block, n0y, n0x)) + 1j * rng.standard_normal((block, n0y, n0x))
        y, out = st.forward(bk.put(w / np.sqrt(2)), with_power=True)
        lost.append(bk.host(out))
        tries += 1
        total += (float(xp.vdot(y, y).real) / block - total) / tries  # running mean |A w|^2
        y = _project_out(xp, y, basis.rows)
        missing = float(xp.vdot(y, y).real) / block
        p, v = xp.linalg.eigh(y @ y.conj().T)  # orthonormalise the block (Gram)
        good = p > 1e-24 * max(float(p.max()) if p.size else 0.0, 1e-300)
        if bool(good.any()):  # (a block wholly in the range found adds nothing)
            basis.add((v[:, good] / xp.sqrt(p[good])).conj().T @ y)
    q = basis.rows
    b = xp.concatenate([st.adjoint(q[i : i + block]) for i in range(0, q.shape[0], block)])
    st.bufs.clear()  # the work arrays: not needed by what uses the modes
    bm = b.reshape(q.shape[0], -1).conj()  # B = E^H A, (r, n_src)
    p, v = xp.linalg.eigh(bm @ bm.conj().T)
    p, v = xp.clip(p[::-1], 0, None), v[:, ::-1]
    ph = bk.host(p)
    keep = int(np.searchsorted(np.cumsum(ph), (1 - tol) * ph.sum())) + 1
    keep = max(1, min(keep, ph.size))
    modes = (v[:, :keep] * xp.sqrt(p[:keep] * st.scale**2)).T @ q  # the sampling grid's
    out = np.concatenate(lost) * step2  # um^2 sr per random vector
    info = {
        "range": int(q.shape[0]),
        "modes": keep,
        "blocks": tries,
        "missing_estimate": missing / total,
        "lost_to_band": float(out.mean()),
        "lost_to_band_se": float(out.std(ddof=1) / np.sqrt(out.size)) if out.size > 1 else 0.0,
        "in_band": float(ph[:keep].sum()) * step2,
    }
    return modes, info


#: A second Gram-Schmidt pass over a block where one of its vectors keeps less than this
#: of its norm (one pass leaves it orthogonal to the range found to ~eps / this; the
#: range finder's vectors keep ~sqrt(tol) = 1e-3 of theirs).
REORTH = 1e-5


def _project_out(xp, y, q):
    """The rows of ``y`` less their parts in the span of the orthonormal rows ``q`` (r,
    nb) (classical Gram-Schmidt against all of them in two products, y q^H as
    conj(conj(y) q^T), so that no conjugate copy of q is made); a second pass where one
    of its rows kept less than :data:`REORTH` of its norm."""
    if q.shape[0] == 0:
        return y
    before = xp.linalg.norm(y, axis=1)
    y = y.copy()
    for _ in range(2):
        y -= (y.conj() @ q.T).conj() @ q
        kept = xp.linalg.norm(y, axis=1)
        if float((kept - REORTH * before).min()) >= 0:
            break
        before = kept
    return y


class _Rows:
    """Rows added block by block to one array, its room doubled when full: a product
    against all of them is one product rather than one per block, and the range needs no
    copy joined at the end (9 blocks of 16 at the circular prototype's 529^2 in-band
    bins, BLAS on one thread: 3.6-3.9 s against 3.9-4.6 s block by block). Its memory:
    up to twice the rows in use, three times while it grows (NumPy commits only the
    pages written; CuPy's pool holds the whole array: the circular prototype's 144 rows
    in 256, 1.15 GB a wavelength, where the blocks and their join at the end took twice
    0.65 GB)."""

    def __init__(self, xp):
        self.xp, self.a, self.rank = xp, None, 0

    @property
    def rows(self):
        return self.a[: self.rank] if self.a is not None else self.xp.zeros((0, 0))

    def add(self, rows) -> None:
        k = rows.shape[0]
        if self.a is None or self.rank + k > self.a.shape[0]:
            room = max(2 * self.rank, self.rank + k)
            grown = self.xp.empty((room, rows.shape[1]), dtype=rows.dtype)
            if self.rank:
                grown[: self.rank] = self.a[: self.rank]
            self.a = grown
        self.a[self.rank : self.rank + k] = rows
        self.rank += k


@dataclass(frozen=True)
class WaveMaps:
    """A pixel's responsivity on the object plane by the 2-D path (cf.
    :class:`.wave.WaveResponse`): marginals on the fine grids, the in-band light, the
    central-cell share, binned maps ``maps`` (nz, nb, nb) in sr on ``edges_um``."""

    design: str
    fingerprint: str
    pixel: dict
    z_mm: np.ndarray
    x_um: np.ndarray
    y_um: np.ndarray
    lsf_x: np.ndarray
    lsf_y: np.ndarray
    etendue_um2sr: np.ndarray
    center_cell_fraction: np.ndarray
    edges_um: np.ndarray
    maps: np.ndarray
    sampling: WaveSampling
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return response_summary(self) | {"meta": self.meta}


@dataclass(frozen=True)
class StackModes:
    """A pixel's in-band light just above the object-side mask, as coherent modes
    (:func:`coherent_modes`) on the stack grid of the backend that computed them."""

    stack: StackOperator
    layers: list[Layer]
    modes: object  # (r, nb) in-band spectra (Parseval-scaled, the sampling grid's)
    info: dict
    sampling: WaveSampling
    propagator: str
    note: str = ""

    @property
    def bk(self) -> Backend:
        return self.stack.bk


def stack_modes(
    design: Design,
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    propagator: str = "exact",
    tol: float = RANGE_TOL,
    seed: int = 0,
    device: str | None = None,
    fresnel: bool = False,
    precision: str = "single",
) -> StackModes:
    """The stack traversed once for the pixel by the 2-D path: its coherent modes above
    the object-side mask (see :func:`wave_response_2d` for the parameters; ``device``
    "cpu" or "cuda", None: the run's device, :func:`~.arrays.wave_backend`; ``fresnel``:
    the interfaces' Fresnel transmission, :func:`angular_filters`, which also apply the
    pixel's acceptance cone; ``precision``: the operator's FFTs in "single" (complex64,
    the default: 3x faster on the CPU, fields to ~2e-7) or "double"; the linear algebra
    of the range finder is double either way)."""
    if propagator not in PROPAGATORS:
        raise InputError(f"propagator: one of {', '.join(PROPAGATORS)} (got {propagator!r})")
    smp = wave_sampling(design) if sampling is None else sampling
    lam, b, step = smp.wavelength_um, smp.band, smp.step_um
    if step > lam / (6 * b) * (1 + 1e-9):
        raise InputError(f"sampling: step {step:g} um is coarser than lambda / (6 band)")
    bk, note = wave_backend(device)
    st, layers = _stack(design, pixel, smp, propagator, bk, fresnel, precision)
    modes, info = coherent_modes(st, tol=tol, seed=seed)
    return StackModes(st, layers, modes, info, smp, propagator, note)


def wave_response_2d(
    design: Design,
    z_mm=(0.0, 1.0),
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    propagator: str = "exact",
    tol: float = RANGE_TOL,
    seed: int = 0,
    cell_um: float | None = None,
    bin_um: float = 2.0,
    map_half_um: float = 200.0,
    device: str | None = None,
    fresnel: bool = False,
    precision: str = "single",
) -> WaveMaps:
    """Responsivity of a used pixel on the object plane at each Z: full 2-D path.

    Parameters
    ----------
    design : Design (square, rectangular or circular holes)
    z_mm : object distances above the reference plane (mm)
    pixel : (row, k) of the used pixel
    sampling : :class:`~opticalstamp.analysis.wave.WaveSampling` (default: the design's)
    propagator : "exact" (angular spectrum, per slab) or "paraxial" (the separable
        path's propagator, for checks)
    tol : relative power the coherent modes may leave out (:func:`coherent_modes`)
    seed : seed of the range finder's random vectors
    cell_um : side of the central cell (default: the output pitch)
    bin_um, map_half_um : bins and half width (um) of the maps
    device : "cpu" (NumPy) or "cuda" (CuPy); None: the run's device (:mod:`.arrays`)
    fresnel : Fresnel transmission at the index changes (:func:`angular_filters`; the
        pixel's acceptance cone applies either way)
    precision : the stack operator's FFTs, "single" or "double" (:func:`stack_modes`)
    """
    zs = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    if zs.size == 0 or not np.all(np.isfinite(zs)) or zs.min() < 0:
        raise InputError("z_mm: object distances must be finite and >= 0")
    sm = stack_modes(
        design,
        pixel=pixel,
        sampling=sampling,
        propagator=propagator,
        tol=tol,
        seed=seed,
        device=device,
        fresnel=fresnel,
        precision=precision,
    )
    st, smp, bk, xp = sm.stack, sm.sampling, sm.bk, sm.bk.xp
    lam, b, step = smp.wavelength_um, smp.band, smp.step_um
    gap = design.reference_gap
    n_obj = design.index(design.object_medium)
    top_red = gap.thickness_um / design.index(gap.medium)
    d_max = top_red + float(zs.max()) * 1000.0 / n_obj
    xf, ox = object_grid(st.x, d_max, smp)
    yf, oy = object_grid(st.y, d_max, smp)
    cell = output_pitch(design) if cell_um is None else float(cell_um)
    nb = int(math.ceil(map_half_um / bin_um))
    edges = np.arange(-nb, nb + 1) * bin_um
    n_z = zs.size
    lsf_x, lsf_y = np.zeros((n_z, xf.size)), np.zeros((n_z, yf.size))
    etendue, cells = np.zeros(n_z), np.zeros(n_z)
    maps = np.zeros((n_z, edges.size - 1, edges.size - 1))
    slabs = [[(gap.thickness_um, design.index(gap.medium)), (z * 1e3, n_obj)] for z in zs]
    hs = [transfer(xf, yf, sl, lam, b, propagator, xp=bk.xp) for sl in slabs]
    inten = xp.zeros((n_z, yf.size, xf.size))
    u = xp.zeros((yf.size, xf.size), dtype=xp.complex128)
    for m in sm.modes:  # one mode at a time: the object grid can be large
        u[oy : oy + st.y.size, ox : ox + st.x.size] = st.field(m)
        s = bk.fft2(u)
        for iz in range(n_z):
            inten[iz] += abs(bk.ifft2(s * hs[iz])) ** 2
    for iz in range(n_z):
        inten_z = bk.host(inten[iz])
        lsf_x[iz] = inten_z.sum(axis=0) * step
        lsf_y[iz] = inten_z.sum(axis=1) * step
        etendue[iz] = inten_z.sum() * step * step
        in_x = band_integral(xf, inten_z, -cell / 2, cell / 2)  # (ny,)
        cells[iz] = float(band_integral(yf, in_x.real, -cell / 2, cell / 2).real) / etendue[iz]
        maps[iz] = binned_map(xf, yf, inten_z, edges) / (bin_um * bin_um)
    meta = {"propagator": propagator, "path": "2d", "cell_um": cell, "device": bk.name}
    meta |= {"grid": (st.y.size, st.x.size), "object_grid": (yf.size, xf.size)} | sm.info
    if sm.note:
        meta["note"] = sm.note
    return WaveMaps(
        design.name,
        design.fingerprint(),
        pixel_record(design, pixel),
        zs,
        xf,
        yf,
        lsf_x,
        lsf_y,
        etendue,
        cells,
        edges,
        maps,
        smp,
        meta,
    )


def binned_map(x: np.ndarray, y: np.ndarray, inten: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Integrals of the intensity (y, x) over the square bins ``edges`` x ``edges``
    (cumulative trapezoid along each axis, interpolated at the edges)."""
    return _axis_bins(y, _axis_bins(x, inten, edges).T, edges).T


def _axis_bins(v: np.ndarray, g: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Integrals over the bins ``edges`` along the last axis of ``g`` (grid ``v``)."""
    c = np.cumsum((g[..., 1:] + g[..., :-1]) / 2, axis=-1) * (v[1] - v[0])
    c = np.concatenate([np.zeros(g.shape[:-1] + (1,)), c], axis=-1)
    pos = np.interp(edges, v, np.arange(v.size))
    i0 = np.clip(np.floor(pos).astype(int), 0, v.size - 2)
    t = pos - i0
    return np.diff(c[..., i0] * (1 - t) + c[..., i0 + 1] * t, axis=-1)
