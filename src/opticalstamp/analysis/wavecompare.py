"""Ray against wave: one design's light, spot and RMTF by the tracer and the wave engine.

The wave engine (:mod:`.wave`, separable paraxial path) carries the light whose
invariant direction lies in its band, |s_x|, |s_y| < B: the own path and the near
crosstalk through neighbouring holes. The ray figures compared with it are the tracer's
rays in the same band (own path and near ghosts; s is conserved through the stack, so
the band is the same test at every plane), and the own path's exact etendue
(:func:`~opticalstamp.analysis.own_etendue.own_etendue`) for reference. Both sides give,
at each Z: the light (um^2 sr), the FWHM of the x line-spread function, the share of the
light in the central output cell, and the RMTF on the design's depth-of-field chart
(:func:`~opticalstamp.design.resolution.dof_chart_dpi`) from the LSFs of rows A and B
folded onto its period (:func:`~opticalstamp.analysis.rmtf.rmtf_curves`, shading
corrected, max over chart shifts).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ..defaults import RAYS_LSF
from ..design import Design
from ..design.resolution import dof_chart_dpi
from ..raytrace.pixel import PixelTracer, Sampling, tracer_for
from ..raytrace.stack import lattice_of, output_pitch
from ..units import period_of_dpi
from .lsf import FoldedLSF
from .own_etendue import own_etendue, rectangular_holes
from .rmtf import rmtf_curves
from .spectrum import Spectrum, one_channel
from .tallies import FOLD_BIN_UM
from .wave import stack_reach
from .wavebase import WaveSampling, fresnel_numbers, fwhm_of, wave_sampling
from .wavespectral import (
    SpectralLSFSource,
    at_wavelength,
    mirror_twin,
    response_at,
    spectral_samplings,
    wave_response_spectral,
)

#: bin of the traced line-spread functions (um)
RAY_BIN_UM = 1.0


def fold(x_um: np.ndarray, lsf: np.ndarray, period_um: float, n_bins: int) -> np.ndarray:
    """LSF samples (um sr per um) on the uniform grid ``x_um`` (from the pixel's axis)
    folded modulo ``period_um`` into ``n_bins`` equal bins of phase: (n_bins,) um^2 sr.
    Each bin's integral is exact for the piecewise-linear interpolant (cumulative
    trapezoid at the bin edges), so no sample is snapped to a bin."""
    dx = x_um[1] - x_um[0]
    c = np.concatenate([[0.0], np.cumsum((lsf[1:] + lsf[:-1]) / 2) * dx])
    step = period_um / n_bins
    k0 = int(np.floor(x_um[0] / step))
    k1 = int(np.ceil(x_um[-1] / step))
    edges = np.arange(k0, k1 + 1) * step
    pos = np.clip((edges - x_um[0]) / dx, 0, x_um.size - 1)
    i0 = np.clip(np.floor(pos).astype(int), 0, x_um.size - 2)
    t = pos - i0
    ce = c[i0] * (1 - t) + c[i0 + 1] * t
    out = np.zeros(n_bins)
    np.add.at(out, np.arange(k0, k1) % n_bins, np.diff(ce))
    return out


def _n_bins(period_um: float) -> int:
    return max(8, int(round(period_um / FOLD_BIN_UM)))


@dataclass(frozen=True)
class RayInBand:
    """The tracer's light in the band, one pixel: light (um^2 sr) own / near ghost / all
    traced, and per Z the x line-spread function on ``x_um`` bins, the centre-cell
    share and the LSF folded onto ``period_um``."""

    band: float
    own_um2sr: float
    near_um2sr: float
    traced_um2sr: float
    x_um: np.ndarray
    lsf_x: np.ndarray  # (nz, nx) um sr per um
    center_cell_fraction: np.ndarray
    folded: np.ndarray  # (nz, n_bins)


def ray_in_band(
    design: Design,
    z_mm,
    band: float,
    *,
    pixel: tuple[int, int] = (0, 0),
    period_um: float,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    cell_um: float | None = None,
    tracer: PixelTracer | None = None,
    fresnel: bool = False,
) -> RayInBand:
    """Tally a pixel's traced rays whose |s_x|, |s_y| < ``band`` at each object distance.

    Parameters
    ----------
    design, z_mm, pixel : as :func:`~opticalstamp.analysis.spots.spots`
    band : the wave engine's band
    period_um : chart period the LSF is folded onto
    n_rays, seed : the tracer's sampling (importance sampled, exact 3-D refraction)
    cell_um : side of the central cell (default: the output pitch)
    fresnel : Fresnel losses in the trace (without ``tracer``; a tracer brings its own)
    """
    zs = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    tr = tracer if tracer is not None else PixelTracer(design, Sampling(n_rays, seed, fresnel))
    cell = output_pitch(design) if cell_um is None else float(cell_um)
    reach = (design.reference_plane_um + zs.max() * 1000.0) * band / np.sqrt(1 - band**2)
    half = np.ceil((reach + lattice_of(design).pitch) / RAY_BIN_UM) * RAY_BIN_UM
    edges = np.arange(-half, half + RAY_BIN_UM / 2, RAY_BIN_UM)
    nb = _n_bins(period_um)
    lsf = np.zeros((zs.size, edges.size - 1))
    folded = np.zeros((zs.size, nb))
    inside = np.zeros(zs.size)
    # tallied over the rays of every batch at once: the sums do not depend on how the
    # tracer splits the rays into batches (a kept chunk, a cut of one, a new trace)
    pbs = list(tr.trace(pixel, n_rays))
    w = _joined([pb.w for pb in pbs], np.float64)
    mine = _joined([pb.own for pb in pbs], bool)
    sx, sy = _joined([pb.rays.sx for pb in pbs]), _joined([pb.rays.sy for pb in pbs])
    ok = (np.abs(sx) < band) & (np.abs(sy) < band)
    traced, own, near = w.sum(), w[ok & mine].sum(), w[ok & ~mine].sum()
    w = w[ok]
    for iz, z in enumerate(zs):
        offs = [pb.offsets(z * 1000.0) for pb in pbs]
        dx, dy = _joined([o[0] for o in offs])[ok], _joined([o[1] for o in offs])[ok]
        lsf[iz] = np.histogram(dx, edges, weights=w)[0]
        folded[iz] = np.histogram(np.mod(dx, period_um), nb, (0.0, period_um), weights=w)[0]
        inside[iz] = w[(np.abs(dx) <= cell / 2) & (np.abs(dy) <= cell / 2)].sum()
    total = own + near
    return RayInBand(
        band,
        own / n_rays,
        near / n_rays,
        traced / n_rays,
        0.5 * (edges[1:] + edges[:-1]),
        lsf / (n_rays * RAY_BIN_UM),
        inside / total if total > 0 else np.zeros(zs.size),
        folded / n_rays,
    )


def _joined(parts: list, dtype=np.float64) -> np.ndarray:
    """The arrays of ``parts`` end to end (an empty array of ``dtype`` for none)."""
    return np.concatenate(parts) if parts else np.zeros(0, dtype)


@dataclass(frozen=True)
class WaveRayComparison:
    """Ray and wave figures of one design at each Z (see the module's docstring)."""

    design: str
    fingerprint: str
    z_mm: list[float]
    fresnel: list[dict]
    sampling: dict
    dof_dpi: float
    period_um: float
    own_exact_um2sr: float | None
    ray: dict
    wave: dict
    difference: dict
    budget: list[dict]
    meta: dict = field(default_factory=dict)
    #: row A's x line-spread functions for figures: ``wave_x_um``, ``wave_lsf`` (nz, n),
    #: ``ray_x_um``, ``ray_lsf`` (nz, n), um sr per um (left out of :meth:`to_dict`)
    profiles: dict = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        d = asdict(self)
        d.pop("profiles")
        return d


def _rmtf(design: Design, zs, per: float, folded_rows: list[np.ndarray], method: str) -> list:
    lat = lattice_of(design)
    rows = [(float(lat.row_x[r]), float(lat.row_y[r])) for r in range(design.sensor.rows)]
    h = np.stack(folded_rows)[:, None]  # (rows, 1, nz, nb)
    lsf = FoldedLSF(np.asarray(zs, float), np.array([per]), rows, [h], method, 0, False, False)
    return rmtf_curves(lsf, design)["max"][0].tolist()


def wave_folded_lsf(
    design: Design,
    z_mm,
    periods_um,
    *,
    sampling: WaveSampling | None = None,
    spectrum: str | Spectrum | None = None,
) -> FoldedLSF:
    """The wave engine's line-spread functions of rows A and B folded onto each chart
    period, as :func:`~opticalstamp.analysis.paraxial.paraxial_folded_lsf` gives the ray
    ones (method "wave", one batch): what :func:`~opticalstamp.analysis.rmtf.
    rmtf_from_lsf` turns into RMTF curves and a depth of field.

    ``spectrum``: the light (:func:`~.wavespectral.spectral_lsf_x`; default the design's
    ``electronics.illumination``, one channel; "mono" is the design's wavelength alone).
    ``sampling``: a sampling at one wavelength, carried to each of the light's. The LSFs
    come from the x-only path (:func:`~.wave.wave_lsf_x`); a row whose pixel sees the
    stack as row A's mirrored in y (:func:`~.wavespectral.mirror_twin`, the nominal
    staggered lattice) takes row A's LSFs. :class:`WaveFolds` gives the same for many
    sets of heights with the stack traversed once."""
    zs = np.asarray(z_mm, dtype=np.float64)
    folds = WaveFolds(design, float(zs.max()), sampling=sampling, spectrum=spectrum)
    return folds.folded(zs, periods_um)


class WaveFolds:
    """The wave engine's folded LSFs of every row at any heights up to ``z_max_mm``: the
    stack is traversed once per row and wavelength, when first asked
    (:class:`~.wavespectral.SpectralLSFSource`); each call of :meth:`folded` then costs
    the object side alone (the depth-of-field refinement asks again and again)."""

    def __init__(
        self,
        design: Design,
        z_max_mm: float,
        *,
        sampling: WaveSampling | None = None,
        spectrum: str | Spectrum | None = None,
        fresnel: bool = False,
    ) -> None:
        self.design, self.z_max_mm = design, float(z_max_mm)
        self.sampling, self.spectrum, self.fresnel = sampling, spectrum, bool(fresnel)
        lat = lattice_of(design)
        self.rows = [(float(lat.row_x[r]), float(lat.row_y[r])) for r in range(design.sensor.rows)]
        self._sources: list = []

    def _row_sources(self) -> list:
        if not self._sources:
            spec = one_channel(self.design, self.spectrum)
            smps = spectral_samplings(self.design, spec, self.sampling)
            reach = max(
                stack_reach(at_wavelength(self.design, lam), s)
                for lam, s in zip(spec.wavelengths_um, smps, strict=True)
            )
            for r in range(len(self.rows)):
                twin = next(
                    (q for q in range(r) if mirror_twin(self.design, (q, 0), (r, 0), reach)),
                    None,
                )
                self._sources.append(
                    self._sources[twin]
                    if twin is not None
                    else SpectralLSFSource.of(
                        self.design,
                        self.z_max_mm,
                        spectrum=spec,
                        pixel=(r, 0),
                        sampling=self.sampling,
                        fresnel=self.fresnel,
                    )  # fmt: skip
                )
        return self._sources

    def folded(self, z_mm, periods_um) -> FoldedLSF:
        """The rows' LSFs at ``z_mm`` (each <= ``z_max_mm``) folded onto ``periods_um``."""
        zs = np.asarray(z_mm, dtype=np.float64)
        per = np.asarray(periods_um, dtype=np.float64)
        done: dict[int, tuple] = {}  # a mirror twin shares its row's source: once each
        for src in self._row_sources():
            if id(src) not in done:
                done[id(src)] = src.lsf_x(zs)[:2]
        lsfs = [done[id(src)] for src in self._row_sources()]
        h = [
            np.stack([[fold(x, p, q, _n_bins(q)) for p in lsf] for x, lsf in lsfs])[:, None]
            for q in per
        ]
        return FoldedLSF(zs, per, self.rows, h, "wave", 0, False, False)


def _weighted_rays(parts: list[RayInBand], weights) -> RayInBand:
    """sum_i w_i of the tracer's in-band figures at the light's wavelengths (their LSF
    bins are centred on the pixel's axis: the shorter ones are padded)."""
    if len(parts) == 1:
        return parts[0]
    n = max(p.x_um.size for p in parts)
    lsf = np.zeros((parts[0].lsf_x.shape[0], n))
    for w, p in zip(weights, parts, strict=True):
        o = (n - p.x_um.size) // 2
        lsf[:, o : o + p.x_um.size] += w * p.lsf_x
    light = [p.own_um2sr + p.near_um2sr for p in parts]
    tot = sum(w * li for w, li in zip(weights, light, strict=True))
    inside = sum(
        w * li * p.center_cell_fraction for w, li, p in zip(weights, light, parts, strict=True)
    )
    return RayInBand(
        max(p.band for p in parts),
        float(sum(w * p.own_um2sr for w, p in zip(weights, parts, strict=True))),
        float(sum(w * p.near_um2sr for w, p in zip(weights, parts, strict=True))),
        float(sum(w * p.traced_um2sr for w, p in zip(weights, parts, strict=True))),
        max(parts, key=lambda p: p.x_um.size).x_um,
        lsf,
        inside / tot if tot > 0 else np.zeros_like(parts[0].center_cell_fraction),
        sum(w * p.folded for w, p in zip(weights, parts, strict=True)),
    )


def compare_wave_ray(
    design: Design,
    z_mm=(0.0, 1.0, 2.0, 3.0),
    *,
    sampling: WaveSampling | None = None,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    dof_dpi: float | None = None,
    spectrum: str | Spectrum | None = None,
    tracer: PixelTracer | None = None,
    fresnel: bool = False,
    progress: bool = False,
) -> WaveRayComparison:
    """Ray against wave for ``design`` at the object distances ``z_mm`` (mm).

    The wave figures come from :func:`~opticalstamp.analysis.wave.wave_response` for row
    A's pixel (rectangular holes; other holes, circles, by the 2-D path's maps,
    :func:`~.wavespectral.response_at`: minutes a height on a CPU, ``progress`` shows its
    bar and expected cost; the other rows' x LSFs for the RMTF from its mirror
    image on the nominal lattice, else the x-only path), the ray figures from :func:`ray_in_band`
    with ``n_rays`` per row. Differences are wave / ray - 1 for the light and the FWHM,
    wave - ray for the centre-cell share and the RMTF.

    ``spectrum``: the light, one channel (default the design's illumination). Over
    several wavelengths both sides are the weighted sums: the wave side
    :func:`~.wavespectral.wave_response_spectral`, the ray side the tracer at each
    wavelength (the design's indices there) in that wavelength's band, ``n_rays`` each.

    ``tracer``: a tracer of ``design`` whose pilots and kept rays the ray side reuses at
    the design's own wavelength (a report's: the rows' rays its other analyses traced
    are not traced again).

    ``fresnel``: Fresnel transmission losses (unpolarised) at the index changes in both
    engines: the wave engine's filters on the angular spectrum (:mod:`.wavefilter`), the
    tracer's losses ray by ray, and the own path's exact etendue with them
    (``meta["fresnel"]`` says so).
    """
    spec = one_channel(design, spectrum)
    mono = spec.wavelengths_um == (design.wavelength_um,)
    smps = [wave_sampling(design) if sampling is None else sampling]
    if not mono:
        smps = spectral_samplings(design, spec, sampling)
    smp = smps[int(np.argmax(spec.weights))]
    zs = [float(z) for z in z_mm]
    dpi = float(dof_chart_dpi(design) if dof_dpi is None else dof_dpi)
    per = period_of_dpi(dpi)
    nb = _n_bins(per)
    rows = range(design.sensor.rows)
    t0 = time.perf_counter()
    if mono:
        wa = response_at(
            design, zs, pixel=(0, 0), sampling=smps[0], fresnel=fresnel, progress=progress
        )
    else:
        wa = wave_response_spectral(
            design,
            zs,
            spectrum=spec,
            pixel=(0, 0),
            sampling=sampling,
            fresnel=fresnel,
            progress=progress,
        )
    # the other rows' x LSFs (all the RMTF needs): row A's where the row is its mirror
    # twin, else the x-only path
    reach = max(
        stack_reach(at_wavelength(design, lam), s)
        for lam, s in zip(spec.wavelengths_um, smps, strict=True)
    )
    row_lsf = [(wa.x_um, wa.lsf_x)]
    for r in rows[1:]:
        if mirror_twin(design, (0, 0), (r, 0), reach):
            row_lsf.append(row_lsf[0])
        else:
            src = SpectralLSFSource.of(
                design, max(zs), spectrum=spec, pixel=(r, 0), sampling=sampling, fresnel=fresnel
            )
            row_lsf.append(src.lsf_x(zs)[:2])
    t_wave = time.perf_counter() - t0
    t0 = time.perf_counter()
    by_lam = []
    for lam, s_i in zip(spec.wavelengths_um, smps, strict=True):
        d_i = at_wavelength(design, lam)
        same = tracer is not None and d_i.fingerprint() == design.fingerprint()
        tr = tracer_for(d_i, Sampling(n_rays, seed, fresnel), tracer if same else None)
        by_lam.append(
            [
                ray_in_band(
                    d_i, zs, s_i.band, pixel=(r, 0), period_um=per, n_rays=n_rays, tracer=tr
                )
                for r in rows
            ]
        )
    rays = [_weighted_rays([b[r] for b in by_lam], spec.weights) for r in rows]
    t_ray = time.perf_counter() - t0
    ra = rays[0]
    w_fold = [np.array([fold(x, p, per, nb) for p in lsf]) for x, lsf in row_lsf]
    wave = {
        "light_um2sr": float(wa.etendue_um2sr[0]),
        "fwhm_x_um": [fwhm_of(wa.x_um, p) for p in wa.lsf_x],
        "center_cell_fraction": wa.center_cell_fraction.tolist(),
        "rmtf": _rmtf(design, zs, per, w_fold, "wave"),
        "lost_to_band_top_um2sr": wa.budget[-1]["lost_to_band"],
    }
    ray = {
        "light_um2sr": ra.own_um2sr + ra.near_um2sr,
        "own_in_band_um2sr": ra.own_um2sr,
        "near_um2sr": ra.near_um2sr,
        "traced_um2sr": ra.traced_um2sr,
        "fwhm_x_um": [fwhm_of(ra.x_um, p) for p in ra.lsf_x],
        "center_cell_fraction": ra.center_cell_fraction.tolist(),
        "rmtf": _rmtf(design, zs, per, [r.folded for r in rays], "trace"),
        "n_rays": n_rays,
        "seed": seed,
    }
    own = None
    if rectangular_holes(design):
        own = float(
            sum(
                w * own_etendue(at_wavelength(design, lam), fresnel=fresnel)
                for lam, w in zip(spec.wavelengths_um, spec.weights, strict=True)
            )
        )
    diff = {
        "light": wave["light_um2sr"] / ray["light_um2sr"] - 1,
        "light_vs_own_exact": None if own is None else wave["light_um2sr"] / own - 1,
        "fwhm_x": [w / r - 1 for w, r in zip(wave["fwhm_x_um"], ray["fwhm_x_um"], strict=True)],
        "center_cell_fraction": [
            w - r
            for w, r in zip(wave["center_cell_fraction"], ray["center_cell_fraction"], strict=True)
        ],
        "rmtf": [w - r for w, r in zip(wave["rmtf"], ray["rmtf"], strict=True)],
    }
    return WaveRayComparison(
        design.name,
        design.fingerprint(),
        zs,
        fresnel_numbers(design, smp.wavelength_um if mono else spec.mean_um),
        asdict(smp),
        dpi,
        per,
        own,
        ray,
        wave,
        diff,
        wa.budget,
        {
            "seconds_wave": t_wave,
            "seconds_ray": t_ray,
            "rows": len(rows),
            "acceptance_half_angle_deg": design.sensor.acceptance_half_angle_deg,
            "spectrum": spec.to_dict(),
            "fresnel": bool(fresnel),
        },
        {"wave_x_um": wa.x_um, "wave_lsf": wa.lsf_x, "ray_x_um": ra.x_um, "ray_lsf": ra.lsf_x},
    )


def comparison_lines(c: WaveRayComparison) -> list[str]:
    """The comparison as lines of text for the terminal."""
    s = c.sampling
    spec = c.meta.get("spectrum")
    light = ""
    if spec and len(spec["wavelengths_um"]) > 1:
        lams = ", ".join(f"{x:.3f}" for x in spec["wavelengths_um"])
        light = (
            f"light: {spec['name']} ({len(spec['wavelengths_um'])} wavelengths {lams} µm, "
            f"weights {', '.join(f'{w:.3f}' for w in spec['weights'])}); ray and wave "
            "figures are the weighted sums, each wavelength in its own band; "
        )
    out = [
        f"{c.design}: ray vs wave at {s['wavelength_um']:g} µm, band |s_x|, |s_y| < "
        f"{s['band']:.3f} (grid {s['step_um']:.3f} µm, {s['source_points'][0]}×"
        f"{s['source_points'][1]} source points)",
        "Fresnel numbers a²/(λd): "
        + ", ".join(f"{f['layer']}→{f['towards']} {f['fresnel_number']:.2f}" for f in c.fresnel),
    ]
    if light:
        mean = sum(x * w for x, w in zip(spec["wavelengths_um"], spec["weights"], strict=True))
        out.insert(
            1,
            light + f"sampling shown at the heaviest wavelength, Fresnel numbers at the "
            f"mean {mean:.3f} µm",
        )
    r, w, d = c.ray, c.wave, c.difference
    own = "" if c.own_exact_um2sr is None else f"; own path exact {c.own_exact_um2sr:.4f}"
    out.append(
        f"light in band: wave {w['light_um2sr']:.4f} µm²·sr, ray {r['light_um2sr']:.4f} "
        f"(own {r['own_in_band_um2sr']:.4f} + near {r['near_um2sr']:.4f}){own}: "
        f"wave/ray {d['light']:+.1%}"
    )
    if c.meta.get("fresnel"):
        out.append(
            "Fresnel transmission losses (unpolarised) at every index change in both engines: "
            "the wave engine's filters on the angular spectrum, the tracer's ray by ray"
            + ("" if c.own_exact_um2sr is None else ", the own path exact with them")
        )
    out.append(
        f"wave light diffracted beyond the band by the object-side mask: "
        f"{w['lost_to_band_top_um2sr']:.4f} µm²·sr"
    )
    out.append(f"RMTF on the {c.dof_dpi:g}-dpi chart (period {c.period_um:.1f} µm)")
    out.append("  Z (mm)  FWHM x wave/ray (µm)   central cell wave/ray   RMTF wave/ray")
    for i, z in enumerate(c.z_mm):
        out.append(
            f"  {z:6.2f}  {w['fwhm_x_um'][i]:7.1f} / {r['fwhm_x_um'][i]:7.1f}"
            f"      {w['center_cell_fraction'][i]:.3f} / {r['center_cell_fraction'][i]:.3f}"
            f"          {w['rmtf'][i]:.3f} / {r['rmtf'][i]:.3f}"
        )
    m = c.meta
    out.append(
        f"time: wave {m['seconds_wave']:.1f} s, ray {m['seconds_ray']:.1f} s ({m['rows']} rows)"
    )
    return out
