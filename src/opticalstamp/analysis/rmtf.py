"""Figures of merit: RMTF and depth of field (paper Eq. 1, Fig. 11), light efficiency
(paper Fig. 13).

RMTF. A bar chart of period P (black = 0, white = 1, equal widths) varying along x lies
on the object plane; the pixels of the merged line (row A at k p, row B at b_x + k p)
read I_j = integral LSF_row(X - x_j) f(X - s) dX for a chart shift s. With the LSF
folded modulo P (:mod:`opticalstamp.responsivity`) this is a circular correlation
C_row(v) of the folded LSF with the chart, sampled at the phases v = (x_j - s) mod P.
For each shift, RMTF(s) = (max_j I_j - min_j I_j) / (max_j I_j + min_j I_j) over the
pixels under a chart window; the paper's RMTF is the maximum over shifts (Moiré
suppression); the mean and minimum over shifts are reported too.

Standard errors come from the interleaved ray batches of a traced LSF: the RMTF of
each batch at the full estimate's best shift, their spread over sqrt(n_batches).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ..defaults import (
    DOF_DPI,
    DOF_THRESHOLD,
    PAPER_CHART_DPI,
    RAYS_LSF,
    SHIFT_STEP_UM,
    WINDOW_UM,
    Z_GRID_MM,
)
from ..design import Design
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import lattice_of
from ..units import period_of_dpi
from ..validate import check_memory, parse_grid
from .lsf import FoldedLSF, paraxial_folded_lsf, traced_folded_lsf

#: The paper's chart periods (um) and their names in dpi (one bar = one dot).
PAPER_DPI = PAPER_CHART_DPI
DEFAULT_Z_MM = parse_grid(Z_GRID_MM, "z_mm", 0.0, 100.0)


def chart_correlation(h: np.ndarray) -> np.ndarray:
    """C[..., v] = sum_phi h[..., phi] f[(phi + v) mod n] for the 50 % square wave f.

    ``h`` (..., n) is a folded LSF over one period in n equal bins; f is averaged over
    each bin (white on the first half period). v in bins.
    """
    n = h.shape[-1]
    edges = np.arange(n + 1) / n
    white = np.clip(np.minimum(edges[1:], 0.5) - np.minimum(edges[:-1], 0.5), 0, None) * n
    c = np.fft.irfft(np.conj(np.fft.rfft(h, axis=-1)) * np.fft.rfft(white), n=n, axis=-1)
    return c


def sample_periodic(c: np.ndarray, v_bins: np.ndarray) -> np.ndarray:
    """Periodic linear interpolation of c[..., n] at fractional bin positions v."""
    n = c.shape[-1]
    i0 = np.floor(v_bins).astype(np.int64)
    t = v_bins - i0
    return c[..., i0 % n] * (1 - t) + c[..., (i0 + 1) % n] * t


def merged_pixels(design: Design, window_um: float) -> list[np.ndarray]:
    """x (um) of the used pixels of each row under a chart window [0, window_um)."""
    lat = lattice_of(design)
    out = []
    for r in range(design.sensor.rows):
        out.append(np.arange(lat.row_x[r] % lat.pitch, window_um, lat.pitch))
    return out


def rmtf_curves(
    lsf: FoldedLSF,
    design: Design,
    *,
    window_um: float = WINDOW_UM,
    shift_step_um: float = SHIFT_STEP_UM,
) -> dict:
    """RMTF max / mean / min over chart shifts, per period and Z, with standard errors.

    Returns arrays of shape (n_periods, nz) under keys ``max``, ``mean``, ``min``,
    ``max_se``, ``best_shift_um``.
    """
    pix = merged_pixels(design, window_um)
    shape = (lsf.periods_um.size, lsf.z_mm.size)
    out = {k: np.zeros(shape) for k in ("max", "mean", "min", "max_se", "best_shift_um")}
    for ip, per in enumerate(lsf.periods_um):
        h = lsf.h[ip]  # (rows, batches, nz, n)
        n = h.shape[-1]
        shifts = np.arange(0.0, per, shift_step_um)
        c_full = chart_correlation(h.sum(axis=1))  # (rows, nz, n)
        phases = [((x[None, :] - shifts[:, None]) % per) / per * n for x in pix]
        sig = np.concatenate([sample_periodic(c_full[r], v) for r, v in enumerate(phases)], axis=-1)
        imax, imin = sig.max(axis=-1), sig.min(axis=-1)  # (nz, shifts)
        rm = np.where(imax + imin > 0, (imax - imin) / np.where(imax + imin > 0, imax + imin, 1), 0)
        best = rm.argmax(axis=-1)  # (nz,)
        out["max"][ip] = rm.max(axis=-1)
        out["mean"][ip] = rm.mean(axis=-1)
        out["min"][ip] = rm.min(axis=-1)
        out["best_shift_um"][ip] = shifts[best]
        n_b = h.shape[1]
        if n_b > 1:  # batches only at the full estimate's best shift
            c_batch = chart_correlation(h * n_b)  # each batch scaled to a full estimate
            for iz, ib in enumerate(best):
                sb = np.concatenate(
                    [sample_periodic(c_batch[r, :, iz], phases[r][ib]) for r in range(h.shape[0])],
                    axis=-1,
                )  # (batches, pixels)
                bmax, bmin = sb.max(axis=-1), sb.min(axis=-1)
                rb = (bmax - bmin) / np.where(bmax + bmin > 0, bmax + bmin, 1)
                out["max_se"][ip, iz] = rb.std(ddof=1) / np.sqrt(n_b)
    return out


def chart_waveform(
    lsf: FoldedLSF,
    design: Design,
    period_index: int,
    z_index: int,
    shift_um: float,
    window_um: float = WINDOW_UM,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel x (um) and signals (um^2 sr; white = the etendue) of the merged line for a
    chart shifted by ``shift_um`` (paper Fig. 12 c, d), sorted by x."""
    per = lsf.periods_um[period_index]
    h = lsf.h[period_index].sum(axis=1)[:, z_index]  # (rows, n)
    n = h.shape[-1]
    xs, sig = [], []
    for r, x in enumerate(merged_pixels(design, window_um)):
        c = chart_correlation(h[r])
        xs.append(x)
        sig.append(sample_periodic(c, ((x - shift_um) % per) / per * n))
    x, s = np.concatenate(xs), np.concatenate(sig)
    order = np.argsort(x)
    return x[order], s[order]


def depth_of_field(z_mm: np.ndarray, rmtf: np.ndarray, threshold: float = DOF_THRESHOLD) -> float:
    """Largest Z (mm) up to which RMTF stays >= threshold, interpolated linearly.

    0 if RMTF starts below the threshold; the last Z if it never drops below.
    """
    z = np.asarray(z_mm, dtype=np.float64)
    r = np.asarray(rmtf, dtype=np.float64)
    if r[0] < threshold:
        return 0.0
    below = np.flatnonzero(r < threshold)
    if below.size == 0:
        return float(z[-1])
    return _crossing(z, r, int(below[0]), threshold)


def _crossing(z: np.ndarray, r: np.ndarray, i: int, threshold: float) -> float:
    """Z where the RMTF crosses ``threshold`` between samples i - 1 and i (linear)."""
    return float(z[i - 1] + (r[i - 1] - threshold) / (r[i - 1] - r[i]) * (z[i] - z[i - 1]))


def spurious_ranges(
    z_mm: np.ndarray, rmtf: np.ndarray, threshold: float = DOF_THRESHOLD
) -> list[list[float]]:
    """Ranges [from, to] of Z (mm) past the depth of field where the RMTF is back at or
    above the threshold; each end is the crossing interpolated linearly between samples
    (the last Z where the RMTF is still over the threshold there).

    The RMTF (paper Eq. 1) is a modulation, blind to the sign of the contrast: past a zero
    of the transfer function the bars come back reversed (dark where the chart is light),
    *spurious resolution*. Such ranges are reported and never counted in the depth of
    field (:func:`depth_of_field` stops at the first crossing).
    """
    z = np.asarray(z_mm, dtype=np.float64)
    r = np.asarray(rmtf, dtype=np.float64)
    below = np.flatnonzero(r < threshold)
    if below.size == 0:
        return []
    out: list[list[float]] = []
    start = None
    for i in range(int(below[0]) + 1, z.size):
        if r[i] >= threshold and start is None:
            start = _crossing(z, r, i, threshold)
        if start is not None and r[i] < threshold:
            out.append([start, _crossing(z, r, i, threshold)])
            start = None
    if start is not None:
        out.append([start, float(z[-1])])
    return out


def crossing_brackets(results, steps: int = 8) -> np.ndarray:
    """Z (mm) that resolve the threshold crossings of RMTF results finer: ``steps - 1``
    points inside every grid interval where an RMTF curve crosses its threshold (the
    depth of field, the ends of spurious ranges) and on both sides of every sampled
    local maximum below the threshold past the first crossing (where a narrow spurious
    range may hide between samples), over all charts of all ``results``. Empty where
    nothing crosses. A range narrower than the grid step that leaves no local maximum
    in the samples is still missed: a finer grid finds it."""
    fine: set[float] = set()
    for res in results:
        z = np.asarray(res.z_mm, dtype=np.float64)
        for curve in res.rmtf_max.values():
            r = np.asarray(curve, dtype=np.float64)
            above = r >= res.dof_threshold
            cross = np.flatnonzero(above[1:] != above[:-1])
            spans = [(i, i + 1) for i in cross]
            if cross.size:
                peak = np.flatnonzero((r[1:-1] >= r[:-2]) & (r[1:-1] >= r[2:]) & ~above[1:-1]) + 1
                spans += [(i - 1, i + 1) for i in peak if i > cross[0]]
            for a, b in spans:
                grid = np.linspace(z[a], z[b], steps * (b - a) + 1)[1:-1]
                fine.update(g for g in grid.round(9).tolist() if g not in set(z.tolist()))
    return np.array(sorted(fine), dtype=np.float64)


def refine_crossings(res: RMTFResult, fine_lsf: FoldedLSF, design: Design) -> RMTFResult:
    """``res`` with its depth of field and spurious ranges taken from its curves merged
    with the RMTF at ``fine_lsf``'s Z (the same periods, light and rays; from
    :func:`crossing_brackets`): crossings interpolated over a finer step where the RMTF
    changes fast. The curves on the grid stay as they were; the finer samples are kept
    in ``meta["refined"]``."""
    if fine_lsf.z_mm.size == 0:
        return res
    cur = rmtf_curves(fine_lsf, design, window_um=res.window_um, shift_step_um=res.shift_step_um)
    z_all = np.concatenate([np.asarray(res.z_mm, dtype=np.float64), fine_lsf.z_mm])
    order = np.argsort(z_all, kind="stable")
    dof, spurious, refined = dict(res.dof_mm), dict(res.spurious_mm), {}
    for i, key in enumerate(_key(d) for d in res.dpi):
        r_all = np.concatenate([np.asarray(res.rmtf_max[key]), cur["max"][i]])[order]
        if not res.dof_open_ended.get(key):
            dof[key] = depth_of_field(z_all[order], r_all, res.dof_threshold)
        spurious[key] = spurious_ranges(z_all[order], r_all, res.dof_threshold)
        refined[key] = cur["max"][i].tolist()
    meta = res.meta | {"refined": {"z_mm": fine_lsf.z_mm.tolist(), "rmtf_max": refined}}
    return replace(res, dof_mm=dof, spurious_mm=spurious, meta=meta)


@dataclass(frozen=True)
class RMTFResult:
    """RMTF versus object distance for several chart periods (paper Fig. 11)."""

    design: str
    fingerprint: str
    seed: int
    method: str
    ghosts: bool
    fresnel: bool
    n_rays: int
    dpi: list[float]
    periods_um: list[float]
    z_mm: list[float]
    rmtf_max: dict[str, list[float]]
    rmtf_max_se: dict[str, list[float]]
    rmtf_mean: dict[str, list[float]]
    rmtf_min: dict[str, list[float]]
    dof_mm: dict[str, float]
    dof_threshold: float
    dof_dpi: float
    window_um: float
    shift_step_um: float
    meta: dict = field(default_factory=dict)
    #: per dpi: the RMTF stays above the threshold to the last Z, so ``dof_mm`` is a lower
    #: bound (">= Zmax"), not a crossing
    dof_open_ended: dict[str, bool] = field(default_factory=dict)
    #: per dpi: Z ranges [from, to] (mm) past the depth of field where the RMTF is back
    #: over the threshold (spurious resolution, :func:`spurious_ranges`; not in dof_mm)
    spurious_mm: dict[str, list[list[float]]] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)

    def dof_text(self, key: str) -> str:
        """The depth of field for chart ``key`` as text: "2.48 mm" or ">= 4.50 mm"."""
        v = self.dof_mm[key]
        return f">= {v:.2f} mm" if self.dof_open_ended.get(key) else f"{v:.2f} mm"

    def to_dataset(self):
        """The curves as an xarray Dataset on coordinates ``dpi`` and ``z_mm``.

        Variables ``rmtf`` (max over chart shifts, paper Eq. 1), ``rmtf_se``, ``rmtf_mean``,
        ``rmtf_min`` (dpi, z_mm), ``period_um`` and ``dof_mm`` (dpi); the method, ghosts,
        Fresnel setting, seed and design in the attributes.
        """
        import xarray as xr

        keys = [_key(d) for d in self.dpi]

        def grid(table: dict) -> np.ndarray:
            return np.array([table[k] for k in keys], dtype=np.float64)

        dims = ("dpi", "z_mm")
        return xr.Dataset(
            {
                "rmtf": (dims, grid(self.rmtf_max)),
                "rmtf_se": (dims, grid(self.rmtf_max_se)),
                "rmtf_mean": (dims, grid(self.rmtf_mean)),
                "rmtf_min": (dims, grid(self.rmtf_min)),
                "period_um": ("dpi", np.asarray(self.periods_um, dtype=np.float64)),
                "dof_mm": ("dpi", np.array([self.dof_mm.get(k, np.nan) for k in keys])),
            },
            coords={"dpi": np.asarray(self.dpi, dtype=np.float64), "z_mm": self.z_mm},
            attrs={
                "design": self.design,
                "fingerprint": self.fingerprint,
                "seed": self.seed,
                "method": self.method,
                "ghosts": int(self.ghosts),
                "fresnel": int(self.fresnel),
                "dof_threshold": self.dof_threshold,
            },
        )


def _key(dpi: float) -> str:
    return f"{dpi:g}"


def check_rmtf_memory(
    design: Design, period_um: float, n_z: int, window_um: float, shift_step_um: float
) -> None:
    """Refuse a chart window and shift step whose signal array (Z x shifts x pixels, float64,
    in :func:`rmtf_curves`) would not fit in MAX_WORK_BYTES, before any tracing."""
    n_pix = design.sensor.rows * (window_um / lattice_of(design).pitch + 1)
    n_shift = math.ceil(period_um / shift_step_um)
    check_memory(
        8.0 * n_z * n_shift * n_pix,
        f"shift_step_um {shift_step_um:g} (--shift-um) with window_um {window_um:g} "
        f"(--window-um) and {n_z} distances",
    )


def rmtf(
    design: Design,
    *,
    dpi=PAPER_DPI,
    z_mm=DEFAULT_Z_MM,
    method: str = "trace",
    ghosts: bool = True,
    fresnel: bool = False,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    window_um: float = WINDOW_UM,
    shift_step_um: float = SHIFT_STEP_UM,
    dof_threshold: float = DOF_THRESHOLD,
    dof_dpi: float = DOF_DPI,
    progress: bool = False,
    tracer: PixelTracer | None = None,
    refine: int = 8,
) -> RMTFResult:
    """RMTF of paper Eq. 1 for bar charts of the given dpi versus Z, and depth of field.

    Parameters
    ----------
    dpi : chart resolutions; period = 2 * 25.4 mm / dpi (508, 339, 254, 206 um)
    method : "trace" (exact tracer, own and ghost light) or "paraxial" (own path,
        closed form, rectangular holes; no ghosts, no Fresnel)
    window_um : width of the chart window over which Imax and Imin are taken
    shift_step_um : step of the chart shifts over one period
    dof_threshold, dof_dpi : depth of field = largest Z with RMTF(dof_dpi) >= threshold
    tracer : a :class:`~opticalstamp.raytrace.pixel.PixelTracer` of this design whose
        pilot runs are reused (analyses of one report share one)
    refine : the threshold crossings (depth of field, spurious ranges) are found again
        with the RMTF at ``refine - 1`` more Z inside each grid interval where a curve
        crosses (:func:`refine_crossings`; the same rays); 0 or 1: on the grid alone
    """
    dpis = [float(d) for d in dpi]
    if dof_dpi not in dpis:
        dpis.append(float(dof_dpi))
    if any(d <= 0 for d in dpis):
        raise ValueError("dpi: every chart resolution must be > 0")
    if window_um <= 0 or shift_step_um <= 0:
        raise ValueError("window_um and shift_step_um must be > 0")
    periods = np.array([period_of_dpi(d) for d in dpis])
    zs = np.asarray(z_mm, dtype=np.float64)
    check_rmtf_memory(design, periods.max(), zs.size, window_um, shift_step_um)
    if method not in ("trace", "paraxial"):
        raise ValueError(f"method must be 'trace' or 'paraxial' (got {method!r})")

    def lsf_at(z: np.ndarray) -> FoldedLSF:
        if method == "paraxial":
            return paraxial_folded_lsf(design, z_mm=z, periods_um=periods)
        return traced_folded_lsf(
            design,
            z_mm=z,
            periods_um=periods,
            n_rays=n_rays,
            seed=seed,
            ghosts=ghosts,
            fresnel=fresnel,
            progress=progress,
            tracer=tracer,
        )

    res = rmtf_from_lsf(
        lsf_at(zs),
        design,
        dpi=dpis,
        seed=seed,
        window_um=window_um,
        shift_step_um=shift_step_um,
        dof_threshold=dof_threshold,
        dof_dpi=dof_dpi,
    )
    fine = crossing_brackets([res], refine) if refine > 1 else np.zeros(0)
    return refine_crossings(res, lsf_at(fine), design) if fine.size else res


def rmtf_from_lsf(
    lsf: FoldedLSF,
    design: Design,
    *,
    dpi,
    seed: int = 0,
    window_um: float = WINDOW_UM,
    shift_step_um: float = SHIFT_STEP_UM,
    dof_threshold: float = DOF_THRESHOLD,
    dof_dpi: float = DOF_DPI,
) -> RMTFResult:
    """RMTF and depth of field from folded LSFs (periods in the order of ``dpi``)."""
    dpis = [float(d) for d in dpi]
    zs = lsf.z_mm
    cur = rmtf_curves(lsf, design, window_um=window_um, shift_step_um=shift_step_um)
    keys = [_key(d) for d in dpis]
    pick = {name: {k: cur[name][i].tolist() for i, k in enumerate(keys)} for name in cur}
    dof = {k: depth_of_field(zs, cur["max"][i], dof_threshold) for i, k in enumerate(keys)}
    # a depth of field that reaches the last Z is a lower bound: the range ended first
    open_ended = {k: bool(min(cur["max"][i]) >= dof_threshold) for i, k in enumerate(keys)}
    spurious = {k: spurious_ranges(zs, cur["max"][i], dof_threshold) for i, k in enumerate(keys)}
    return RMTFResult(
        design=design.name,
        fingerprint=design.fingerprint(),
        seed=seed,
        method=lsf.method,
        ghosts=lsf.ghosts,
        fresnel=lsf.fresnel,
        n_rays=lsf.n_rays,
        dpi=dpis,
        periods_um=lsf.periods_um.tolist(),
        z_mm=zs.tolist(),
        rmtf_max=pick["max"],
        rmtf_max_se=pick["max_se"],
        rmtf_mean=pick["mean"],
        rmtf_min=pick["min"],
        dof_mm=dof,
        dof_threshold=dof_threshold,
        dof_dpi=dof_dpi,
        window_um=window_um,
        shift_step_um=shift_step_um,
        meta={"best_shift_um": pick["best_shift_um"]},
        dof_open_ended=open_ended,
        spurious_mm=spurious,
    )
