"""The wave engine over a spectrum: a pixel's responsivity under the design's light.

The responsivity under a light (:mod:`.spectrum`: an illumination's spectrum times the
sensor's QE, sampled at wavelengths lambda_i with weights w_i summing to 1) is
sum_i w_i R(lambda_i), each R(lambda_i) the separable wave engine's
(:func:`~.wave.wave_response`) for the design at lambda_i: every medium named from the
catalogue takes its index at lambda_i (dispersion; a plain number stays a number), and
the band, margin and source points follow lambda_i by :func:`~.wavebase.wave_sampling`'s
rules, each on its own grid; the line-spread functions (band-limited below 2B / lambda)
are summed on one grid, the union of theirs at the finest step, by exact band-limited
(Fourier series) interpolation. A light of one wavelength ("mono", the design's
``wavelength_um``) gives :func:`~.wave.wave_response`'s figures exactly. Holes that are
not rectangles (circles) take the 2-D path at each wavelength (:func:`response_at`,
:func:`~.wave2dmaps.wave_maps_2d`): the same figures and maps, so that no analysis needs
to know which path gave them.

R, G and B LEDs lit in turn ("rgb"): three channels (:func:`wave_response_channels`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import fft as sfft

from ..design import Design
from .arrays import fft_workers, wave_backend
from .spectrum import Spectrum, channels, one_channel
from .wave import (
    WaveResponse,
    half_width,
    lsf_source,
    stack_reach,
    wave_marginals,
    wave_response,
)
from .wave2d import range_tol
from .wave2dlsf import lsf_source_2d
from .wave2dmaps import checked_heights
from .wavebase import (
    SOURCE_EXTRA,
    WaveSampling,
    rectangular,
    response_summary,
    stack_axes,
    wave_sampling,
)
from .wavethreads import side_by_side

__all__ = [
    "SpectralWaveResponse",
    "at_wavelength",
    "mirror_rows",
    "mirror_twin",
    "response_at",
    "spectral_lsf_x",
    "spectral_marginals",
    "spectral_samplings",
    "wave_response_channels",
    "wave_response_spectral",
]


#: The loosest compression tolerance a wavelength of small weight gets.
MAX_MODE_TOL = 1e-6


def at_wavelength(design: Design, wavelength_um: float) -> Design:
    """``design`` lit at ``wavelength_um`` (its media's indices follow; a
    :class:`~.spectrum.Spectrum` has checked the wavelength's range)."""
    if wavelength_um == design.wavelength_um:
        return design
    return design.model_copy(update={"wavelength_um": float(wavelength_um)})


def spectral_samplings(
    design: Design, spectrum: Spectrum, sampling: WaveSampling | None = None
) -> list[WaveSampling]:
    """The wave engine's sampling at each of the spectrum's wavelengths.

    Without ``sampling``: :func:`~.wavebase.wave_sampling` of the design at each
    wavelength. With it (a sampling at ``sampling.wavelength_um``): its band at every
    wavelength, its step, margin and source points scaled with the wavelength as the
    default rules scale them. The compression tolerance of each is ``mode_tol / w_i``
    (at most :data:`MAX_MODE_TOL`): each wavelength drops about ``mode_tol`` of the
    weighted sum's power (where the wavelengths' powers are alike), n wavelengths about
    n ``mode_tol``.
    """
    lams = spectrum.wavelengths_um
    if sampling is None:
        smps = [wave_sampling(at_wavelength(design, lam)) for lam in lams]
    else:
        l0 = sampling.wavelength_um
        smps = [
            replace(
                sampling,
                wavelength_um=lam,
                step_um=sampling.step_um * (lam / l0),
                margin_um=sampling.margin_um * (lam / l0),
                source_points=tuple(
                    max(1, math.ceil((p - SOURCE_EXTRA) * (l0 / lam) - 1e-9) + SOURCE_EXTRA)
                    for p in sampling.source_points
                ),
            )
            if lam != l0
            else sampling
            for lam in lams
        ]
    # each wavelength may drop mode_tol / w_i of its power to compression: in the weighted
    # sum that is about mode_tol of its power for each (one wavelength: as it is)
    return [
        replace(s, mode_tol=min(MAX_MODE_TOL, s.mode_tol / w)) if w < 1.0 else s
        for s, w in zip(smps, spectrum.weights, strict=True)
    ]


def resample(x: np.ndarray, y: np.ndarray, x_out: np.ndarray, cycles_per_um: float):
    """Real periodic samples ``y`` (..., n) on the uniform grid ``x`` (period n dx),
    band-limited below ``cycles_per_um``, evaluated on the uniform grid ``x_out`` by their
    Fourier series (exact band-limited interpolation, a chirp-z transform: Rabiner,
    Schafer and Rader, IEEE Trans. Audio Electroacoust. 17, 86 (1969)); 0 outside
    [x[0], x[-1]] (the periodic copies are not light)."""
    n, dx = x.size, x[1] - x[0]
    period = n * dx
    q = min(n // 2 - 1, int(np.ceil(cycles_per_um * period)) + 1)
    c = sfft.fft(y, axis=-1, workers=fft_workers()) / n
    coef = np.concatenate([c[..., n - q :], c[..., : q + 1]], axis=-1)  # k = -q .. q
    s, shift = x_out[1] - x_out[0], x_out[0] - x[0]
    a = np.exp(-2j * np.pi * shift / period)
    w = np.exp(2j * np.pi * s / period)
    from scipy.signal import czt  # here: scipy.signal takes ~1.4 s to import

    v = czt(coef, x_out.size, w, a, axis=-1)
    ramp = np.exp(-2j * np.pi * q * (shift + np.arange(x_out.size) * s) / period)
    out = (v * ramp).real
    out[..., (x_out < x[0] - 1e-9 * dx) | (x_out > x[-1] + 1e-9 * dx)] = 0.0
    return out


def _weighted_sum(xs: list[np.ndarray], ys: list[np.ndarray], w, cycles: list[float]):
    """sum_i w_i y_i (..., n_i) of band-limited samples on grids x_i, on one grid: the
    union of the grids' spans at the finest of their steps, each evaluated there by
    :func:`resample` (one grid: as it is)."""
    if len(xs) == 1:
        return xs[0], ys[0] * w[0] if w[0] != 1.0 else ys[0]
    step = min(x[1] - x[0] for x in xs)
    lo, hi = min(x[0] for x in xs), max(x[-1] for x in xs)
    x_out = lo + np.arange(int(np.floor((hi - lo) / step + 1e-6)) + 1) * step
    out = np.zeros(ys[0].shape[:-1] + (x_out.size,))
    for xi, yi, wi, ci in zip(xs, ys, w, cycles, strict=True):
        out += wi * resample(xi, yi, x_out, ci)
    return x_out, out


def _weighted_marginals(parts: list[tuple], w, smps: list[WaveSampling]):
    """The wavelengths' marginals ``parts`` [(x_um, lsf_x, y_um, lsf_y)] weighted by ``w``
    and summed on one grid per axis (:func:`_weighted_sum`, each band-limited below
    2 B / lambda of its sampling): (x_um, lsf_x, y_um, lsf_y)."""
    cyc = [2 * s.band / s.wavelength_um for s in smps]
    x, lx = _weighted_sum([p[0] for p in parts], [p[1] for p in parts], w, cyc)
    y, ly = _weighted_sum([p[2] for p in parts], [p[3] for p in parts], w, cyc)
    return x, lx, y, ly


@dataclass(frozen=True)
class SpectralWaveResponse:
    """A pixel's responsivity under a light, the weighted sum of the wave engine's
    responses at the light's wavelengths (the attributes of
    :class:`~.wave.WaveResponse` where they mean the same).

    Attributes
    ----------
    design, fingerprint, pixel, z_mm : as :class:`~.wave.WaveResponse`
    x_um, y_um : (nx,), (ny,) the union of the wavelengths' grids at the finest step
    lsf_x, lsf_y : (nz, nx), (nz, ny) weighted line-spread functions (um sr per um)
    etendue_um2sr : (nz,) weighted light (um^2 sr)
    center_cell_fraction : (nz,) share of the weighted light within the central cell
    spectrum : the :class:`~.spectrum.Spectrum`
    parts : one :class:`~.wave.WaveResponse` per wavelength
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
    spectrum: Spectrum
    parts: list[WaveResponse] = field(repr=False)
    meta: dict = field(default_factory=dict)

    @property
    def budget(self) -> list[dict]:
        """The mask-by-mask budget, weighted over the wavelengths (um^2 sr; the 2-D
        path's, :class:`~.wave2dmaps.MapResponse`, has the object-side mask's alone)."""
        out = []
        keys = ("incoming", "transmitted", "in_band", "lost_to_band")
        for i, rec in enumerate(self.parts[0].budget):
            agg = {"mask": rec["mask"]}
            for key in (k for k in keys if k in rec):
                agg[key] = float(
                    sum(
                        w * p.budget[i][key]
                        for w, p in zip(self.spectrum.weights, self.parts, strict=True)
                    )
                )
            out.append(agg)
        return out

    def to_dict(self) -> dict:
        """Summary as plain data (no fine arrays)."""
        return response_summary(self) | {
            "spectrum": self.spectrum.to_dict(),
            "budget": self.budget,
            "bands": [p.sampling.band for p in self.parts],
            "meta": self.meta,
        }

    def spot(self, iz: int, bin_um: float = 2.0, half_um: float | None = None):
        """The weighted responsivity map at ``z_mm[iz]`` on square bins (sr): (edges,
        map[y, x]), as :meth:`~.wave.WaveResponse.spot`."""
        if half_um is None:
            half_um = max(
                half_width(self.x_um, self.lsf_x[iz]), half_width(self.y_um, self.lsf_y[iz])
            )
        edges, total = None, None
        for w, p in zip(self.spectrum.weights, self.parts, strict=True):
            edges, m = p.spot(iz, bin_um, half_um)
            total = w * m if total is None else total + w * m
        return edges, total


def response_at(
    design: Design,
    z_mm,
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    cell_um: float | None = None,
    fresnel: bool = False,
    progress: bool = False,
    bar=None,
    weight: float = 1.0,
):
    """A used pixel's responsivity at the design's wavelength, by the path its holes
    take: the separable :func:`~.wave.wave_response` for rectangles, else the 2-D path's
    maps (:func:`~.wave2dmaps.wave_maps_2d`: the same figures and ``spot``; its range
    finder's tolerance that of a wavelength of ``weight`` in a light,
    :func:`~.wave2d.range_tol`), with a progress bar (heights; ``progress``) and, on a
    CPU, the expected cost (:func:`maps_bar`) unless the caller's ``bar`` counts them."""
    if rectangular(design):
        return wave_response(
            design, z_mm, pixel=pixel, sampling=sampling, cell_um=cell_um, fresnel=fresnel
        )
    from .wave2dmaps import wave_maps_2d

    smp = wave_sampling(design) if sampling is None else sampling
    zs = checked_heights(z_mm)
    own = bar is None
    if own:
        bar = maps_bar(design, [smp], zs, progress)
    try:
        return wave_maps_2d(design, zs, pixel=pixel, sampling=smp, cell_um=cell_um,
                            fresnel=fresnel, bar=bar, tol=range_tol(weight))  # fmt: skip
    finally:
        if own:
            bar.close()


def maps_bar(design: Design, smps: list[WaveSampling], zs: np.ndarray, progress: bool):
    """A tqdm bar over the 2-D path's heights x wavelengths (shown with ``progress`` on a
    terminal, :func:`~opticalstamp.raytrace.launch.progress_bar`) and, where the maps run
    on the CPU (:func:`~.wave2dmaps.maps_on_gpu`), a line on stderr with the expected
    cost (:func:`~.wave2dmaps.expected_seconds`) before any work."""
    import sys

    from ..raytrace.launch import progress_bar
    from .wave2dmaps import expected_seconds, maps_on_gpu

    n = len(smps) * zs.size
    bar = progress_bar(total=n, progress=progress, desc="wave maps (2-D path)", unit="height")
    if progress and not maps_on_gpu():
        z_max = float(zs.max()) if zs.size else 0.0
        est = [expected_seconds(design, s, z_max, zs.size) for s in smps]
        total = sum(e["total_s"] for e in est)
        said = f"{total:.0f} s" if total < 120 else f"{total / 60:.0f} min"
        bar.write(
            f"{design.name}: holes that are not rectangles take the wave engine's 2-D path "
            f"on the CPU: expect about {said} of CPU time for {zs.size} "
            f"height(s) x {len(smps)} wavelength(s) (the stack ~{est[0]['stack_s']:.0f} s "
            f"and ~{est[0]['height_s']:.0f} s a height per wavelength; a CUDA GPU with "
            "CuPy, --device cuda, takes seconds)",
            file=sys.stderr,
        )
    return bar


def wave_response_spectral(
    design: Design,
    z_mm=(0.0, 1.0, 2.0, 3.0),
    *,
    spectrum: str | Spectrum | None = None,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    cell_um: float | None = None,
    fresnel: bool = False,
    progress: bool = False,
) -> SpectralWaveResponse:
    """A used pixel's responsivity under a light of one channel.

    Parameters
    ----------
    design, z_mm, pixel, cell_um, fresnel : as :func:`~.wave.wave_response`; any hole
        shape: rectangles by the separable path, other holes (circles) by the 2-D path's
        maps (:func:`response_at`), the same figures and ``spot``
    spectrum : a :class:`~.spectrum.Spectrum`, a light's name ("mono", "white", "red",
        "green", "blue") or None: the design's ``electronics.illumination`` ("rgb" has
        three channels: :func:`wave_response_channels`)
    sampling : a :class:`~.wavebase.WaveSampling` at one wavelength, carried to each
        (:func:`spectral_samplings`); default the design's rules at each wavelength
    progress : the 2-D path's progress bar over heights x wavelengths, and on a CPU the
        expected cost (:func:`maps_bar`); the separable path takes seconds and shows none
    """
    spec = one_channel(design, spectrum)
    smps = spectral_samplings(design, spec, sampling)
    zs = checked_heights(z_mm)
    bar = None if rectangular(design) else maps_bar(design, smps, zs, progress)
    try:
        parts = [
            response_at(
                at_wavelength(design, lam),
                zs,
                pixel=pixel,
                sampling=s,
                cell_um=cell_um,
                fresnel=fresnel,
                bar=bar,
                weight=w,
            )
            for lam, s, w in zip(spec.wavelengths_um, smps, spec.weights, strict=True)
        ]
    finally:
        if bar is not None:
            bar.close()
    w = spec.weights
    x, lx, y, ly = _weighted_marginals([(p.x_um, p.lsf_x, p.y_um, p.lsf_y) for p in parts], w, smps)
    e = [p.etendue_um2sr for p in parts]
    light = sum(wi * ei for wi, ei in zip(w, e, strict=True))
    inside = sum(wi * ei * p.center_cell_fraction for wi, ei, p in zip(w, e, parts, strict=True))
    with np.errstate(invalid="ignore", divide="ignore"):
        cells = np.where(light > 0, inside / np.where(light > 0, light, 1.0), 0.0)
    first = parts[0]
    return SpectralWaveResponse(
        design.name,
        design.fingerprint(),
        first.pixel,
        first.z_mm,
        x,
        y,
        lx,
        ly,
        np.asarray(light, dtype=np.float64),
        cells,
        spec,
        parts,
        {"path": first.meta["path"], "propagator": first.meta["propagator"]}
        | {"cell_um": first.meta["cell_um"]},
    )


def spectral_marginals(
    design: Design,
    z_mm,
    *,
    spectrum: str | Spectrum | None = None,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """:func:`wave_response_spectral`'s marginals and light alone, (x_um, lsf_x, y_um,
    lsf_y, light um^2 sr): for rectangular holes by :func:`~.wave.wave_marginals` at each
    wavelength (no central-cell shares, no budget: the fit's forward model), other holes
    by the whole response."""
    if not rectangular(design):
        r = wave_response_spectral(design, z_mm, spectrum=spectrum, pixel=pixel, sampling=sampling)
        return r.x_um, r.lsf_x, r.y_um, r.lsf_y, float(r.etendue_um2sr[0])
    spec = one_channel(design, spectrum)
    smps = spectral_samplings(design, spec, sampling)
    zs = checked_heights(z_mm)
    parts = [
        wave_marginals(at_wavelength(design, lam), zs, pixel=pixel, sampling=s)
        for lam, s in zip(spec.wavelengths_um, smps, strict=True)
    ]
    w = spec.weights
    x, lx, y, ly = _weighted_marginals([p[:4] for p in parts], w, smps)
    return x, lx, y, ly, float(sum(wi * p[4] for wi, p in zip(w, parts, strict=True)))


def wave_response_channels(
    design: Design,
    z_mm=(0.0, 1.0, 2.0, 3.0),
    *,
    illumination: str | Spectrum | None = None,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    cell_um: float | None = None,
) -> dict[str, SpectralWaveResponse]:
    """One responsivity per channel of the light (default: the design's illumination;
    "rgb" gives "red", "green" and "blue", any other light one channel)."""
    return {
        name: wave_response_spectral(
            design, z_mm, spectrum=spec, pixel=pixel, sampling=sampling, cell_um=cell_um
        )
        for name, spec in channels(design, illumination).items()
    }


def spectral_lsf_x(
    design: Design,
    z_mm,
    *,
    spectrum: str | Spectrum | None = None,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
) -> tuple[np.ndarray, np.ndarray, float]:
    """The x line-spread functions alone under a light of one channel (the x-only path,
    :func:`~.wave.wave_lsf_x`, at each wavelength, weighted): (x_um, lsf_x (nz, nx),
    light um^2 sr)."""
    zs = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    src = SpectralLSFSource.of(design, float(zs.max()), spectrum=spectrum, pixel=pixel,
                               sampling=sampling)  # fmt: skip
    return src.lsf_x(zs)


@dataclass(frozen=True)
class SpectralLSFSource:
    """The stack traversed once per wavelength of one channel's light
    (:func:`~.wave.lsf_source`): weighted x LSFs at any Z up to ``z_max_mm``."""

    sources: list
    weights: np.ndarray
    cycles: list[float]

    @classmethod
    def of(
        cls,
        design: Design,
        z_max_mm: float,
        *,
        spectrum: str | Spectrum | None = None,
        pixel: tuple[int, int] = (0, 0),
        sampling: WaveSampling | None = None,
        fresnel: bool = False,
    ) -> SpectralLSFSource:
        spec = one_channel(design, spectrum)
        smps = spectral_samplings(design, spec, sampling)

        def one(lam: float, s: WaveSampling, w: float):
            d = at_wavelength(design, lam)
            if rectangular(d):
                return lsf_source(d, z_max_mm, pixel=pixel, sampling=s, fresnel=fresnel)
            return lsf_source_2d(d, z_max_mm, pixel=pixel, sampling=s, fresnel=fresnel,
                                 tol=range_tol(w))  # fmt: skip

        jobs = list(zip(spec.wavelengths_um, smps, spec.weights, strict=True))
        if len(jobs) > 1 and not rectangular(design):
            # the 2-D path: the wavelengths side by side (:mod:`.wavethreads`; on the
            # CPU the circular prototype's 7: 238 -> 182 s, 2026-11-27), each computed as
            # alone (its seed, its arrays): the figures of one after the other (on the
            # CPU to the last bits of FFTs on 1 and 2 threads); the heaviest first: a
            # wavelength's tolerance follows its weight (:func:`~.wave2d.range_tol`), so
            # the lightest cost least and fill the end
            order = sorted(range(len(jobs)), key=lambda i: -jobs[i][2])
            sources = side_by_side(one, jobs, order, _on_gpu(design))
        else:
            sources = [one(*job) for job in jobs]
        cyc = [2 * s.band / s.wavelength_um for s in smps]
        return cls(sources, np.asarray(spec.weights, dtype=np.float64), cyc)

    def lsf_x(self, z_mm) -> tuple[np.ndarray, np.ndarray, float]:
        """(x_um, lsf_x (nz, nx), light um^2 sr) at the heights ``z_mm``."""
        runs = [src.lsf_x(z_mm) for src in self.sources]
        x, lsf = _weighted_sum([r[0] for r in runs], [r[1] for r in runs], self.weights,
                               self.cycles)  # fmt: skip
        light = float(sum(w * r[2] for w, r in zip(self.weights, runs, strict=True)))
        return x, lsf, light


def _on_gpu(design: Design) -> bool:
    """Whether the design's sources take the 2-D path on a GPU (CuPy) in this run."""
    return not rectangular(design) and wave_backend(None)[0].name == "cuda"


def mirror_twin(
    design: Design, pixel: tuple[int, int], other: tuple[int, int], reach_um: float
) -> bool:
    """Whether the pixel ``other`` sees the stack as ``pixel`` does mirrored in y with
    the rows' roles exchanged (the nominal staggered lattice: row B's pixel sees row A's
    view mirrored), so that its x line-spread functions are ``pixel``'s exactly: the
    same sensitive interval (symmetric in y), and at every mask, among the holes within
    ``reach_um`` along x (:func:`~.wave.stack_reach`: those the separable path takes), each
    row's intervals along x equal to the other row's from ``other`` and along y their
    mirror images. Near a line's ends, or with a mask misregistered in y, it is not."""
    if pixel[0] == other[0]:
        return pixel == other
    a = stack_axes(design, pixel, reach_um=reach_um, bounds=True)  # a circle: its box
    b = stack_axes(design, other, reach_um=reach_um, bounds=True)
    tol = 1e-9 * max(1.0, design.sensor.row_pitch_um)
    (ax, ay), (bx, by) = a, b
    if abs(ay.source[0] + ay.source[1]) > tol or not np.allclose(ax.source, bx.source, atol=tol):
        return False
    swap = {pixel[0]: other[0], other[0]: pixel[0]}
    for i in range(len(ax.holes)):
        for r in range(design.sensor.rows):
            hx_a, hx_b = ax.holes[i][r], bx.holes[i][swap.get(r, r)]
            hy_a, hy_b = ay.holes[i][r], by.holes[i][swap.get(r, r)]
            if hx_a.shape != hx_b.shape or not np.allclose(hx_a, hx_b, atol=tol):
                return False
            if not np.allclose(hy_a, -hy_b[:, ::-1], atol=tol):
                return False
    return True


def mirror_rows(
    design: Design, sampling: WaveSampling | None = None, spectrum: str | Spectrum | None = None
) -> list[int | None]:
    """For each row of used pixels, the earlier row whose view it sees mirrored in y
    (:func:`mirror_twin` at k = 0, within the widest reach of the light's wavelengths,
    :func:`~.wave.stack_reach`; only a row computed on its own is a twin), or None where
    it has none and is computed on its own; row A's is None. ``sampling``, ``spectrum``:
    as :func:`wave_response_spectral`."""
    spec = one_channel(design, spectrum)
    smps = spectral_samplings(design, spec, sampling)
    reach = max(
        stack_reach(at_wavelength(design, lam), s)
        for lam, s in zip(spec.wavelengths_um, smps, strict=True)
    )
    out: list[int | None] = []
    for r in range(design.sensor.rows):
        own = (q for q in range(r) if out[q] is None)
        out.append(next((q for q in own if mirror_twin(design, (q, 0), (r, 0), reach)), None))
    return out
