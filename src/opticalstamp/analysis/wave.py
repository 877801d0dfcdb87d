"""Wave optics of the stack: a used pixel's responsivity by the angular spectrum method.

Scalar waves, thin absorbing masks, incoherent light (DESIGN.md section 3, "Wave optics of
the stack"; issue 23). The pixel's sensitive area is a set of mutually incoherent points,
each with a flat angular spectrum over the band |s_x|, |s_y| < B, s = n sin(theta) the
invariant transverse direction (wavevector k_t = 2 pi s / lambda, conserved at planar
interfaces). Reverse tracing (paper Fig. 4): the field of each point is stepped up
through the slabs and multiplied by each mask's transmission on the real staggered
lattice (rows A and B, misregistration), then through the reference gap and the object
medium to the object plane at height Z; the responsivity adds in intensity over the
points.

Normalisation. With the point source's spectrum equal to 1 over the band in spatial
frequency f = s / lambda, a point field carries the power (2B)^2 / lambda^2, so

    R(X, Y; Z) = lambda^2 integral_A |U(X, Y; x0, y0)|^2 dx0 dy0        (sr)

integrates over the object plane to the pixel's etendue in um^2 sr (a uniform
Lambertian object of unit radiance gives the pixel that power), the unit of the tracer's
maps and of :func:`~opticalstamp.analysis.own_etendue.own_etendue`. With no mask the
integral is A (2B)^2 at every Z; between two apertures the paraxial coupling tends, as B
grows, to n w1 w2 / L per axis, the geometric etendue (exactly, without band limit).

This module is the separable fast path: the paraxial propagator exp(-i pi lambda d f^2)
over the reduced (air-equivalent) distance d = sum t / n is separable in x and y; a mask
is a sum of two separable terms (row A: a comb of rects in x times a rect in y; row B
the same, offset), the rows do not overlap in y, so the field of a source point is a sum
of separable terms, one per sequence of rows through the masks (at most rows^masks,
pruned where their power is negligible), and everything reduces to 1-D FFTs. The
source integral is Gauss-Legendre over the sensitive width and height; after every mask
the source points (or modes) of each axis are compressed to the coherent modes that
carry all but ``mode_tol`` of the power (an SVD over every sequence at once, which keeps
the cross terms). The full 2-D path (exact propagator, any hole shape) is in
:mod:`.wave2d`; the sampling rules are in :func:`wave_sampling`.

Fresnel transmission at the index changes (option ``fresnel``) and the pixel's acceptance
cone are filters on the angular spectrum, applied where they act between the masks as
short sums of separable terms (:mod:`.wavefilter`); multiple reflections are left out.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass, field

import numpy as np
from threadpoolctl import ThreadpoolController

from ..design import Design
from ..raytrace.stack import lattice_of, output_pitch
from ..validate import InputError
from .arrays import backend, gram_rows
from .wavebase import (
    Plane,
    WaveSampling,
    gauss_legendre,
    in_band,
    kernel,
    mask_field,
    pixel_record,
    point_sources,
    propagate,
    rectangular,
    response_summary,
    stack_axes,
    stack_grid,
    wave_sampling,
)
from .wavefilter import separable_filter
from .waveobject import (
    ObjectSide,
    lsf_x_from,
    marginals_at,
    object_side,
    responses_at,
    x_modes,
)

__all__ = ["WaveResponse", "WaveSampling", "wave_lsf_x", "wave_response", "wave_sampling"]


# -- the separable engine ------------------------------------------------------------------
@dataclass
class _Axis:
    """One axis of the run: the stack grid and each mask's rows' transmission on it."""

    plane: Plane
    x: np.ndarray  # stack grid (um)
    trans: list[list[np.ndarray]]  # [mask][row] low-passed transmission on x
    lit: list[list[bool]]  # [mask][row] whether any hole of that row is within reach


def _axis(plane: Plane, smp: WaveSampling) -> _Axis:
    b = smp.band
    x = stack_grid(plane.source, plane.heights[-1], smp)
    trans, lit = [], []
    for i, rows in enumerate(plane.holes):
        r_i = plane.heights[i] * b + smp.margin_um  # light in the band stays inside
        keep, on = [], []
        for holes in rows:
            near = (holes[:, 1] > plane.source[0] - r_i) & (holes[:, 0] < plane.source[1] + r_i)
            keep.append(mask_field(x, holes[near], b, smp.wavelength_um))
            on.append(bool(near.any()))
        trans.append(keep)
        lit.append(on)
    return _Axis(plane, x, trans, lit)


def _gram(fields: list[np.ndarray], step: float, weight: np.ndarray | None = None) -> np.ndarray:
    """G[j, l] = step * sum_n sum_m u_j[n, m] conj(u_l[n, m]) (times weight[n])."""
    f = np.stack(fields)  # (J, n, m)
    fw = f if weight is None else f * weight[None, :, None]
    a = fw.reshape(len(fields), -1)
    return (a @ f.reshape(len(fields), -1).conj().T) * step


def _compress(fields: list[np.ndarray], tol: float) -> list[np.ndarray]:
    """The same Gram matrices X_jl = u_j u_l^H with fewer columns (modes): the
    eigenvectors of the modes' Gram matrix over every field at once (the right singular
    vectors of the stacked fields), keeping all but ``tol`` of the power."""
    if not fields:
        return fields
    a = np.concatenate(fields, axis=0)  # (J n, m)
    g = gram_rows(a.T).conj()  # a^H a (zherk)
    p, v = np.linalg.eigh(g)
    p, v = p[::-1], v[:, ::-1]
    p = np.clip(p, 0.0, None)
    keep = int(np.searchsorted(np.cumsum(p), (1 - tol) * p.sum())) + 1
    v = v[:, : max(1, min(keep, p.size))]
    return [f @ v for f in fields]


@dataclass(frozen=True)
class WaveResponse:
    """A pixel's responsivity on the object plane by the wave engine.

    Attributes
    ----------
    design, fingerprint : the design
    pixel : {"row", "k", "x_um", "y_um"}
    z_mm : (nz,) object distances above the reference plane (mm)
    x_um, y_um : (nx,), (ny,) fine grids on the object plane from the pixel's axis (um)
    lsf_x, lsf_y : (nz, nx), (nz, ny) marginals of R (um sr per um): the line-spread
        functions of x (a chart varying along x) and of y
    etendue_um2sr : (nz,) in-band light on the object plane (um^2 sr)
    center_cell_fraction : (nz,) share of it within the central output cell
    budget : per mask: ``incoming``, ``transmitted``, ``in_band`` (um^2 sr) and
        ``sequences`` (row sequences kept) and ``modes`` ((x, y) coherent modes)
    sampling : the :class:`WaveSampling` used
    fields : the separable terms leaving the stack, from which :meth:`spot` recomputes
        X_jl(x), Y_jl(y) at a Z (R = sum_jl X_jl Y_jl)
    meta : what else describes the run (propagator, path, sequences kept)
    """

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
    budget: list[dict]
    sampling: WaveSampling
    fields: ObjectSide | None = field(default=None, repr=False)
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Summary as plain data (no fine arrays)."""
        return response_summary(self) | {
            "budget": self.budget,
            "sampling": asdict(self.sampling),
            "meta": self.meta,
        }

    def spot(self, iz: int, bin_um: float = 2.0, half_um: float | None = None):
        """The responsivity map at ``z_mm[iz]`` on square bins (sr): (edges, map[y, x]),
        edges from the pixel's axis, ``half_um`` half width (default: where the
        marginals hold all but 1e-4 of the light)."""
        (x, gx), (y, gy) = self.fields.terms(float(self.z_mm[iz]))
        if half_um is None:
            half_um = max(
                half_width(self.x_um, self.lsf_x[iz]), half_width(self.y_um, self.lsf_y[iz])
            )
        n = int(math.ceil(half_um / bin_um))
        edges = np.arange(-n, n + 1) * bin_um
        bx = _bin(x, gx, edges)  # (J, J, nb)
        by = _bin(y, gy, edges)
        m = np.einsum("jlx,jly->yx", bx, by).real / (bin_um * bin_um)
        return edges, m


def half_width(x: np.ndarray, p: np.ndarray, tail: float = 1e-4) -> float:
    """Half width about the pixel's axis (um) that holds all but ``tail`` of the
    marginal ``p`` on ``x`` (the default extent of a spot map)."""
    c = np.cumsum(p)
    c = c / c[-1]
    lo = x[np.searchsorted(c, tail / 2)]
    hi = x[min(np.searchsorted(c, 1 - tail / 2), x.size - 1)]
    return float(max(abs(lo), abs(hi)))


def _bin(x: np.ndarray, terms: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Integrals of terms (J, J, n) over the bins ``edges`` (cumulative trapezoid)."""
    dx = x[1] - x[0]
    c = (
        np.concatenate(
            [
                np.zeros(terms.shape[:2] + (1,)),
                np.cumsum((terms[..., 1:] + terms[..., :-1]) / 2, -1),
            ],
            axis=-1,
        )
        * dx
    )
    pos = np.interp(edges, x, np.arange(x.size))
    i0 = np.clip(np.floor(pos).astype(int), 0, x.size - 2)
    t = pos - i0
    ce = c[..., i0] * (1 - t) + c[..., i0 + 1] * t
    return np.diff(ce, axis=-1)


def wave_response(
    design: Design,
    z_mm=(0.0, 1.0, 2.0, 3.0),
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    cell_um: float | None = None,
    fresnel: bool = False,
) -> WaveResponse:
    """Responsivity of a used pixel on the object plane at each Z: separable paraxial path.

    Parameters
    ----------
    design : Design with rectangular (or square) holes
    z_mm : object distances above the reference plane (mm), each >= 0
    pixel : (row, k) of the used pixel (0 = A, 1 = B; k = 0 mid-array)
    sampling : :class:`WaveSampling` (default: :func:`wave_sampling` of the design)
    cell_um : side of the central cell (default: the output pitch, 84.6 um for the paper)
    fresnel : Fresnel transmission losses at the index changes (:mod:`.wavefilter`)

    Returns
    -------
    WaveResponse
        Marginals on the fine object-plane grids, the in-band light (um^2 sr), the share
        in the central cell, the power budget mask by mask.

    Notes
    -----
    The pixel's acceptance cone (``sensor.acceptance_half_angle_deg``) and, with
    ``fresnel``, the interfaces' transmission are filters on the angular spectrum
    (:mod:`.wavefilter`; ``meta["filters"]`` gives their separable terms and measured
    errors). One wavelength: the design's (:mod:`.wavespectral` for a spectrum).
    """
    smp = wave_sampling(design) if sampling is None else sampling
    zs = _heights(z_mm)
    with one_blas_thread():
        terms, axes, budget, filters = _stack(design, pixel, smp, fresnel)
        return _object_side(design, pixel, zs, terms, axes, smp, budget, cell_um, filters)


def wave_marginals(
    design: Design,
    z_mm=(0.0, 1.0, 2.0, 3.0),
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    fresnel: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Both line-spread functions of a used pixel at each Z and its light, and nothing
    else (no budget, no central-cell shares): what a model of scans needs
    (:mod:`~opticalstamp.studies.fitwave`). Each axis by its coherent modes
    (:func:`~.waveobject.marginals_at`): :func:`wave_response`'s marginals to 1e-14 of
    the light in L1 (``MARGINAL_TOL``), in about half its time.

    Returns
    -------
    (x_um (nx,), lsf_x (nz, nx), y_um (ny,), lsf_y (nz, ny), light um^2 sr)
    """
    smp = wave_sampling(design) if sampling is None else sampling
    zs = _heights(z_mm)
    with one_blas_thread():
        side, _ = _leaving(design, pixel, smp, fresnel, zs.max())
        lsf_x, lsf_y, light = marginals_at(side, zs)
    return side.grids[0], lsf_x, side.grids[1], lsf_y, light


def wave_lsf_x(
    design: Design,
    z_mm=(0.0, 1.0, 2.0, 3.0),
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    fresnel: bool = False,
) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """The x line-spread functions of a used pixel alone (what a chart varying along x
    needs), by the object side's x-only path (:func:`~.waveobject.lsf_x_at`): the same
    LSFs as :func:`wave_response` gives (to the compression tolerance ``mode_tol`` in
    L1), without the y marginals and the central-cell shares.

    Returns
    -------
    (x_um (nx,), lsf_x (nz, nx) um sr per um, light um^2 sr, meta {"modes", "sequences"})
    """
    zs = _heights(z_mm)
    src = lsf_source(design, float(zs.max()), pixel=pixel, sampling=sampling, fresnel=fresnel)
    return src.lsf_x(zs)


@dataclass(frozen=True)
class LSFSource:
    """A used pixel's in-band field after the stack, on an object-side grid that holds
    the band's reach up to ``z_max_mm``: x line-spread functions at any Z in [0,
    ``z_max_mm``] without traversing the stack again (:func:`lsf_source`)."""

    side: ObjectSide
    z_max_mm: float
    sequences: list[str]
    modes: np.ndarray = field(repr=False)  # (q, nb) coherent modes of LSF_x (x_modes)
    light: float = 0.0
    meta: dict = field(default_factory=dict)  # how the stack was traversed (2-D path)
    arrays: str = "cpu"  # the object side's array backend (arrays.py): the 2-D path's

    def lsf_x(self, z_mm) -> tuple[np.ndarray, np.ndarray, float, dict]:
        """As :func:`wave_lsf_x` at the heights ``z_mm`` (each <= ``z_max_mm``)."""
        zs = _heights(z_mm)
        if zs.max() > self.z_max_mm * (1 + 1e-12):
            raise ValueError(
                f"z_mm: {zs.max():g} mm lies beyond the grid's reach ({self.z_max_mm:g} mm)"
            )
        bk = None if self.arrays == "cpu" else backend(self.arrays)
        with one_blas_thread():
            lsf = lsf_x_from(self.side, self.modes, zs, bk)
        meta = {"modes": self.modes.shape[0], "sequences": self.sequences}
        return self.side.grids[0], lsf, self.light, meta


def lsf_source(
    design: Design,
    z_max_mm: float,
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    fresnel: bool = False,
) -> LSFSource:
    """The stack traversed once for the pixel: an :class:`LSFSource` for every Z up to
    ``z_max_mm`` (the analyses that refine their heights ask it again and again);
    ``fresnel`` as :func:`wave_response`. Holes that are not rectangles (circles) take
    the 2-D path (:func:`~.wave2dlsf.lsf_source_2d`, on the run's device), whose angular
    filters are exact (not separable sums)."""
    if not rectangular(design):
        from .wave2dlsf import lsf_source_2d

        return lsf_source_2d(design, z_max_mm, pixel=pixel, sampling=sampling, fresnel=fresnel)
    smp = wave_sampling(design) if sampling is None else sampling
    with one_blas_thread():
        side, keys = _leaving(design, pixel, smp, fresnel, z_max_mm)
        modes, light = x_modes(side)
    return LSFSource(side, float(z_max_mm), _names(keys), modes, light)


def _leaving(design: Design, pixel, smp: WaveSampling, fresnel: bool, z_max_mm: float):
    """The stack traversed without its budget and the in-band light leaving it, as an
    :class:`~.waveobject.ObjectSide` reaching ``z_max_mm``, and the terms' keys."""
    terms, axes, _, filters = _stack(design, pixel, smp, fresnel, budget=False)
    terms = _leave(terms, axes, smp, filters)
    keys = list(terms)
    return object_side(keys, terms, _planes(axes), [ax.x for ax in axes], smp, z_max_mm), keys


def one_blas_thread():
    """BLAS on one thread for the engine's call (restored on leaving): its products are
    small or thin, the FFTs carry the work, and OpenBLAS's spinning threads made them
    5-10x slower on a loaded 2-core machine (as in :func:`~opticalstamp.studies.fit.fit`).
    Through one :class:`~threadpoolctl.ThreadpoolController` per process
    (:func:`_blas_controller`): ``threadpool_limits`` scans the loaded libraries at every
    call, 1.3 ms here and 15 ms on a GPU machine with PyTorch's libraries loaded, and the
    engine enters this once per source and per call of :meth:`LSFSource.lsf_x`."""
    return _blas_controller().limit(limits=1, user_api="blas")


@functools.cache
def _blas_controller() -> ThreadpoolController:
    """The BLAS libraries loaded when the engine first runs (NumPy's and SciPy's, which
    this module's imports load), scanned once."""
    return ThreadpoolController()


def _heights(z_mm) -> np.ndarray:
    zs = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    if zs.size == 0 or not np.all(np.isfinite(zs)) or zs.min() < 0:
        raise InputError("z_mm: object distances must be finite and >= 0")
    return zs


def _names(keys) -> list[str]:
    """The row sequences of the terms (once each: the terms of an angular filter share
    their sequence)."""
    names = ["".join("AB"[r] for r in k if isinstance(r, int)) for k in keys]
    return list(dict.fromkeys(names))


def _planes(axes) -> tuple[Plane, Plane]:
    return (axes[0].plane, axes[1].plane)


def stack_reach(design: Design, smp: WaveSampling) -> float:
    """How far along x from the pixel's axis the separable path takes holes (um): two
    pitches beyond four times the band's reach through the stack and the margin."""
    return 2 * lattice_of(design).pitch + 4 * (smp.margin_um + design.reference_plane_um * smp.band)


def _filters(design: Design, axes: list[_Axis], smp: WaveSampling, fresnel: bool) -> list:
    """Each group's angular filter (:mod:`.wavefilter`: group 0 at the source, group i in
    the step to mask i, the last above the object-side mask) as per-term transfer
    factors [(fx (nx,), fy (ny,))] on the stack grids' FFT bins, or None where it is 1."""
    out = []
    s_in = []
    for ax in axes:
        f = np.fft.fftfreq(ax.x.size, smp.step_um)
        keep = np.flatnonzero(in_band(f, smp.wavelength_um, smp.band))
        s_in.append((keep, smp.wavelength_um * f))
    for g in range(axes[0].plane.heights.size + 1):
        sx, sy = (s[k] for k, s in s_in)
        flt = separable_filter(design, g, smp.band, sx, sy, fresnel=fresnel)
        if flt is None:
            out.append(None)
            continue
        terms = []
        for a, b in zip(flt.a, flt.b, strict=True):
            fa, fb = np.zeros(axes[0].x.size), np.zeros(axes[1].x.size)
            fa[s_in[0][0]], fb[s_in[1][0]] = a, b
            terms.append((fa, fb))
        out.append((terms, flt.info))
    return out


def _stack(design: Design, pixel, smp: WaveSampling, fresnel: bool = False, budget: bool = True):
    """The source points stepped up through the stack: (terms {row sequence: (ux, uy)}
    just above the object-side mask, the axes, the budget mask by mask, the angular
    filters (:func:`_filters`; the last one is the object side's)). ``budget`` False: no
    budget (an empty list), which costs a propagation of every term and several Gram
    matrices at each mask and changes nothing else (:func:`lsf_source` drops it)."""
    want = budget
    lam, b, step = smp.wavelength_um, smp.band, smp.step_um
    if step > lam / (6 * b) * (1 + 1e-9):
        raise InputError(
            f"sampling: step {step:g} um is coarser than lambda / (6 band) = {lam / (6 * b):g} um"
        )
    planes = stack_axes(design, pixel, reach_um=stack_reach(design, smp))
    axes = [_axis(p, smp) for p in planes]
    filters = _filters(design, axes, smp, fresnel)
    n_rows = design.sensor.rows
    # source points through the first slab(s) to the first mask
    fields = []
    for ax, npts in zip(axes, smp.source_points, strict=True):
        x0, w = gauss_legendre(*ax.plane.source, npts)
        fields.append(_sources(ax.x, x0, lam * w, lam, float(ax.plane.heights[0]), b))
    terms = {(): (fields[0], fields[1])}
    if filters[0] is not None:  # the acceptance cone and the interfaces below mask 0
        terms = _step_terms(terms, axes, smp, 0.0, filters[0], 0)
    budget = []
    heights = planes[0].heights
    for i in range(heights.size):
        if i > 0:
            terms = _step_terms(terms, axes, smp, heights[i] - heights[i - 1], filters[i], i)
        rec = {"mask": i, "incoming": _power(terms, step)} if want else {}
        new = {}
        for hist, (ux, uy) in terms.items():
            for r in range(n_rows):
                if not (axes[0].lit[i][r] and axes[1].lit[i][r]):
                    continue
                tx, ty = axes[0].trans[i][r], axes[1].trans[i][r]
                new[hist + (r,)] = (ux * tx[:, None], uy * ty[:, None])
        if want:
            rec["transmitted"] = _transmitted(terms, axes, i, n_rows, step)
        new = _prune(new, step, smp.prune_tol)
        keys = list(new)
        cx = _compress([new[k][0] for k in keys], smp.mode_tol)
        cy = _compress([new[k][1] for k in keys], smp.mode_tol)
        terms = {k: (cx[j], cy[j]) for j, k in enumerate(keys)}
        if not want:
            continue
        rec["in_band"] = _power(_band_only(terms, axes, smp), step)
        rec["sequences"] = _names(keys)
        rec["modes"] = (int(cx[0].shape[1]), int(cy[0].shape[1])) if keys else (0, 0)
        budget.append(rec)
    return terms, axes, budget, filters


def _sources(x, x0, w, lam: float, d: float, band: float) -> np.ndarray:
    """:func:`~.wavebase.point_sources`, read-only, the last 16 kept (both axes of a
    design in white light's 7 wavelengths): the designs of a fit's Jacobian or a tolerance
    study that leave the grid, the sensitive area and the first gap as they are (most of
    them) reuse the Fresnel integrals (a tenth of a run)."""
    keys = (np.ascontiguousarray(a, dtype=np.float64).ravel().tobytes() for a in (x, x0, w))
    return _sources_of(*keys, float(lam), float(d), float(band))


@functools.lru_cache(maxsize=16)  # a few MB each on the presets' grids
def _sources_of(x: bytes, x0: bytes, w: bytes, lam: float, d: float, band: float):
    u = point_sources(*(np.frombuffer(v) for v in (x, x0, w)), lam, d, band)  # 1-D each
    u.flags.writeable = False
    return u


def _step_terms(
    terms: dict, axes: list[_Axis], smp: WaveSampling, d: float, filt=None, group: int = 0
) -> dict:
    """The terms over the reduced distance ``d``, through the angular filter ``filt``
    (:func:`_filters`; a filter of K > 1 terms makes K terms of each, their keys marked
    with the group and the filter's term)."""
    hs = [kernel(ax.x.size, smp.step_um, smp.wavelength_um, d, smp.band) for ax in axes]
    if filt is None:
        return {k: (propagate(ux, hs[0]), propagate(uy, hs[1])) for k, (ux, uy) in terms.items()}
    parts = filt[0]
    out = {}
    for k, (ux, uy) in terms.items():
        for t, (fa, fb) in enumerate(parts):
            key = k if len(parts) == 1 else k + (f"{group}.{t}",)
            out[key] = (propagate(ux, hs[0] * fa), propagate(uy, hs[1] * fb))
    return out


def _band_only(terms: dict, axes: list[_Axis], smp: WaveSampling) -> dict:
    return _step_terms(terms, axes, smp, 0.0)


def _leave(terms: dict, axes: list[_Axis], smp: WaveSampling, filters: list) -> dict:
    """The in-band terms leaving the stack, through the interfaces above the object-side
    mask (the last filter of :func:`_filters`)."""
    return _step_terms(terms, axes, smp, 0.0, filters[-1], len(filters) - 1)


def _power(terms: dict, step: float) -> float:
    """2-D power of a sum of separable terms: sum_jl Gx_jl Gy_jl (um^2 sr)."""
    if not terms:
        return 0.0
    gx = _gram([t[0] for t in terms.values()], step)
    gy = _gram([t[1] for t in terms.values()], step)
    return float(np.sum(gx * gy).real)


def _transmitted(terms: dict, axes: list[_Axis], i: int, n_rows: int, step: float) -> float:
    """Power through mask i, midpoint rule with the cells' transmission (|M|^2 = M)."""
    if not terms:
        return 0.0
    ux = [t[0] for t in terms.values()]
    uy = [t[1] for t in terms.values()]
    tot = 0.0
    for r in range(n_rows):
        gx = _gram(ux, step, axes[0].trans[i][r])
        gy = _gram(uy, step, axes[1].trans[i][r])
        tot += float(np.sum(gx * gy).real)
    return tot


def _prune(new: dict, step: float, tol: float) -> dict:
    pw = {k: np.vdot(u, u).real * np.vdot(v, v).real * step * step for k, (u, v) in new.items()}
    total = sum(pw.values())
    return {k: v for k, v in new.items() if total > 0 and pw[k] >= tol * total}


def _object_side(design, pixel, zs, terms, axes, smp, budget, cell_um, filters) -> WaveResponse:
    """From the object-side mask through the reference gap and object medium to every Z."""
    cell = output_pitch(design) if cell_um is None else float(cell_um)
    terms = _leave(terms, axes, smp, filters)  # the in-band light leaving the stack grid
    keys = list(terms)
    side = object_side(keys, terms, _planes(axes), [ax.x for ax in axes], smp, zs.max())
    lsf_x, lsf_y, etendue, cells = responses_at(side, zs, cell)
    for rec in budget:
        rec["lost_to_band"] = rec["transmitted"] - rec["in_band"]
    return WaveResponse(
        design.name,
        design.fingerprint(),
        pixel_record(design, pixel),
        zs,
        side.grids[0],
        side.grids[1],
        lsf_x,
        lsf_y,
        etendue,
        cells,
        budget,
        smp,
        side,
        {
            "propagator": "paraxial",
            "path": "separable",
            "cell_um": cell,
            "sequences": _names(keys),
            "filters": [f[1] for f in filters if f is not None],
        },
    )
