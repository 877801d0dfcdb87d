"""Analyses of a rod-lens-array scanner with the stamp's definitions, so numbers compare.

* Light efficiency: etendue one pixel (sensitive area of the design's sensor, a 300-dpi
  square with fill factor 1 in the presets) collects from a uniform Lambertian object,
  averaged over the pixel's position along the array, divided by the paper's F/10 1:1
  reference lens for the same pixel (:func:`.efficiency.reference_etendue`); the
  equivalent working F-number F_ref / sqrt(ratio); the ripple (max - min) / mean of the
  pixel's etendue over one rod period.
* Contrast of bar charts against object height with the stamp's RMTF definition: a line
  of pixels under a chart window reads I_j = sum over its rays of the chart at the ray's
  landing; the contrast (max_j - min_j) / (max_j + min_j) is maximised over the chart's
  shift. Each pixel is shading-corrected (divided by its white level), as every contact
  image sensor does; without it the ripple alone would read as contrast on a blank page.
  Heights are measured from the design's document reference (the cover glass's top,
  i.e. the nominal object plane), positive away from the scanner.
* Depth of field: the heights around the best focus where the 200-dpi contrast stays
  >= 0.3, [low, high], each end at the *first* crossing from the peak (contrast that comes
  back beyond it is spurious resolution, with reversed phase, and is not counted).
* MTF (position-averaged, pixel aperture included) and point PSFs on a rod axis and
  between rods.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..defaults import DOF_THRESHOLD, SHIFT_STEP_UM, WINDOW_UM
from ..design.resolution import chart_dpis, dof_chart_dpi
from ..design.rodlens import RodLensDesign
from ..raytrace.rodlens import RodRays, trace_rods
from ..units import mm_to_um, period_of_dpi
from .efficiency import reference_etendue, reference_f_number
from .rmtf import chart_correlation
from .tallies import FOLD_BIN_UM

#: Rays of the efficiency estimate (about 0.2 % standard error on the presets).
RAYS_EFFICIENCY = 1 << 20
#: Rays of the contrast/LSF trace (a line of pixels under the chart window).
RAYS_CONTRAST = 1 << 21
#: Pixel positions over one rod period for the efficiency and its ripple.
POSITIONS = 32
#: Heights (mm) around the nominal object plane of the contrast table.
HEIGHTS_MM = tuple(np.round(np.arange(-1.0, 1.0001, 0.25), 6))
#: Bisection steps that refine each end of the depth of field between grid heights.
REFINE_STEPS = 10
BATCHES = 8
ESTIMATOR = "trace"  # every rod-lens figure comes from the exact tracer


def _provenance(design: RodLensDesign, rays: RodRays) -> dict:
    return {
        "design": design.name,
        "fingerprint": design.fingerprint(),
        "seed": rays.seed,
        "fresnel": rays.fresnel,
        "estimator": ESTIMATOR,
    }


@dataclass(frozen=True)
class RodResult:
    """What every rod-lens result carries: the design, how it was traced."""

    design: str
    fingerprint: str
    seed: int
    fresnel: bool
    estimator: str
    n_rays: int

    def to_dict(self) -> dict:
        return asdict(self)


# -- light ------------------------------------------------------------------------------
@dataclass(frozen=True)
class RodEfficiency(RodResult):
    etendue_um2sr: float
    etendue_se: float
    reference_etendue_um2sr: float
    reference_f_number: float
    ratio: float
    ratio_se: float
    working_f_number: float
    positions_um: list[float]
    etendue_by_position_um2sr: list[float]
    ripple: float
    ripple_noise: float  # expected (max - min) / mean of pure noise at this ray count
    ledger: dict
    meta: dict = field(default_factory=dict)


def rod_efficiency(
    design: RodLensDesign,
    *,
    n_rays: int = RAYS_EFFICIENCY,
    seed: int = 0,
    fresnel: bool = False,
    positions: int = POSITIONS,
    reference: dict | None = None,
    progress: bool = False,
) -> RodEfficiency:
    """Etendue of one pixel averaged over its position along the array, vs F/10."""
    period = 2 * design.array.rod_radius_um
    pos = (np.arange(positions) + 0.5) * period / positions
    rays = trace_rods(design, pos, n_rays=n_rays, seed=seed, fresnel=fresnel, progress=progress)
    # the array is mirror-symmetric about a rod axis (x -> -x maps each row onto itself
    # modulo the period), so positions u and 2R - u are one: average them
    per_pos = rays.etendue_per_pixel()
    per_pos = 0.5 * (per_pos + per_pos[::-1])
    g = float(per_pos.mean())
    # standard error of the mean of n_rays i.i.d. per-ray contributions (weight or 0)
    s1 = rays.w.sum() / n_rays
    s2 = (rays.w**2).sum() / n_rays
    se = rays.ray_etendue * n_rays * math.sqrt(max(s2 - s1 * s1, 0.0) / n_rays)
    ref = {"pixel_um": design.sensor.pixel_pitch_um} | dict(reference or {})
    g_ref = reference_etendue(**ref)
    f_ref = reference_f_number(ref.get("focal_mm", 10.0), ref.get("pupil_mm", 2.0))
    ratio = g / g_ref
    pos_se = se * math.sqrt(positions / 2) / g  # relative SE of one (mirror-averaged) position
    return RodEfficiency(
        **_provenance(design, rays),
        n_rays=n_rays,
        etendue_um2sr=g,
        etendue_se=se,
        reference_etendue_um2sr=g_ref,
        reference_f_number=f_ref,
        ratio=ratio,
        ratio_se=se / g_ref,
        working_f_number=f_ref / math.sqrt(ratio) if ratio > 0 else math.inf,
        positions_um=pos.tolist(),
        etendue_by_position_um2sr=per_pos.tolist(),
        ripple=float((per_pos.max() - per_pos.min()) / g) if g > 0 else 0.0,
        ripple_noise=_range_of_normals(positions // 2) * pos_se,
        ledger=rays.ledger,
        meta={"reference_lens": {"focal_mm": 10.0, "pupil_mm": 2.0, "conjugate_mm": 20.0} | ref},
    )


def _range_of_normals(n: int) -> float:
    """Expected range of n standard normal samples (Monte Carlo-free approximation)."""
    if n < 2:
        return 0.0
    from scipy.special import ndtri  # the normal quantile: scipy.stats costs ~1 s to import

    q = ndtri((n - 0.375) / (n + 0.25))  # Blom's approximation of the top order statistic
    return float(2 * q)


# -- contrast, MTF and depth of field ------------------------------------------------------
@dataclass(frozen=True)
class RodContrast(RodResult):
    dpi: list[float]
    heights_mm: list[float]
    contrast: list[list[float]]  # (dpi, height): shading-corrected RMTF
    contrast_se: list[list[float]]
    mtf: list[list[float]]  # (dpi, height): MTF at the chart's fundamental
    dof_mm: dict  # low, high, span (relative to the nominal object plane), clipped flags
    dof_threshold: float
    dof_dpi: float
    window_um: float
    lsf_x_um: list[float]
    lsf: list[list[float]]  # (height, x): position-averaged LSF, normalised to area 1
    meta: dict = field(default_factory=dict)


class _Line:
    """A line of pixels under the chart window and its traced rays (folded on demand)."""

    def __init__(self, design: RodLensDesign, rays: RodRays, batches: int):
        self.design = design
        self.rays = rays
        self.x = rays.pixel_x_um
        self.pix = rays.pixel
        self.batch = (rays.ids // self.x.size) % batches
        self.batches = batches
        white = np.bincount(self.pix, weights=rays.w, minlength=self.x.size)
        self.norm = rays.w / np.where(white > 0, white, 1.0)[self.pix]  # shading correction
        self._landing: dict[float, np.ndarray] = {}

    def landing(self, height_mm: float) -> np.ndarray:
        """Landing offsets from each ray's pixel centre on the plane at ``height_mm``."""
        key = float(height_mm)
        if key not in self._landing:
            x = self.rays.landing_x(mm_to_um(key), self.design.glass_index)
            self._landing = {key: x - self.x[self.pix]}  # keep one height: bounded memory
        return self._landing[key]

    def folded(self, height_mm: float, period_um: float) -> np.ndarray:
        """(batches, pixels, bins) shading-corrected LSFs folded modulo the period."""
        nb = max(8, round(period_um / FOLD_BIN_UM))
        phi = np.mod(self.landing(height_mm), period_um)
        b = np.minimum((phi / period_um * nb).astype(np.int64), nb - 1)
        npx = self.x.size
        idx = (self.batch * npx + self.pix) * nb + b
        h = np.bincount(idx, weights=self.norm, minlength=self.batches * npx * nb)
        return h.reshape(self.batches, npx, nb)

    def contrast(self, height_mm: float, period_um: float, shift_step_um: float):
        """(contrast, standard error, MTF) of the line for one period at one height.

        The MTF is the fundamental of the folded LSFs (bins of FOLD_BIN_UM: a sinc
        factor 1 - 1e-5 at 100 dpi), averaged over the pixels.
        """
        h = self.folded(height_mm, period_um)
        nb = h.shape[-1]
        shifts = np.arange(0.0, period_um, shift_step_um)
        v = np.mod(self.x[None, :] - shifts[:, None], period_um) / period_um * nb
        c_batch = chart_correlation(h * self.batches)  # each batch scaled to a full estimate
        full = _line_contrast(c_batch.mean(axis=0), v)
        best = int(full.argmax())
        per_batch = _line_contrast(c_batch, v[best : best + 1])[..., 0]
        hs = h.sum(axis=0)
        first = np.fft.rfft(hs, axis=-1)[:, 1]
        mtf = float(abs(first.sum()) / hs.sum())
        return float(full[best]), float(per_batch.std(ddof=1) / math.sqrt(self.batches)), mtf

    def lsf(self, height_mm: float, edges_um: np.ndarray) -> np.ndarray:
        h, _ = np.histogram(self.landing(height_mm), bins=edges_um, weights=self.norm)
        return h / (self.norm.sum() * np.diff(edges_um))


def _line_contrast(c: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Contrast of the line per shift: c (..., pixels, bins) correlations, v (shifts, pixels).

    Returns (..., shifts).
    """
    nb = c.shape[-1]
    i0 = np.floor(v).astype(np.int64)
    t = v - i0
    j = np.arange(c.shape[-2])[None, :]
    sig = c[..., j, i0 % nb] * (1 - t) + c[..., j, (i0 + 1) % nb] * t
    hi, lo = sig.max(axis=-1), sig.min(axis=-1)
    return np.where(hi + lo > 0, (hi - lo) / np.where(hi + lo > 0, hi + lo, 1.0), 0.0)


def first_crossings(
    heights: np.ndarray, values: np.ndarray, threshold: float, refine
) -> tuple[float, float, bool, bool]:
    """Ends of the interval around the peak where ``values`` >= threshold.

    Each end is the first crossing walking out from the peak, refined by ``refine(a, b)``
    (a bracket with values above/below); an end beyond the grid is the grid's end,
    flagged clipped. (nan, nan) when the peak itself is below the threshold.
    """
    k = int(np.argmax(values))
    if values[k] < threshold:
        return math.nan, math.nan, False, False
    ends, clipped = [], []
    for step in (-1, 1):
        i = k
        while 0 <= i + step < heights.size and values[i + step] >= threshold:
            i += step
        if 0 <= i + step < heights.size:
            ends.append(refine(heights[i], heights[i + step]))
            clipped.append(False)
        else:
            ends.append(float(heights[i]))
            clipped.append(True)
    return ends[0], ends[1], clipped[0], clipped[1]


def rod_contrast(
    design: RodLensDesign,
    *,
    dpi=None,
    heights_mm=HEIGHTS_MM,
    n_rays: int = RAYS_CONTRAST,
    seed: int = 0,
    fresnel: bool = False,
    window_um: float = WINDOW_UM,
    shift_step_um: float = SHIFT_STEP_UM,
    threshold: float = DOF_THRESHOLD,
    dof_dpi: float | None = None,
    lsf_half_um: float | None = None,
    progress: bool = False,
) -> RodContrast:
    """Contrast and MTF of bar charts against height, the depth of field and the LSF.

    ``dpi``, ``dof_dpi``: the charts and the depth-of-field chart; default, as for a
    stamp, the paper's charts scaled to the array's resolution and 2/3 of it
    (:mod:`opticalstamp.design.resolution`)."""
    pitch = design.sensor.pixel_pitch_um
    x = np.arange(0.0, window_um, pitch)
    rays = trace_rods(design, x, n_rays=n_rays, seed=seed, fresnel=fresnel, progress=progress)
    line = _Line(design, rays, BATCHES)
    hs = np.asarray(heights_mm, dtype=np.float64)
    dpis = [float(d) for d in (chart_dpis(design) if dpi is None else dpi)]
    dof_dpi = float(dof_chart_dpi(design) if dof_dpi is None else dof_dpi)
    con = np.zeros((len(dpis), hs.size))
    se = np.zeros_like(con)
    mtf = np.zeros_like(con)
    dof_per = period_of_dpi(dof_dpi)
    dof_curve = np.zeros(hs.size)
    for j, h in enumerate(hs):  # heights outer: one landing computation per height
        for i, d in enumerate(dpis):
            con[i, j], se[i, j], mtf[i, j] = line.contrast(
                float(h), period_of_dpi(d), shift_step_um
            )
        k = dpis.index(float(dof_dpi)) if float(dof_dpi) in dpis else None
        dof_curve[j] = (
            con[k, j] if k is not None else line.contrast(float(h), dof_per, shift_step_um)[0]
        )

    def refine(a: float, b: float) -> float:  # a above, b below the threshold
        for _ in range(REFINE_STEPS):
            m = 0.5 * (a + b)
            if line.contrast(m, dof_per, shift_step_um)[0] >= threshold:
                a = m
            else:
                b = m
        return 0.5 * (a + b)

    lo, hi, clip_lo, clip_hi = first_crossings(hs, dof_curve, threshold, refine)
    lo, hi = float(lo), float(hi)
    # the pixel and the defocus blur (NA per unit height) at the farthest height
    half = lsf_half_um or 3 * pitch + design.array.na * mm_to_um(float(np.abs(hs).max()))
    edges = np.arange(-half, half + 1e-9, 2.0)
    lsf = [line.lsf(float(h), edges).tolist() for h in hs]
    return RodContrast(
        **_provenance(design, rays),
        n_rays=n_rays,
        dpi=dpis,
        heights_mm=hs.tolist(),
        contrast=con.tolist(),
        contrast_se=se.tolist(),
        mtf=mtf.tolist(),
        dof_mm={
            "low": lo,
            "high": hi,
            "span": hi - lo,
            "clipped_low": clip_lo,
            "clipped_high": clip_hi,
            "usable_from_reference": max(hi, 0.0) - max(lo, 0.0) if math.isfinite(hi) else 0.0,
        },
        dof_threshold=threshold,
        dof_dpi=dof_dpi,
        window_um=window_um,
        lsf_x_um=(0.5 * (edges[1:] + edges[:-1])).tolist(),
        lsf=lsf,
        meta={"shading_corrected": True, "pixels": int(x.size)},
    )


# -- point PSF ----------------------------------------------------------------------------
def psf_positions(design: RodLensDesign) -> dict[str, float]:
    """x of a point on a rod axis and of one between rods (the middle of a gap)."""
    r = design.array.rod_radius_um
    between = r if design.array.rows == 1 else r / 2  # two rows: axes at 0 and R alternate
    return {"axis": 0.0, "between": between}


def rod_psf(
    design: RodLensDesign,
    *,
    heights_mm=(0.0, 0.5),
    n_rays: int = 1 << 20,
    seed: int = 0,
    half_um: float | None = None,
    bin_um: float = 5.0,
) -> dict:
    """Where light from a point on the sensor lands on planes above the reference.

    By reciprocity this is the point-spread function of an object point at that place.
    Returns per position ("axis", "between") and height a 2-D histogram (fraction of
    the traced power per bin) with its edges, the centroid and the rms radius.
    """
    half = half_um or design.array.view_radius_um
    edges = np.arange(-half, half + 1e-9, bin_um)
    out: dict = {"x_edges_um": edges.tolist(), "heights_mm": list(heights_mm), "at": {}}
    for name, x0 in psf_positions(design).items():
        rays = trace_rods(design, [x0], n_rays=n_rays, seed=seed, point=True)
        per_h = []
        for h in heights_mm:
            xs = rays.landing_x(mm_to_um(h), design.glass_index) - x0
            ys = rays.landing_y(mm_to_um(h), design.glass_index)
            img, _, _ = np.histogram2d(ys, xs, bins=(edges, edges), weights=rays.w)
            tot = rays.w.sum()
            cx = float(np.sum(rays.w * xs) / tot) if tot > 0 else math.nan
            rms = (
                float(np.sqrt(np.sum(rays.w * ((xs - cx) ** 2 + ys**2)) / tot)) if tot else math.nan
            )
            per_h.append(
                {"image": (img / max(tot, 1e-300)).tolist(), "centroid_x_um": cx, "rms_um": rms}
            )
        out["at"][name] = {"x_um": x0, "by_height": per_h, "through": rays.ledger["through"]}
    return out
