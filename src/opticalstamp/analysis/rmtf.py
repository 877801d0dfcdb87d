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
    DOF_THRESHOLD,
    PAPER_CHART_DPI,
    RAYS_LSF,
    SHIFT_STEP_UM,
    WINDOW_UM,
    Z_GRID_MM,
)
from ..design import Design
from ..design.resolution import chart_dpis, dof_chart_dpi
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import lattice_of
from ..units import period_of_dpi
from ..validate import check_memory, parse_grid
from .colour import channel_folds, folded_lsf_channels, worst_channel
from .dof import depth_of_field, dof_bounds, dof_text, refine_points, spurious_ranges
from .lsf import FoldedLSF, fast_light
from .responsivity import RAY, Optics, resolve_optics

__all__ = ["depth_of_field", "dof_bounds", "dof_text", "refine_points", "spurious_ranges"]

#: The paper's chart periods (um) and their names in dpi (one bar = one dot), for its
#: 300-dpi line; a design's own charts: :func:`~opticalstamp.design.resolution.chart_dpis`
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
    shading: bool = True,
) -> dict:
    """RMTF max / mean / min over chart shifts, per period and Z, with standard errors.

    ``shading``: the merged line as a scanner delivers it, each pixel divided by its own
    white response (shading correction: each row's signals over the row's signal from a
    white page at that Z), so rows that collect different light (misregistered layers)
    are not read as contrast; False: the raw merged line.

    Returns arrays of shape (n_periods, nz) under keys ``max``, ``mean``, ``min``,
    ``max_se``, ``best_shift_um``.
    """
    pix = merged_pixels(design, window_um)
    shape = (lsf.periods_um.size, lsf.z_mm.size)
    out = {k: np.zeros(shape) for k in ("max", "mean", "min", "max_se", "best_shift_um")}
    for ip, per in enumerate(lsf.periods_um):
        h = lsf.h[ip]  # (rows, batches, nz, n)
        if shading:
            h = h / white_level(h)[:, None, :, None]
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


def white_level(h: np.ndarray) -> np.ndarray:
    """(rows, nz) signal of each row's pixel from a white page (the folded LSF's total,
    um^2 sr), 1 where a row collects nothing (its signals stay 0)."""
    w = h.sum(axis=(1, 3))
    return np.where(w > 0, w, 1.0)


def chart_waveform(
    lsf: FoldedLSF,
    design: Design,
    period_index: int,
    z_index: int,
    shift_um: float,
    window_um: float = WINDOW_UM,
    shading: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel x (um) and signals of the merged line for a chart shifted by ``shift_um``
    (paper Fig. 12 c, d), sorted by x: relative to each pixel's white response
    (``shading``, as :func:`rmtf_curves`), else in um^2 sr (white = the etendue)."""
    per = lsf.periods_um[period_index]
    hp = lsf.h[period_index]
    if shading:
        hp = hp / white_level(hp)[:, None, :, None]
    h = hp.sum(axis=1)[:, z_index]  # (rows, n)
    n = h.shape[-1]
    xs, sig = [], []
    for r, x in enumerate(merged_pixels(design, window_um)):
        c = chart_correlation(h[r])
        xs.append(x)
        sig.append(sample_periodic(c, ((x - shift_um) % per) / per * n))
    x, s = np.concatenate(xs), np.concatenate(sig)
    order = np.argsort(x)
    return x[order], s[order]


def merged_samples(res: RMTFResult, key: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z (mm), RMTF and its standard error of chart ``key`` on the grid and at the
    refined Z of ``res`` together, ascending in Z."""
    ref = res.meta.get("refined", {})
    z = np.concatenate([np.asarray(res.z_mm, dtype=np.float64), ref.get("z_mm", [])])
    r = np.concatenate([res.rmtf_max[key], ref.get("rmtf_max", {}).get(key, [])])
    e = np.concatenate([res.rmtf_max_se[key], ref.get("rmtf_max_se", {}).get(key, [])])
    order = np.argsort(z, kind="stable")
    return z[order], r[order], e[order]


def crossing_brackets(results, steps: int = 8) -> np.ndarray:
    """Z (mm) at which to sample RMTF results again so that their threshold crossings
    are resolved: :func:`refine_points` over every chart of every result (on its grid
    and refined samples together). Empty where nothing needs it."""
    fine: set[float] = set()
    for res in results:
        for d in res.dpi:
            key = _key(d)
            z, r, e = merged_samples(res, key)
            fast = res.meta.get("fast_light") if key == res.dof_key else None
            step = None if fast is None else _step_for_margin(fast, period_of_dpi(d))
            pts = refine_points(z, r, e, res.dof_threshold, steps=steps, step_for_margin=step)
            fine.update(pts.tolist())
    return np.array(sorted(fine), dtype=np.float64)


def _step_for_margin(fast: dict, period_um: float):
    """margin -> the Z step (mm) that resolves the curve of a chart of period ``period_um``
    to within that margin of RMTF: a quarter of the Z over which light of slope t moves
    one period (P / 4 t), for the slope t that all but margin / 2 of the light stays
    under (light carrying a fraction g of the signal moves the RMTF by at most about
    2 g); ``fast``: ``meta["fast_light"]`` (:func:`~opticalstamp.analysis.lsf.fast_light`)."""
    slope, beyond = np.asarray(fast["slope"]), np.asarray(fast["beyond"])

    def step(margin):
        i = np.searchsorted(-beyond, -np.maximum(np.asarray(margin), 0.0) / 2.0, side="left")
        t = np.where(i < slope.size, slope[np.minimum(i, slope.size - 1)], slope[-1])
        return period_um / (4.0 * np.maximum(t, slope[1])) / 1000.0

    return step


def refine_crossings(res: RMTFResult, fine_lsf: FoldedLSF, design: Design) -> RMTFResult:
    """``res`` with its depth of field, its range and the spurious ranges taken from its
    samples merged with the RMTF at ``fine_lsf``'s Z (the same periods, light and rays;
    from :func:`crossing_brackets`). The curves on the grid stay as they were; the finer
    samples are kept in ``meta["refined"]`` (added to those of earlier rounds)."""
    if fine_lsf.z_mm.size == 0:
        return res
    cur = rmtf_curves(
        fine_lsf,
        design,
        window_um=res.window_um,
        shift_step_um=res.shift_step_um,
        shading=res.shading,
    )
    old = res.meta.get("refined", {"z_mm": [], "rmtf_max": {}, "rmtf_max_se": {}})
    refined = {
        "z_mm": list(old["z_mm"]) + fine_lsf.z_mm.tolist(),
        "rmtf_max": {},
        "rmtf_max_se": {},
    }
    for i, key in enumerate(_key(d) for d in res.dpi):
        for name, part in (("rmtf_max", "max"), ("rmtf_max_se", "max_se")):
            refined[name][key] = list(old[name].get(key, [])) + cur[part][i].tolist()
    out = replace(res, meta=res.meta | {"refined": refined})
    return _with_crossings(out)


def _with_crossings(res: RMTFResult) -> RMTFResult:
    """``res`` with its depth of field, range and spurious ranges from all its samples."""
    dof, bounds, spurious, open_ended = {}, {}, {}, {}
    for key in (_key(d) for d in res.dpi):
        z, r, e = merged_samples(res, key)
        dof[key] = depth_of_field(z, r, res.dof_threshold)
        bounds[key] = dof_bounds(z, r, e, res.dof_threshold)
        spurious[key] = spurious_ranges(z, r, res.dof_threshold)
        # a depth of field that reaches the last Z is a lower bound: the range ended first
        open_ended[key] = bool(r.min() >= res.dof_threshold)
    return replace(
        res, dof_mm=dof, dof_range_mm=bounds, spurious_mm=spurious, dof_open_ended=open_ended
    )


def refine_results(results: list, trace, design: Design, *, steps: int = 8, passes: int = 1):
    """RMTF results refined where their crossings need it, ``passes`` rounds of
    :func:`crossing_brackets` / :func:`refine_crossings`; ``trace(z)`` returns one
    :class:`FoldedLSF` per result at the Z given (the same rays as the grid's)."""
    results = list(results)
    for _ in range(passes if steps > 1 else 0):
        fine = crossing_brackets(results, steps)
        if fine.size == 0:
            break
        lsfs = trace(fine)
        results = [refine_crossings(r, f, design) for r, f in zip(results, lsfs, strict=True)]
    return results


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
    #: per dpi: [low, high] (mm), the depth of field of the curves 2 standard errors
    #: below and above (:func:`dof_bounds`)
    dof_range_mm: dict[str, list[float]] = field(default_factory=dict)
    #: the merged line shading-corrected (each pixel over its white response), as a
    #: scanner delivers it; False: the raw merged line
    shading: bool = True

    def to_dict(self) -> dict:
        return asdict(self)

    def dof_text(self, key: str) -> str:
        """The depth of field for chart ``key`` as text (:func:`dof_text`)."""
        return dof_text(self.to_dict(), key)

    @property
    def dof_key(self) -> str:
        """The key of the depth-of-field chart."""
        return _key(self.dof_dpi)

    def to_dataset(self):
        """The curves as an xarray Dataset on coordinates ``dpi`` and ``z_mm``.

        Variables ``rmtf`` (max over chart shifts, paper Eq. 1), ``rmtf_se``, ``rmtf_mean``,
        ``rmtf_min`` (dpi, z_mm), ``period_um``, ``dof_mm``, ``dof_open_ended`` (a lower
        bound: the Z range ended first) and ``dof_low_mm`` / ``dof_high_mm`` (the range at
        ±2 SE) (dpi); the method, ghosts, shading, Fresnel setting, seed, design and the
        depth-of-field chart in the attributes. A colour scanner's channels (wave
        optics): ``rmtf_channel`` (channel, dpi, z_mm) and ``dof_channel_mm`` (channel,
        dpi), the headline channel (the worst) in the attributes.
        """
        import xarray as xr

        keys = [_key(d) for d in self.dpi]

        def grid(table: dict) -> np.ndarray:
            return np.array([table[k] for k in keys], dtype=np.float64)

        dims = ("dpi", "z_mm")
        ds = xr.Dataset(
            {
                "rmtf": (dims, grid(self.rmtf_max)),
                "rmtf_se": (dims, grid(self.rmtf_max_se)),
                "rmtf_mean": (dims, grid(self.rmtf_mean)),
                "rmtf_min": (dims, grid(self.rmtf_min)),
                "period_um": ("dpi", np.asarray(self.periods_um, dtype=np.float64)),
                "dof_mm": ("dpi", np.array([self.dof_mm.get(k, np.nan) for k in keys])),
                # the depth of field is a lower bound where the curve never fell below
                "dof_open_ended": (
                    "dpi",
                    np.array([self.dof_open_ended.get(k, False) for k in keys], np.int8),
                ),
                "dof_low_mm": (
                    "dpi",
                    np.array([self.dof_range_mm.get(k, [np.nan])[0] for k in keys]),
                ),
                "dof_high_mm": (
                    "dpi",
                    np.array([self.dof_range_mm.get(k, [np.nan])[-1] for k in keys]),
                ),
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
                "dof_dpi": self.dof_dpi,
                "shading": int(self.shading),
            },
        )
        from .colour import channel_variables  # a colour scanner's channels, one by one

        extra = channel_variables(self)
        if not extra:
            return ds
        ds = ds.assign_coords(channel=extra.pop("channel")[1]).assign(extra)
        ds.attrs["headline_channel"] = self.meta["headline"]["channel"]
        return ds


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
    dpi=None,
    z_mm=DEFAULT_Z_MM,
    method: str = "trace",
    ghosts: bool = True,
    fresnel: bool = False,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    window_um: float = WINDOW_UM,
    shift_step_um: float = SHIFT_STEP_UM,
    dof_threshold: float = DOF_THRESHOLD,
    dof_dpi: float | None = None,
    progress: bool = False,
    tracer: PixelTracer | None = None,
    refine: int = 8,
    passes: int = 1,
    shading: bool = True,
    optics: str | Optics = "ray",
) -> RMTFResult:
    """RMTF of paper Eq. 1 for bar charts of the given dpi versus Z, and depth of field.

    Parameters
    ----------
    dpi : chart resolutions; period = 2 * 25.4 mm / dpi; default: the paper's 100, 150,
        200 and 247 dpi scaled to the design's resolution
        (:func:`~opticalstamp.design.resolution.chart_dpis`)
    method : "trace" (exact tracer, own and ghost light) or "paraxial" (own path,
        closed form, rectangular holes; no ghosts, no Fresnel)
    window_um : width of the chart window over which Imax and Imin are taken
    shift_step_um : step of the chart shifts over one period
    dof_threshold, dof_dpi : depth of field = first Z where RMTF(dof_dpi) falls below the
        threshold; default chart: 2/3 of the design's resolution (200 dpi for 300,
        :func:`~opticalstamp.design.resolution.dof_chart_dpi`), added to ``dpi`` in order
        when it is not there
    tracer : a :class:`~opticalstamp.raytrace.pixel.PixelTracer` of this design whose
        pilot runs are reused (analyses of one report share one)
    refine, passes : the threshold crossings (depth of field, its range, spurious
        ranges) are found again with the RMTF at ``refine - 1`` more Z inside each
        interval where a curve crosses, comes near the threshold or jumps
        (:func:`refine_points`; the same rays), ``passes`` rounds (one: steps of 1/32 mm
        on the default grid; a second resolves dips narrower than that); ``refine`` 0 or
        1: on the grid alone
    shading : the merged line shading-corrected, as a scanner delivers it (each pixel
        over its white response); False: the raw merged line (:func:`rmtf_curves`)
    optics : "ray", "wave" or "auto" (or a resolved
        :class:`~opticalstamp.analysis.responsivity.Optics`): which engine gives the
        responsivity (:func:`~opticalstamp.analysis.responsivity.folded_lsf`); the
        result's ``meta["optics"]`` says which one did and why. A colour scanner
        (``electronics.illumination`` "rgb") under wave optics: one RMTF and depth of
        field per channel (``meta["channels"]``), the headline the worst channel's
        (:func:`~opticalstamp.analysis.colour.worst_channel`); the refinement samples
        every channel at the Z that any of them needs
    """
    dpis = sorted({float(d) for d in (chart_dpis(design) if dpi is None else dpi)})
    dof_dpi = float(dof_chart_dpi(design) if dof_dpi is None else dof_dpi)
    if dof_dpi not in dpis:
        dpis = sorted(dpis + [dof_dpi])
    if any(d <= 0 for d in dpis):
        raise ValueError("dpi: every chart resolution must be > 0")
    if window_um <= 0 or shift_step_um <= 0:
        raise ValueError("window_um and shift_step_um must be > 0")
    periods = np.array([period_of_dpi(d) for d in dpis])
    zs = np.asarray(z_mm, dtype=np.float64)
    check_rmtf_memory(design, periods.max(), zs.size, window_um, shift_step_um)
    if method not in ("trace", "paraxial"):
        raise ValueError(f"method must be 'trace' or 'paraxial' (got {method!r})")
    opt = resolve_optics(design, optics, fresnel=fresnel, method=method, channels=True)
    # the stack once per channel, for every Z below ("rgb" under wave optics: three)
    waves = channel_folds(design, opt, float(zs.max()))

    def lsf_at(z: np.ndarray) -> list[FoldedLSF]:
        return list(
            folded_lsf_channels(
                design,
                z_mm=z,
                periods_um=periods,
                waves=waves,
                optics=opt,
                method=method,
                n_rays=n_rays,
                seed=seed,
                ghosts=ghosts,
                fresnel=fresnel,
                progress=progress,
                tracer=tracer,
            ).values()
        )

    res = [
        rmtf_from_lsf(
            lsf,
            design,
            dpi=dpis,
            seed=seed,
            window_um=window_um,
            shift_step_um=shift_step_um,
            dof_threshold=dof_threshold,
            dof_dpi=dof_dpi,
            shading=shading,
            optics=opt,
        )
        for lsf in lsf_at(zs)
    ]
    res = refine_results(res, lsf_at, design, steps=refine, passes=passes)
    if len(res) == 1:
        return res[0]
    return worst_channel(design, dict(zip(waves, res, strict=True)))


def rmtf_from_lsf(
    lsf: FoldedLSF,
    design: Design,
    *,
    dpi,
    seed: int = 0,
    window_um: float = WINDOW_UM,
    shift_step_um: float = SHIFT_STEP_UM,
    dof_threshold: float = DOF_THRESHOLD,
    dof_dpi: float | None = None,
    shading: bool = True,
    optics: Optics = RAY,
) -> RMTFResult:
    """RMTF and depth of field from folded LSFs (periods in the order of ``dpi``) on
    their Z alone (:func:`refine_results` refines the crossings); ``dof_dpi`` default as
    :func:`rmtf`; ``optics``: the engine that gave ``lsf`` (``meta["optics"]``).
    ``meta["fast_light"]``: the fraction of the light whose image moves
    faster than each slope with Z (:func:`~opticalstamp.analysis.lsf.fast_light`), from
    which :func:`crossing_brackets` sets the Z step that resolves the curve."""
    dpis = [float(d) for d in dpi]
    dof_dpi = float(dof_chart_dpi(design) if dof_dpi is None else dof_dpi)
    zs = lsf.z_mm
    cur = rmtf_curves(
        lsf, design, window_um=window_um, shift_step_um=shift_step_um, shading=shading
    )
    keys = [_key(d) for d in dpis]
    pick = {name: {k: cur[name][i].tolist() for i, k in enumerate(keys)} for name in cur}
    res = RMTFResult(
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
        dof_mm={},
        dof_threshold=dof_threshold,
        dof_dpi=dof_dpi,
        window_um=window_um,
        shift_step_um=shift_step_um,
        meta={
            "best_shift_um": pick["best_shift_um"],
            "fast_light": fast_light(lsf),
            # no light reached the pixels: every RMTF is 0 for want of a signal
            "no_light": _no_light(lsf, design),
            "optics": optics.to_dict(),
        },
        shading=shading,
    )
    return _with_crossings(res)


#: Light below this fraction of the pixel's open etendue (sensitive area x pi sr) is no
#: light: the wave engine's filters leave ~1e-12 of it where a stack passes none (a tracer
#: gives exactly 0).
NO_LIGHT = 1e-9


def _no_light(lsf: FoldedLSF, design: Design) -> bool:
    """Whether no light reaches the pixels: the folded light (um^2 sr) of every row at
    every Z (``h``: rows, batches, Z, bins) below NO_LIGHT of the open etendue of the
    sensitive area."""
    s = design.sensor
    scale = NO_LIGHT * s.sensitive_width_um * s.sensitive_height_um * np.pi
    return not any(float(np.max(h.sum(axis=(1, 3)), initial=0.0)) > scale for h in lsf.h)
