"""One responsivity, two engines: the used pixels' line-spread functions from ray or wave
optics, behind one interface.

The analyses that consume a pixel's responsivity on the object plane take an
:class:`Optics` value that says which engine gives it: the RMTF and depth of field ask
:func:`folded_lsf` / :func:`folded_lsf_pair` for the LSFs folded onto their chart periods,
the light :func:`pixel_light`; the spots (:func:`~opticalstamp.analysis.spots.spots`)
and the scan kernels (:func:`~opticalstamp.imaging.kernels.scan_kernels`, source
"wave") join the wave engine's maps with the traced maps beyond the band in the same way:

* ``ray``: the exact tracer (:func:`~opticalstamp.analysis.lsf.traced_folded_lsf`), own
  and ghost paths, geometric optics;
* ``wave``: the wave engine (:mod:`.wave`, scalar diffraction) for the light whose
  invariant direction lies in its band, |s_x|, |s_y| < B (the own path, its diffraction
  and the near crosstalk), joined with the tracer's light outside the band (the far
  ghost paths, which land millimetres away at grazing angles, where ray optics holds).
  s = n sin(theta) is conserved through the planar stack, so the split is one test on
  each traced ray and nothing is counted twice or lost, apart from the light a mask
  diffracts beyond the band, which the wave engine counts (``budget``) but does not
  propagate (a faint halo; docs/wave.md). :func:`folded_lsf` with two bands shows the
  sum does not depend on where the band is split (tests/test_optics_engines.py).

:func:`resolve_optics` turns the user's ``ray | wave | auto`` into an :class:`Optics`;
``auto`` applies the measured validity rule (:mod:`.validity`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..defaults import RAYS_LSF
from ..design import Design
from ..raytrace.pixel import PixelTracer, Sampling, tracer_for
from ..validate import InputError
from .lsf import FoldedLSF, traced_folded_lsf
from .paraxial import paraxial_folded_lsf
from .tallies import SLOPE_EDGES
from .wavebase import CIRCLE_MAPS, WaveSampling, rectangular, wave_sampling

if TYPE_CHECKING:
    from .wavecompare import WaveFolds

#: what a user may ask for
OPTICS = ("ray", "wave", "auto")


@dataclass(frozen=True)
class Optics:
    """Which engine gives a design's responsivity, and why.

    Attributes
    ----------
    asked : what the user asked for: "ray", "wave" or "auto"
    engine : what is used: "ray" or "wave"
    reason : why, in words (the validity rule's verdict for "auto")
    sampling : the wave engine's sampling (band, grid) where ``engine`` is "wave"
    rule : the validity rule's figures for "auto" (plain data), else None
    fresnel : Fresnel losses in the wave engine (and in the traced light it is joined
        with); the tracer takes its own ``fresnel`` argument
    light : the wave engine's light where ``engine`` is "wave": {"name": the design's
        illumination, "wavelengths_um": every wavelength of its channels} (the sampling's
        wavelength is the design's, where the band is set, not the light's)
    """

    asked: str
    engine: str
    reason: str
    sampling: WaveSampling | None = None
    rule: dict | None = None
    fresnel: bool = False
    light: dict | None = None

    @property
    def band(self) -> float | None:
        return None if self.sampling is None else self.sampling.band

    def to_dict(self) -> dict:
        return {
            "asked": self.asked,
            "engine": self.engine,
            "reason": self.reason,
            "band": self.band,
            "wavelength_um": None if self.sampling is None else self.sampling.wavelength_um,
            "rule": self.rule,
            "fresnel": self.fresnel,
            "light": self.light,
        }


RAY = Optics("ray", "ray", "asked for")


def light_of(design: Design) -> dict:
    """The design's light as :class:`Optics` records it: its illumination's name and
    every wavelength of its channels."""
    from .spectrum import channels

    lams = sorted({lam for s in channels(design).values() for lam in s.wavelengths_um})
    return {"name": design.electronics.illumination, "wavelengths_um": lams}


def light_words(optics: dict) -> str:
    """Where the wave engine's figures of an :class:`Optics` record (its ``to_dict``) were
    computed, in words: "at 0.55 µm", or "under the white light (7 wavelengths,
    0.407-0.757 µm)"."""
    light = optics.get("light") or {}
    lams = light.get("wavelengths_um") or []
    if len(lams) > 1:
        return (
            f"under the {light.get('name', '')} light ({len(lams)} wavelengths, "
            f"{min(lams):.3f}-{max(lams):.3f} µm)"
        )
    return f"at {(lams or [optics['wavelength_um']])[0]:g} µm"


def wave_unavailable(
    design: Design, band: float | None = None, *, maps: bool = True, channels: bool = False
) -> str | None:
    """Why the wave engine cannot give this design's responsivity yet, or None: an
    illumination of several channels where the caller does not take them one by one
    (``channels`` False: the background search and tolerance study; the RMTF, the depth
    of field and the light take them one by one, :func:`~.colour.folded_lsf_channels`,
    :func:`pixel_light_channels`, the spots too, and the scan kernels mix them into the
    grey light, :func:`~.spectrum.grey_light`), or (with ``maps``: what ``auto`` asks)
    holes that are not rectangular where the 2-D path's maps would run on the CPU
    (:data:`CIRCLE_MAPS`: minutes a height; ``--optics wave`` computes them, and ``auto``
    follows the validity rule where the run's device is a GPU with CuPy,
    :func:`~.wave2dmaps.maps_on_gpu`).
    (The pixel's acceptance cone and Fresnel losses are filters on its angular
    spectrum, :mod:`.wavefilter`.)"""
    if maps and not rectangular(design):
        from .wave2dmaps import maps_on_gpu

        if not maps_on_gpu():
            return CIRCLE_MAPS
    if not channels and design.electronics.illumination == "rgb":
        return (
            "electronics.illumination is rgb: three channels, one exposure each; the RMTF, "
            "the depth of field and the light take them one by one (opticalstamp rmtf / "
            "efficiency --optics wave), this analysis does not yet"
        )
    return None


def resolve_optics(
    design: Design,
    optics: str | Optics = "ray",
    *,
    fresnel: bool = False,
    method: str = "trace",
    channels: bool = False,
) -> Optics:
    """The :class:`Optics` for ``design`` from ``"ray"``, ``"wave"`` or ``"auto"``.

    ``wave`` for a design the wave engine cannot do raises :class:`InputError` naming
    the reason; ``auto`` picks ray there, and elsewhere follows the measured validity
    rule (:func:`~opticalstamp.analysis.validity.choose_optics`). Holes that are not
    rectangles: ``wave`` takes the 2-D path everywhere (maps included, minutes a height
    on a CPU); ``auto`` keeps ray optics on a CPU and says so (:data:`CIRCLE_MAPS`),
    and follows the rule where the run's device (:func:`~opticalstamp.device.run_device`,
    ``--device``) is a GPU with CuPy. ``fresnel`` (Fresnel
    losses) goes with either engine (the wave engine's are filters on its angular
    spectrum, :mod:`.wavefilter`; the result carries it). ``method`` "paraxial" (the ray
    closed form) is ray optics: ``auto`` picks ray for it and says so, :func:`folded_lsf`
    refuses it with ``wave``. ``channels``: the caller takes a colour scanner's channels
    one by one (:func:`wave_unavailable`); ``auto`` then applies the rule at the channel
    of the lowest own-path Fresnel number (the reddest: diffraction grows with the
    wavelength), wave where that channel needs it."""
    if isinstance(optics, Optics):
        if optics.engine == "wave" and optics.fresnel != bool(fresnel):
            return replace(optics, fresnel=bool(fresnel))
        return optics
    if optics not in OPTICS:
        raise InputError(f"optics: must be one of {', '.join(OPTICS)} (got {optics!r})")
    if optics == "ray":
        return RAY
    if optics == "wave":
        why = wave_unavailable(design, maps=False, channels=channels)
        if why is not None:
            raise InputError(f"optics: 'wave' is not available for {design.name}: {why}")
        return Optics("wave", "wave", "asked for", wave_sampling(design), None, bool(fresnel),
                      light_of(design))  # fmt: skip
    if method == "paraxial":
        return Optics("auto", "ray", "the paraxial closed form asked for is ray optics")
    from .validity import choose_optics

    why = wave_unavailable(design, channels=channels)
    if why is not None:
        return Optics("auto", "ray", f"ray optics: {why}")
    choice, channel = _channel_choice(design, choose_optics)
    rule = {
        "fresnel_min": choice.fresnel_min,
        "predictor": choice.predictor,
        "predicted_error": choice.predicted_error,
        "tolerance": choice.tolerance,
    }
    if channel is not None:
        rule |= {"channel": channel[0], "channel_predictors": channel[1]}
    if choice.engine == "wave":
        return Optics("auto", "wave", choice.reason, wave_sampling(design), rule, bool(fresnel),
                      light_of(design))  # fmt: skip
    return Optics("auto", "ray", choice.reason, None, rule)


def _channel_choice(design: Design, choose_optics):
    """The validity rule's choice for ``design``, and for a light of several channels
    (rgb) the rule applied at the channel with the lowest own-path Fresnel number (at
    its mean wavelength): (choice, (channel, {channel: Fresnel number})), else
    (choice, None)."""
    from .spectrum import channels as light_channels
    from .wavespectral import at_wavelength

    specs = light_channels(design)
    if len(specs) == 1:
        return choose_optics(design, optics="auto"), None
    picks = {
        name: choose_optics(at_wavelength(design, spec.mean_um), optics="auto")
        for name, spec in specs.items()
    }
    worst = min(picks, key=lambda name: picks[name].predictor)
    c = picks[worst]
    said = f"the {worst} channel ({specs[worst].mean_um:.3f} µm) diffracts most: {c.reason}"
    return replace(c, reason=said), (worst, {k: v.predictor for k, v in picks.items()})


def folded_lsf(
    design: Design,
    *,
    z_mm,
    periods_um,
    optics: Optics = RAY,
    method: str = "trace",
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    ghosts: bool = True,
    fresnel: bool = False,
    progress: bool = False,
    tracer: PixelTracer | None = None,
    wave: WaveFolds | None = None,
) -> FoldedLSF:
    """The used pixels' LSFs folded onto ``periods_um`` at each ``z_mm``, by ``optics``.

    Ray optics: ``method`` "trace" (exact tracer; ``ghosts``, ``fresnel``, ``n_rays``,
    ``seed``, ``tracer`` as :func:`~opticalstamp.analysis.lsf.traced_folded_lsf`) or
    "paraxial" (own path, closed form). ``wave``: as :func:`folded_lsf_pair`. Wave
    optics: the wave engine's LSFs in its band plus, with ``ghosts``, the traced light
    outside it (:func:`join`); its method is
    "wave" and its standard errors those of the traced part (the wave part has no
    sampling noise). ``fresnel`` applies to both parts alike: the wave engine's filters
    (:mod:`.wavefilter`) and the traced light beyond the band.
    """
    if optics.engine == "ray":
        if method == "paraxial":
            return paraxial_folded_lsf(design, z_mm=z_mm, periods_um=periods_um)
        return traced_folded_lsf(
            design,
            z_mm=z_mm,
            periods_um=periods_um,
            n_rays=n_rays,
            seed=seed,
            ghosts=ghosts,
            fresnel=fresnel,
            progress=progress,
            tracer=tracer,
        )
    if method == "paraxial":
        raise InputError("method: 'paraxial' is a ray-optics closed form; not with --optics wave")
    optics = resolve_optics(design, optics, fresnel=fresnel)
    wf = checked_folds(design, optics, wave, z_mm)
    if not ghosts:
        return wf.folded(z_mm, periods_um)
    both, _ = folded_lsf_pair(
        design,
        z_mm=z_mm,
        periods_um=periods_um,
        optics=optics,
        n_rays=n_rays,
        seed=seed,
        fresnel=fresnel,
        progress=progress,
        tracer=tracer,
        wave=wf,
    )
    return both


def checked_folds(design: Design, optics: Optics, wave: WaveFolds | None, z_mm) -> WaveFolds:
    """The wave folds to use: ``wave`` where given (made with the same Fresnel setting
    as ``optics``, else the join would mix two models), else new ones."""
    if wave is None:
        return wave_folds(design, optics, float(np.max(z_mm)))
    if getattr(wave, "fresnel", False) != optics.fresnel:
        raise ValueError(
            f"wave: folds made with fresnel={wave.fresnel}, asked for fresnel={optics.fresnel}"
        )
    return wave


def folded_lsf_pair(
    design: Design,
    *,
    z_mm,
    periods_um,
    optics: Optics = RAY,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    fresnel: bool = False,
    progress: bool = False,
    tracer: PixelTracer | None = None,
    wave: WaveFolds | None = None,
) -> tuple[FoldedLSF, FoldedLSF]:
    """All light by ``optics`` and the own path alone (traced, geometric), from one trace
    per row (:func:`~opticalstamp.analysis.lsf.traced_folded_lsf_pair`): with wave
    optics the all-light LSFs are the wave engine's in band joined with the traced light
    beyond it (:func:`join`), as :func:`folded_lsf` gives them. ``wave``: the wave
    engine's folds to reuse (:func:`wave_folds`; built here where None)."""
    from .lsf import traced_folded_lsf_pair

    if optics.engine == "wave":
        optics = resolve_optics(design, optics, fresnel=fresnel)
    both, own = traced_folded_lsf_pair(
        design,
        z_mm=z_mm,
        periods_um=periods_um,
        n_rays=n_rays,
        seed=seed,
        fresnel=fresnel,
        progress=progress,
        tracer=tracer,
        outside_band=optics.band,
    )
    if optics.engine == "ray":
        return both, own
    wf = checked_folds(design, optics, wave, z_mm)
    return join(wf.folded(z_mm, periods_um), both, optics.band, _n_obj(design)), own


def wave_folds(design: Design, optics: Optics, z_max_mm: float) -> WaveFolds | None:
    """The wave engine's folds of ``design`` for heights up to ``z_max_mm`` (None with
    ray optics): pass them as ``wave=`` to :func:`folded_lsf` and
    :func:`folded_lsf_pair` called again and again (the stack traversed once)."""
    if optics.engine != "wave":
        return None
    from .wavecompare import WaveFolds

    return WaveFolds(design, z_max_mm, sampling=optics.sampling, fresnel=optics.fresnel)


@dataclass(frozen=True)
class BandSpots:
    """What an engine gives a pixel's spots inside its band (:func:`band_spots`):
    ``edges`` per Z, the grids' bin edges (um from the pixel's axis); ``maps`` per Z, the
    in-band responsivity (sr) on them; ``light`` (nz,) its etendue (um^2 sr) and
    ``center_cell`` (nz,) the share of it on the centre output cell; ``band``: the tracer
    takes only the light outside it (None: all of it)."""

    edges: list[np.ndarray]
    maps: list[np.ndarray]
    light: np.ndarray
    center_cell: np.ndarray
    band: float | None


def band_spots(
    design: Design,
    optics: Optics,
    z_mm,
    half_um,
    bins_um,
    pixel,
    progress: bool = False,
    spectrum=None,
) -> BandSpots:
    """A pixel's spots inside the engine's band, on square grids of half width
    ``half_um`` and bins ``bins_um`` per Z: the wave engine's (``spectrum``, None: the
    design's light, on its own bins) with wave optics; none with ray optics (the tracer
    takes all the light)."""
    if optics.engine != "wave":
        edges = [np.arange(-h, h + b / 2, b) for h, b in zip(half_um, bins_um, strict=True)]
        zero = np.zeros(len(edges))
        return BandSpots(edges, [np.zeros((e.size - 1,) * 2) for e in edges], zero, zero, None)
    from .wavespectral import wave_response_spectral

    wave = wave_response_spectral(
        design, z_mm, pixel=pixel, sampling=optics.sampling, fresnel=optics.fresnel,
        progress=progress, spectrum=spectrum,
    )  # fmt: skip
    spots = [
        wave.spot(iz, float(b), float(h))
        for iz, (h, b) in enumerate(zip(half_um, bins_um, strict=True))
    ]
    return BandSpots(
        [e for e, _ in spots], [m for _, m in spots], np.asarray(wave.etendue_um2sr),
        np.asarray(wave.center_cell_fraction), optics.band,
    )  # fmt: skip


def _n_obj(design: Design) -> float:
    return float(design.index(design.object_medium))


def join(wave: FoldedLSF, far: FoldedLSF, band: float, n_obj: float) -> FoldedLSF:
    """The wave engine's in-band LSFs plus the tracer's out-of-band ones (same Z,
    periods and rows). The wave part is dealt evenly into the tracer's batches, so the
    batch scatter (the standard errors) is the traced part's alone. The light's
    lateral slopes (:func:`~opticalstamp.analysis.lsf.fast_light`): the traced part's,
    and the in-band light at the band's edge slope, the fastest it can move (a bound
    that can only make the refinement of the Z grid finer)."""
    if not (
        np.array_equal(wave.z_mm, far.z_mm) and np.array_equal(wave.periods_um, far.periods_um)
    ):
        raise ValueError("join: the wave and traced LSFs must share their Z and periods")
    nb = far.n_batches
    h = [
        f + np.broadcast_to(w.sum(axis=1, keepdims=True) / nb, f.shape)
        for w, f in zip(wave.h, far.h, strict=True)
    ]
    slopes = None
    if far.slope_power is not None:
        slopes = far.slope_power.copy()
        light = float(np.sum(wave.h[0][:, :, 0, :])) / len(wave.rows)
        edge = band / np.sqrt(max(n_obj * n_obj - band * band, 1e-12))
        slopes[min(int(np.searchsorted(SLOPE_EDGES, edge, "right")) - 1, slopes.size - 1)] += light
    return replace(far, h=h, method="wave", slope_power=slopes)


def pixel_light(
    design: Design,
    optics: Optics,
    *,
    pixel: tuple[int, int] = (0, 0),
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    tracer: PixelTracer | None = None,
    spectrum=None,
) -> dict:
    """A used pixel's light from a uniform Lambertian object (um^2 sr) by wave optics:
    the wave engine's in-band light plus the tracer's light outside the band, with the
    tracer's in-band light beside it (what ray optics gives for the same directions) and
    the light the object-side mask diffracts beyond the band (counted, not propagated:
    an upper bound on the halo left out). Fresnel losses as ``optics.fresnel`` says, on
    both parts. ``tracer``: a tracer of ``design`` whose pilots and kept rays to reuse
    (the ghost analysis's: the traced part then traces only the rays it has not).
    ``spectrum``: the light (one channel; default the design's illumination)."""
    if optics.engine != "wave":
        raise ValueError("pixel_light: wave optics only (the ray figures are the ghost analysis')")
    traced = _traced_light(design, optics, pixel, n_rays, seed, tracer)
    return _light(_wave_light(design, optics, pixel, spectrum), traced, n_rays, seed, optics)


def pixel_light_channels(
    design: Design,
    optics: Optics,
    *,
    pixel: tuple[int, int] = (0, 0),
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    tracer: PixelTracer | None = None,
) -> dict[str, dict]:
    """:func:`pixel_light` per channel of the design's light ({channel: figures}; "rgb":
    red, green, blue), the light beyond the band traced at each channel's mean
    wavelength as :func:`~.colour.folded_lsf_channels` traces it (``traced_at_um``)."""
    from .colour import channel_designs
    from .spectrum import channels as light_channels

    if optics.engine != "wave":
        raise ValueError("pixel_light_channels: wave optics only")
    designs = channel_designs(design)
    traced = {}  # per traced design: channels of one index share it
    for d in designs.values():
        if d.fingerprint() not in traced:
            tr = tracer if d is design else None
            traced[d.fingerprint()] = _traced_light(d, optics, pixel, n_rays, seed, tr)
    return {
        name: _light(
            _wave_light(design, optics, pixel, spec),
            traced[designs[name].fingerprint()],
            n_rays,
            seed,
            optics,
        )
        | {"spectrum": spec.to_dict(), "traced_at_um": designs[name].wavelength_um}
        for name, spec in light_channels(design).items()
    }


def _wave_light(design: Design, optics: Optics, pixel, spectrum) -> tuple[float, float]:
    """The wave engine's in-band light under one channel's light and the light the
    object-side mask sends beyond the band (um^2 sr)."""
    from .wavespectral import SpectralLSFSource, wave_response_spectral

    if rectangular(design):
        w = wave_response_spectral(
            design,
            [0.0],
            spectrum=spectrum,
            pixel=pixel,
            sampling=optics.sampling,
            fresnel=optics.fresnel,
        )
        return float(w.etendue_um2sr[0]), float(w.budget[-1]["lost_to_band"])
    # the 2-D path's light (and its estimate of the light sent beyond the band)
    src = SpectralLSFSource.of(
        design,
        0.0,
        spectrum=spectrum,
        pixel=pixel,
        sampling=optics.sampling,
        fresnel=optics.fresnel,
    )
    parts = list(zip(src.weights, src.sources, strict=True))
    wave = float(sum(wi * s.light for wi, s in parts))
    return wave, float(sum(wi * s.meta["lost_to_band"] for wi, s in parts))


def _traced_light(design: Design, optics: Optics, pixel, n_rays, seed, tracer):
    """The tracer's light of the pixel in and beyond the band (:func:`ray_in_band`)."""
    from .wavecompare import ray_in_band

    sampling = Sampling(n_rays, seed, optics.fresnel)
    return ray_in_band(
        design,
        [0.0],
        optics.band,
        pixel=pixel,
        period_um=float(design.sensor.row_pitch_um),
        n_rays=n_rays,
        seed=seed,
        fresnel=optics.fresnel,
        tracer=None if tracer is None else tracer_for(design, sampling, tracer),
    )


def _light(wave_lost: tuple[float, float], r, n_rays: int, seed: int, optics: Optics) -> dict:
    wave, lost = wave_lost
    far = r.traced_um2sr - r.own_um2sr - r.near_um2sr
    return {
        "etendue_um2sr": wave + far,
        "wave_in_band_um2sr": wave,
        "far_traced_um2sr": far,
        "ray_in_band_um2sr": float(r.own_um2sr + r.near_um2sr),
        "lost_to_band_um2sr": lost,
        "n_rays": n_rays,
        "seed": seed,
        "fresnel": optics.fresnel,
    }
