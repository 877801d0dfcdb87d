"""Scan simulation: from a document (linear reflectance) to the scanner's output image.

Geometry (paper §4, Figs. 3, 8, 9, 12). The document moves along y by one line pitch L
(84.6 um for the staggered 300-dpi prototype) per line period. Line m is exposed around
the document position y_m = (m + 1/2) L (1 + speed error) (+ jitter); a pixel at sensor
height s_row sees document point y = y_m - s_row + Y, so row B (s = 84.6 um) sees each
document line one line period later than row A; the scanner merges row A's line m with
row B's line m + d, d = s_B / L (paper §4). Columns: row A's pixels at x = k p + L/2,
row B's at x = b_x + k p + L/2; merged, they form the 300-dpi columns (c + 1/2) L.

Optics. A pixel's signal is the document's reflectance weighted by its responsivity map
at the local Z (:mod:`opticalstamp.kernels`): the own path as separable terms applied as
two sparse matrix products (along y, then x), exact for a document that is uniform within
its pixels; motion smear averages the y factor over the exposure; ghost light is a coarse
map convolved with the block-averaged document (FFT). Outside the document the
reflectance is ``surround``. A height map is handled by computing kernels at levels
``z_step_mm`` apart and blending each pixel's signals linearly in its local Z.

Then illumination along x, photon and sensor noise (:mod:`opticalstamp.sensor`), dark and
white calibration scans (mean of ``calibration_lines`` lines of a black and a white page at
``calibration_z_mm``) and shading correction (raw - dark) / (white - dark).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator
from scipy import ndimage

from ..defaults import RAYS_MAP
from ..design import AnyDesign, Design
from ..design.electronics import LUMA
from ..raytrace.launch import progress_bar
from ..raytrace.pixel import PixelTracer
from ..units import dpi_of_pitch, pitch_of_dpi
from ..validate import check_seed
from .convolve import fft_convolve
from .heightmap import check_heights
from .heightmap import sample as sample_height
from .kernels import KernelCache, ScanKernel, kernel_cache, scan_kernels
from .kinds import PixelGroup, scanner_of
from .sensor import SensorModel, expose, fixed_pattern, signal_budget
from .separable import box_taps, inside, x_pass, y_pass

Illumination = Literal["uniform", "ripple"]
Kernel = Literal["auto", "paraxial", "trace", "wave"]
#: the choices of ScanSettings.illumination and .kernel
ILLUMINATIONS: tuple[str, ...] = get_args(Illumination)
KERNELS: tuple[str, ...] = get_args(Kernel)


class ScanSettings(BaseModel):
    """Everything about a scan except the document, the design and the height."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    sensor: SensorModel = SensorModel()
    illumination: Illumination = "uniform"
    ripple_amplitude: float = Field(0.05, ge=0, lt=1)  # relative, light-guide ripple
    ripple_period_mm: float = Field(8.0, gt=0)  # LED spacing along the light guide
    illumination_profile: tuple[tuple[float, float], ...] | None = None  # (x_mm, rel)
    speed_error: float = Field(0.0, gt=-0.5, lt=0.5)  # relative scan-speed error
    speed_jitter: float = Field(0.0, ge=0, lt=0.5)  # relative rms per line
    # reflectance outside the document: white, a page under a scanner lid (0: an open lid)
    surround: float = Field(1.0, ge=0, le=1)
    z_step_mm: float = Field(0.25, gt=0, le=2)
    calibration_z_mm: float = Field(0.0, ge=0, le=10)
    calibration_lines: int = Field(32, ge=1, le=4096)
    white_reference: float = Field(1.0, gt=0, le=1)
    kernel: Kernel = "auto"
    kernel_rays: int = Field(RAYS_MAP, ge=1 << 14, le=1 << 30)
    fresnel: bool = False  # Fresnel transmission losses in the traced kernels

    @field_validator("illumination_profile")
    @classmethod
    def _profile(cls, rows):
        """A profile of light along x: two points or more, x increasing, every value
        finite, the relative light >= 0 and positive somewhere (a lamp that lights
        nothing gives no signal: its shading correction would divide by nothing)."""
        if rows is None:
            return rows
        arr = np.asarray(rows, dtype=np.float64).reshape(-1, 2)
        if arr.shape[0] < 2:
            raise ValueError(f"needs two rows x_mm,relative or more (got {arr.shape[0]})")
        if not np.all(np.isfinite(arr)):
            raise ValueError("every x_mm and relative value must be a finite number")
        if np.any(np.diff(arr[:, 0]) <= 0):
            raise ValueError("x_mm must increase from row to row")
        if np.any(arr[:, 1] < 0):
            raise ValueError(f"relative light must be >= 0 (got {arr[:, 1].min():g})")
        if not np.any(arr[:, 1] > 0):
            raise ValueError(
                "relative light is 0 everywhere: a profile must be positive somewhere (a "
                "lamp that lights nothing gives no image to correct)"
            )
        return rows


@dataclass(frozen=True)
class ScanResult:
    """A simulated scan: the corrected output, the raw rows and their bookkeeping."""

    image: np.ndarray  # [line, column] or [line, column, channel], shading corrected
    dpi: float  # output resolution (x and y)
    pitch_um: float
    raw: list[np.ndarray]  # per row: [line, pixel] or [line, pixel, channel], DN
    dark: list[np.ndarray]  # per row: [pixel] or [pixel, channel]
    white: list[np.ndarray]
    row_delay_lines: int
    z_levels_mm: list[float]
    meta: dict = field(default_factory=dict)


def _illumination(settings: ScanSettings, x_um: np.ndarray) -> np.ndarray:
    if settings.illumination_profile:
        xs, vs = zip(*settings.illumination_profile, strict=True)
        return np.interp(x_um / 1000.0, xs, vs)
    if settings.illumination == "ripple":
        return 1 + settings.ripple_amplitude * np.cos(
            2 * np.pi * x_um / (settings.ripple_period_mm * 1000.0)
        )
    return np.ones_like(x_um)


def _taps(
    kern: ScanKernel,
    axis: int,
    centers: np.ndarray,
    p: float,
    smear: float = 0.0,
    sign: float = 1.0,
):
    """Tap tables (i0, w (K, n, taps)) of every factor at the sample centres.

    Axis 0 (y): Y = centre - y (the document moves past the pixel), averaged over the
    motion ``smear``; axis 1 (x): X = x - centre.
    """
    reach = kern.half_um + smear / 2 + p
    i0 = np.floor((centers - reach) / p).astype(np.int64)
    n_taps = int(np.ceil(2 * reach / p)) + 2
    pos = (i0[:, None] + np.arange(n_taps)[None, :] + 0.5) * p  # pixel centres
    # the box of the motion, by the midpoint rule on 9 sub-positions
    subs = ((np.arange(9) + 0.5) / 9 - 0.5) * smear if smear > 0 else np.zeros(1)
    w = np.zeros((kern.scale.size,) + pos.shape)
    for sub in subs:
        off = (centers[:, None] + sub - pos) if axis == 0 else (pos - centers[:, None])
        w += kern.weights(axis, off.ravel(), p).reshape(w.shape)
    return i0, w / subs.size


def _own_signal(doc: np.ndarray, kern: ScanKernel, centers, x_pix, p, smear, surround):
    """Own-path signal (um^2 sr x reflectance) at [center, pixel]."""
    iy, wy = _taps(kern, 0, centers, p, smear)
    ix, wx = _taps(kern, 1, x_pix, p)
    out = np.zeros((centers.size, x_pix.size))
    for k in range(kern.scale.size):
        out += kern.scale[k] * x_pass(y_pass(doc, iy, wy[k]), ix, wx[k])
        if surround:
            fy = inside(iy, wy[k], doc.shape[0])
            fx = inside(ix, wx[k], doc.shape[1])
            total = kern.cum_y[k, -1] * kern.cum_x[k, -1]
            out += surround * kern.scale[k] * (total - np.outer(fy, fx))
    return out


def _block_mean(doc: np.ndarray, p: float, b: float, pad: tuple[int, int], surround: float):
    """Document averaged over b x b um cells, padded by pad cells of ``surround``."""
    ny = int(np.ceil(doc.shape[0] * p / b))
    nx = int(np.ceil(doc.shape[1] * p / b))
    iy, wy = box_taps((np.arange(ny) + 0.5) * b, b, p)
    ix, wx = box_taps((np.arange(nx) + 0.5) * b, b, p)
    mean = x_pass(y_pass(doc, iy, wy), ix, wx)
    # the part of a border cell beyond the page has the surround's reflectance
    frac = np.outer(inside(iy, wy, doc.shape[0]), inside(ix, wx, doc.shape[1]))
    mean = mean + surround * (1 - frac)
    return np.pad(mean, ((pad[0], pad[0]), (pad[1], pad[1])), constant_values=surround)


def _ghost_signal(blocks: np.ndarray, kern: ScanKernel, centers, x_pix, surround):
    """Ghost signal from the padded block-averaged document (see :func:`_block_mean`)."""
    g = kern.ghost
    b = kern.ghost_bin_um
    ny, nx = g.shape
    r = fft_convolve(blocks, g[:, ::-1], mode="full")
    y0, x0 = kern.ghost_lo_um
    # F[i, j] = sum G[a, e] D[i - a, j + e] lives in r[i, j + nx - 1]; D cell i is centred
    # at (i - pad + 1/2) b on the page
    iy = (centers - y0 - 0.5 * b) / b + ny - 0.5
    jx = (x_pix + x0 + 0.5 * b) / b + nx - 0.5 + nx - 1
    yy, xx = np.meshgrid(iy, jx, indexing="ij")
    return ndimage.map_coordinates(r, [yy, xx], order=1, mode="constant", cval=surround * g.sum())


def scan_pitch(design: AnyDesign) -> float:
    """Output pixel pitch (um) of a scan: the merged pitch of a stamp, a rod-lens array's
    sensor pitch."""
    return scanner_of(design).pitch(design)


def pixel_groups(design: AnyDesign, n_cols: int) -> list[PixelGroup]:
    """The output columns (c + 1/2) pitch, c < n_cols, grouped by the kernel they use.

    A stamp: its rows of used pixels (row B delayed by row offset / pitch lines). A
    rod-lens array: its pixels' phase classes on the rod lattice (one sensor row);
    classes without a pixel are left out.
    """
    return scanner_of(design).groups(design, n_cols)


def scan_levels(z_mm: float | None, height_map: np.ndarray | None, z_step_mm: float) -> list[float]:
    """The distances (mm) whose kernels a scan needs: ``z_mm``, or for a height map every
    multiple of ``z_step_mm`` from below its lowest to above its highest point."""
    if height_map is None:
        return [float(z_mm)]
    hm = np.asarray(height_map)
    lo = np.floor(hm.min() / z_step_mm) * z_step_mm
    hi = np.ceil(hm.max() / z_step_mm) * z_step_mm
    return [float(v) for v in np.round(np.arange(lo, hi + z_step_mm / 2, z_step_mm), 6)]


def prepare_kernels(
    design: Design,
    *,
    z_mm=(),
    height_maps=(),
    settings: ScanSettings | None = None,
    seed: int = 0,
    ghosts: bool = True,
    progress: bool = False,
    tracer: PixelTracer | None = None,
) -> KernelCache:
    """Kernels for several scans of one design, built once (pass them as ``kernels=``).

    Parameters
    ----------
    design : Design
    z_mm : constant float heights (mm) of the scans to come
    height_maps : height maps (mm) of the scans to come
    settings : ScanSettings of those scans (kernel source, rays, Fresnel, Z step)
    seed : their seed
    ghosts : whether any of them needs ghost light (a cache with it serves scans
        without it too)
    tracer : a PixelTracer of this design whose pilot runs to reuse

    Returns
    -------
    KernelCache
        Each scan gets bit for bit the kernels it would have built itself.
    """
    check_seed(seed)
    st = settings or ScanSettings()
    sets = []
    for z in z_mm:
        check_heights(z, None)
        sets.append(scan_levels(z, None, st.z_step_mm))
    for hm in height_maps:
        check_heights(None, hm)
        sets.append(scan_levels(None, hm, st.z_step_mm))
    return kernel_cache(
        design,
        sets,
        source=st.kernel,
        ghosts=ghosts,
        fresnel=st.fresnel,
        n_rays=st.kernel_rays,
        seed=seed,
        progress=progress,
        tracer=tracer,
    )


def kernels_for(
    design: AnyDesign,
    levels,
    settings: ScanSettings,
    *,
    seed: int,
    ghosts: bool = True,
    kernels: KernelCache | None = None,
    progress: bool = False,
) -> list[list[ScanKernel]]:
    """The scan kernels [row][level] at ``levels`` for ``settings`` (kernel source, rays,
    Fresnel) and ``seed``: looked up in ``kernels`` (built beforehand by
    :func:`prepare_kernels`; ValueError where they do not fit) or built here."""
    how = {
        "source": settings.kernel,
        "ghosts": ghosts,
        "n_rays": settings.kernel_rays,
        "seed": seed,
        "fresnel": settings.fresnel,
    }
    if kernels is None:
        return scan_kernels(design, levels, progress=progress, **how)
    return kernels.lookup(design, levels, **how)


def simulate_scan(
    doc: np.ndarray,
    doc_dpi: float,
    design: Design,
    *,
    z_mm: float | None = 1.0,
    height_map: np.ndarray | None = None,
    settings: ScanSettings | None = None,
    seed: int = 0,
    ghosts: bool = True,
    noiseless: bool = False,
    color: bool = False,
    progress: bool = False,
    kernels: KernelCache | None = None,
) -> ScanResult:
    """Simulate the scanner's output for a document at a float height (or height map).

    Parameters
    ----------
    doc : [y, x] or [y, x, 3] linear reflectance in [0, 1]
    doc_dpi : the document's sampling (dpi)
    z_mm : constant float height (mm above the reference plane), or None with height_map
    height_map : [y, x] heights (mm) covering the page (any resolution, page aspect)
    color : the three LEDs lit in turn (sequential R, G, B lines); with wave kernels a
        colour scanner's (``illumination = "rgb"``) channels each take their LED's own
        kernels (:func:`led_designs`), any other design one kernel set for all three
    kernels : kernels built beforehand for this scan's levels and settings
        (:func:`prepare_kernels`); None builds them here. Either way the result is the
        same; a cache that does not fit raises ValueError.
    """
    check_seed(seed)
    st = settings or ScanSettings()
    doc = np.asarray(doc, dtype=np.float32)
    if doc.ndim == 2:
        doc = doc[..., None]
    if doc.ndim != 3 or doc.shape[2] not in (1, 3) or min(doc.shape[:2]) < 2:
        raise ValueError(f"document must be [y, x] or [y, x, 3] (got shape {doc.shape})")
    if not 10 <= doc_dpi <= 20_000:
        raise ValueError(f"document dpi must lie in [10, 20000] (got {doc_dpi})")
    if color and doc.shape[2] == 1:
        doc = np.repeat(doc, 3, axis=2)
    if not color and doc.shape[2] == 3:
        doc = (doc @ np.array(LUMA, np.float32))[..., None]
    check_heights(None if height_map is not None else z_mm, height_map)
    p = pitch_of_dpi(doc_dpi)
    h_um, w_um = doc.shape[0] * p, doc.shape[1] * p
    pitch = scan_pitch(design)
    n_lines = int(np.floor(h_um / pitch))
    n_cols = int(np.floor(w_um / pitch))
    if n_lines < 1 or n_cols < 1:
        raise ValueError("document smaller than one output pixel")
    groups = pixel_groups(design, n_cols)
    delay = max(g.delay for g in groups)
    rng_lines = np.random.default_rng([seed, 7])
    step = (
        pitch
        * (1 + st.speed_error)
        * (1 + st.speed_jitter * rng_lines.standard_normal(n_lines + delay))
    )
    y_line = np.cumsum(step) - step / 2
    levels = scan_levels(z_mm, height_map, st.z_step_mm)
    # a colour scanner's colour scan through wave kernels: each LED's own (led_designs)
    leds = led_designs(design) if color and st.kernel == "wave" else None
    by_ch = [
        kernels_for(d, levels, st, seed=seed, ghosts=ghosts, kernels=kernels, progress=progress)
        for d in (leds or [design])
    ]
    by_ch = [[k[g.kernel] for g in groups] for k in by_ch]
    kern = by_ch[0]
    n_rows = len(groups)
    n_ch = doc.shape[2]
    duty = st.sensor.exposure_duty
    smear = duty * pitch / (3 if color else 1)
    e_per = st.sensor.electrons_per_um2sr
    raw, darks, whites, pix_x = [], [], [], []
    jobs = [(r, c) for r in range(n_rows) for c in range(n_ch)]
    jobs = progress_bar(jobs, desc="scan", unit="row-channel", progress=progress)
    by_row: dict[int, list] = {r: [None] * n_ch for r in range(n_rows)}
    blocks: dict[int, np.ndarray] = {}
    for r, ch in jobs:
        x_pix, row_y = groups[r].x_um, groups[r].y_um
        n_l = n_lines + groups[r].delay
        centers = y_line[:n_l] - row_y
        if color:
            centers = centers + (ch - 1) * pitch / 3
        z_loc = None
        if height_map is not None:
            z_loc = sample_height(
                np.asarray(height_map), h_um / 1000, w_um / 1000, centers + row_y, x_pix
            )
        sig = np.zeros((n_l, x_pix.size))
        k_row = by_ch[ch if leds else 0][r]  # this channel's LED's (one light: the same)
        for il, zl in enumerate(levels):
            kr = k_row[il]
            if z_loc is None:
                sel, wts = np.arange(n_l), None
            else:
                wts = np.clip(1 - np.abs(z_loc - zl) / st.z_step_mm, 0, 1)
                sel = np.flatnonzero(wts.max(axis=1) > 0)
                if sel.size == 0:
                    continue
            s = _own_signal(doc[..., ch], kr, centers[sel], x_pix, p, smear, st.surround)
            if kr.ghost is not None:
                if ch not in blocks:  # the same cells for every row and level
                    blocks[ch] = _block_mean(
                        doc[..., ch], p, kr.ghost_bin_um, kr.ghost.shape, st.surround
                    )
                s += _ghost_signal(blocks[ch], kr, centers[sel], x_pix, st.surround)
            sig[sel] += s if wts is None else s * wts[sel]
        gain = e_per * _illumination(st, x_pix) * (st.sensor.channel_response[ch] if color else 1.0)
        s_white = st.white_reference * (k_row[0].own_etendue + k_row[0].ghost_etendue)
        by_row[r][ch] = (sig * gain, s_white * gain)
        if ch == 0:
            pix_x.append(x_pix)
    for r in range(n_rows):
        pattern = fixed_pattern(
            st.sensor, by_row[r][0][0].shape[1], np.random.default_rng([seed, r, 99])
        )
        chans, dk, wh = [], [], []
        for ch in range(n_ch):
            mean_e, white_e = by_row[r][ch]
            rng = None if noiseless else np.random.default_rng([seed, r, ch, 1])
            rng_c = None if noiseless else np.random.default_rng([seed, r, ch, 2])
            n_cal = 1 if noiseless else st.calibration_lines
            w_cal = np.broadcast_to(white_e, (n_cal, white_e.size))
            chans.append(expose(mean_e, st.sensor, pattern, rng))
            wh.append(expose(w_cal, st.sensor, pattern, rng_c).mean(axis=0))
            dk.append(expose(np.zeros_like(w_cal), st.sensor, pattern, rng_c).mean(axis=0))
        raw.append(np.stack(chans, axis=-1))
        darks.append(np.stack(dk, axis=-1))
        whites.append(np.stack(wh, axis=-1))
    corrected = [
        (raw[r] - darks[r][None]) / np.maximum(whites[r] - darks[r], 1e-9)[None]
        for r in range(n_rows)
    ]
    image = merge_rows(corrected, pix_x, [g.delay for g in groups], n_lines)
    if not color:
        image = image[..., 0]
        raw = [a[..., 0] for a in raw]
        darks = [a[..., 0] for a in darks]
        whites = [a[..., 0] for a in whites]
    return ScanResult(
        image=image,
        dpi=dpi_of_pitch(pitch),
        pitch_um=pitch,
        raw=raw,
        dark=darks,
        white=whites,
        row_delay_lines=delay,
        z_levels_mm=levels,
        meta={
            "design": design.name,
            "design_fingerprint": design.fingerprint(),
            "seed": seed,
            "z_mm": None if height_map is not None else z_mm,
            "height_map": height_map is not None,
            "ghosts": ghosts,
            "noiseless": noiseless,
            "color": color,
            "document_dpi": doc_dpi,
            "settings": st.model_dump(mode="json"),
            "kernel_source": st.kernel,
            # a pixel's signal and noise budget at the first level (mean over pixel groups)
            "signal": signal_budget(
                st.sensor,
                st.white_reference
                * float(np.mean([k[0].own_etendue + k[0].ghost_etendue for k in kern])),
            ),
        },
    )


def led_designs(design: AnyDesign) -> list[Design] | None:
    """A colour scanner's design as each LED lights it, red, green, blue (the order of a
    colour document's channels), for its colour scans through wave kernels: the design
    with that LED as its illumination, at the LED's mean wavelength where its media
    disperse (:func:`~opticalstamp.analysis.colour.channel_designs`: the light beyond the
    wave band traced there); None for any other design (one light for every channel)."""
    if getattr(getattr(design, "electronics", None), "illumination", None) != "rgb":
        return None
    from ..analysis.colour import channel_designs
    from ..analysis.spectrum import CHANNELS
    from ..design.variants import replace as vary

    per = channel_designs(design)
    return [vary(per[c], {"electronics.illumination": c}) for c in CHANNELS["rgb"]]


def merge_rows(
    rows: list[np.ndarray], x_pix: list[np.ndarray], delays: list[int], n_lines: int
) -> np.ndarray:
    """Merge the pixel groups into one image: group g's line m + delays[g] goes with line m
    (the stamp's row B, paper §4: delay = row offset / line pitch); columns are ordered by
    the pixels' x."""
    parts = [r[d : d + n_lines] for r, d in zip(rows, delays, strict=True)]
    x = np.concatenate(x_pix)
    order = np.argsort(x, kind="stable")
    return np.concatenate(parts, axis=1)[:, order]
