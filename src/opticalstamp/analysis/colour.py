"""A colour scanner's channels taken one by one: which channel's figures are the
headline.

A design whose ``electronics.illumination`` is "rgb" lights its red, green and blue LEDs
in turn: each line is three exposures, each with its own responsivity
(:func:`~opticalstamp.analysis.spectrum.channels`), so its own RMTF, depth of field and
light. The headline of each figure is the channel that limits the scanner:

* **depth of field: the worst channel's.** A colour image is sharp where all three
  channels are; past the first channel's depth of field the colours separate (colour
  fringes on every edge), so the scanner's depth of field is the least of the three.
* **light: the weakest channel's signal** (the wave engine's in-band light). The
  exposure of each channel is set so that a white page fills the pixel (white balance),
  so the channel that collects least light needs the longest exposure and sets the
  line time and the noise of the balanced image.

Each channel's figures are kept beside the headline (``meta["channels"]``). The wave
engine gives each channel's in-band light under its LED (:func:`channel_folds`); the light
beyond the band is traced at each channel's mean wavelength (:func:`channel_designs`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..defaults import RAYS_LSF
from ..design import Design
from ..raytrace.pixel import PixelTracer
from .lsf import FoldedLSF
from .responsivity import (
    RAY,
    Optics,
    checked_folds,
    folded_lsf,
    folded_lsf_pair,
    join,
    resolve_optics,
    wave_folds,
    wave_unavailable,
)
from .spectrum import channels as light_channels

if TYPE_CHECKING:
    from .wavecompare import WaveFolds

#: the rules, in words, carried with the results
DOF_RULE = (
    "a colour scanner's depth of field is its worst channel's: each channel is its own "
    "exposure, and a colour image is sharp only where all three are"
)
LIGHT_RULE = (
    "a colour scanner's light is its weakest channel's signal (the wave light in band): "
    "white balance gives that channel the longest exposure, which sets the line time"
)
#: the per-channel figures of an RMTF result kept in ``meta["channels"]``
RMTF_FIELDS = (
    "dof_mm",
    "dof_range_mm",
    "dof_open_ended",
    "spurious_mm",
    "rmtf_max",
    "rmtf_max_se",
    "rmtf_mean",
    "rmtf_min",
)


def channel_folds(design: Design, optics: Optics, z_max_mm: float) -> dict[str, WaveFolds | None]:
    """The wave engine's folds per channel of the design's light, {channel: folds}: one
    entry (the design's light, :func:`wave_folds`) where it has one channel or the optics
    is ray, three for "rgb" (red, green and blue lit in turn: one exposure, so one
    responsivity, each)."""
    specs = light_channels(design)
    if optics.engine != "wave" or len(specs) == 1:
        return {next(iter(specs)): wave_folds(design, optics, z_max_mm)}
    from .wavecompare import WaveFolds

    return {
        name: WaveFolds(
            design, z_max_mm, sampling=optics.sampling, spectrum=spec, fresnel=optics.fresnel
        )
        for name, spec in specs.items()
    }


def folded_lsf_channels(
    design: Design,
    *,
    z_mm,
    periods_um,
    waves: dict[str, WaveFolds | None],
    optics: Optics = RAY,
    method: str = "trace",
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    ghosts: bool = True,
    fresnel: bool = False,
    progress: bool = False,
    tracer: PixelTracer | None = None,
) -> dict[str, FoldedLSF]:
    """:func:`folded_lsf` per channel, ``waves`` as :func:`channel_folds` gives them: one
    channel as :func:`folded_lsf`; several (wave optics) each channel's in-band LSFs
    joined with the traced light beyond the band (:func:`join`).

    The light beyond the band (the far ghost paths, millimetres away at grazing angles)
    is traced at each channel's mean wavelength (:func:`channel_designs`): near grazing
    it is sensitive to the index (the prototype's plates as soda-lime glass: the blue
    channel's far light 10 % below the one traced at 0.55 um, the red's 2 % above, two
    seeds of 2^20 rays agreeing to 2 %; docs/wave.md), and a 20-40 nm LED band is
    narrow enough for its mean to stand for it. Where no medium of the design disperses
    (indices given as numbers, as the prototype's), every channel shares one trace,
    through ``tracer``.
    """
    if len(waves) == 1:
        ((name, wave),) = waves.items()
        one = folded_lsf(
            design,
            z_mm=z_mm,
            periods_um=periods_um,
            optics=optics,
            wave=wave,
            method=method,
            n_rays=n_rays,
            seed=seed,
            ghosts=ghosts,
            fresnel=fresnel,
            progress=progress,
            tracer=tracer,
        )
        return {name: one}
    optics = resolve_optics(design, optics, fresnel=fresnel, channels=True)
    if optics.engine != "wave" or method != "trace":
        raise ValueError("folded_lsf_channels: several channels are wave optics (method trace)")
    folds = {name: checked_folds(design, optics, w, z_mm) for name, w in waves.items()}
    if not ghosts:
        return {name: wf.folded(z_mm, periods_um) for name, wf in folds.items()}
    kw = {"z_mm": z_mm, "periods_um": periods_um, "n_rays": n_rays, "seed": seed}
    far = _far_light(design, optics.band, fresnel, progress, tracer, own=False, **kw)
    return _joined(design, folds, far, optics.band, z_mm, periods_um)


def folded_lsf_channels_pair(
    design: Design,
    *,
    z_mm,
    periods_um,
    waves: dict[str, WaveFolds | None],
    optics: Optics = RAY,
    n_rays: int = RAYS_LSF,
    seed: int = 0,
    fresnel: bool = False,
    progress: bool = False,
    tracer: PixelTracer | None = None,
) -> tuple[dict[str, FoldedLSF], FoldedLSF]:
    """All light per channel, as :func:`folded_lsf_channels` gives it, and the own path
    alone (traced, geometric, through ``design`` itself), as
    :func:`~.responsivity.folded_lsf_pair` gives the pair for one light: from one trace
    per row where no medium of the design disperses (the far light and the own path
    share it), else the own path traced once more through ``design``."""
    if len(waves) == 1:
        ((name, wave),) = waves.items()
        both, own = folded_lsf_pair(
            design,
            z_mm=z_mm,
            periods_um=periods_um,
            optics=optics,
            n_rays=n_rays,
            seed=seed,
            fresnel=fresnel,
            progress=progress,
            tracer=tracer,
            wave=wave,
        )
        return {name: both}, own
    optics = resolve_optics(design, optics, fresnel=fresnel, channels=True)
    if optics.engine != "wave":
        raise ValueError("folded_lsf_channels_pair: several channels are wave optics")
    folds = {name: checked_folds(design, optics, w, z_mm) for name, w in waves.items()}
    kw = {"z_mm": z_mm, "periods_um": periods_um, "n_rays": n_rays, "seed": seed}
    far = _far_light(design, optics.band, fresnel, progress, tracer, own=True, **kw)
    own = far.pop("own")
    return _joined(design, folds, far, optics.band, z_mm, periods_um), own


def _far_light(design, band, fresnel, progress, tracer, *, own: bool, **kw) -> dict:
    """The traced light beyond ``band`` per traced design of the channels
    (:func:`channel_designs`; channels of one index share a trace), {fingerprint:
    FoldedLSF}; with ``own``, also "own": ``design``'s own path alone, from the same
    trace where ``design`` is one of the traced designs."""
    from .lsf import traced_folded_lsf_pair

    designs = list(channel_designs(design).values())
    if own and all(d is not design for d in designs):
        designs.append(design)  # a dispersive design: its own path traced on its own
    far: dict = {}
    for d in designs:
        if d.fingerprint() in far:
            continue
        both, path = traced_folded_lsf_pair(
            d,
            **kw,
            fresnel=fresnel,
            progress=progress,
            tracer=tracer if d is design else None,
            outside_band=band,
        )
        far[d.fingerprint()] = both
        if own and d is design:
            far["own"] = path
    return far


def _joined(design, folds: dict, far: dict, band: float, z_mm, periods_um) -> dict:
    """Each channel's in-band folds joined with the light beyond the band traced through
    its design."""
    designs = channel_designs(design)
    return {
        name: join(
            wf.folded(z_mm, periods_um),
            far[designs[name].fingerprint()],
            band,
            float(designs[name].index(designs[name].object_medium)),
        )
        for name, wf in folds.items()
    }


def channel_designs(design: Design) -> dict[str, Design]:
    """The design each channel's light beyond the wave band is traced through: the
    design at the channel's mean wavelength, or ``design`` itself where its media have
    the same indices there (no dispersion: indices given as numbers)."""
    from .wavespectral import at_wavelength

    def indices(d: Design) -> tuple[float, ...]:
        media = [sl.medium for sl in d.slabs] + [d.reference_gap.medium, d.object_medium]
        return tuple(d.index(m) for m in media)

    own = indices(design)
    out = {}
    for name, spec in light_channels(design).items():
        d = at_wavelength(design, spec.mean_um)
        out[name] = design if indices(d) == own else d
    return out


def worst_channel(design: Design, results: dict):
    """The RMTF result of the channel with the least depth of field on the depth-of-field
    chart (the first in red, green, blue order on a tie), with every channel's figures in
    ``meta["channels"]`` (their curves, depth of field, range, spurious ranges, refined
    samples and light spectrum) and the rule in ``meta["headline"]``."""
    specs = light_channels(design)
    key = next(iter(results.values())).dof_key
    worst = min(results, key=lambda name: results[name].dof_mm[key])
    per = {
        name: {f: getattr(r, f) for f in RMTF_FIELDS}
        | {
            "refined": r.meta.get("refined"),
            "no_light": r.meta["no_light"],
            "spectrum": specs[name].to_dict(),
        }
        for name, r in results.items()
    }
    head = {"channel": worst, "rule": DOF_RULE}
    res = results[worst]
    return replace(res, meta=res.meta | {"channels": per, "headline": head})


def weakest_channel(lights: dict[str, dict]) -> str:
    """The channel whose signal (``wave_in_band_um2sr``) is least (:data:`LIGHT_RULE`)."""
    return min(lights, key=lambda name: lights[name]["wave_in_band_um2sr"])


def channel_variables(res) -> dict:
    """The channels of an RMTF result as netCDF variables (an empty dict with one
    channel): ``rmtf_channel`` (channel, dpi, z_mm) and ``dof_channel_mm`` (channel,
    dpi), on the coordinate ``channel``; the headline channel in ``headline_channel``."""
    chans = res.meta.get("channels")
    if not chans:
        return {}
    keys = [f"{d:g}" for d in res.dpi]
    names = list(chans)
    curves = np.array([[chans[c]["rmtf_max"][k] for k in keys] for c in names])
    dof = np.array([[chans[c]["dof_mm"].get(k, np.nan) for k in keys] for c in names])
    return {
        "rmtf_channel": (("channel", "dpi", "z_mm"), curves),
        "dof_channel_mm": (("channel", "dpi"), dof),
        "channel": ("channel", np.array(names, dtype=str)),
    }


def rmtf_channel_lines(res: dict) -> list[str]:
    """A colour scanner's depth of field per channel as lines of text (none with one
    channel); ``res``: ``RMTFResult.to_dict()``."""
    from .dof import dof_text

    chans = (res.get("meta") or {}).get("channels")
    if not chans:
        return []
    head = res["meta"]["headline"]["channel"]
    out = []
    for name, c in chans.items():
        mean = float(np.dot(c["spectrum"]["wavelengths_um"], c["spectrum"]["weights"]))
        mark = " (the headline: the worst)" if name == head else ""
        out.append(f"  {name} channel ({mean:.3f} µm): depth of field {dof_text(res | c)}{mark}")
    return [f"per channel ({DOF_RULE}):"] + out


def light_channel_lines(optics: dict) -> list[str]:
    """A colour scanner's light per channel as lines of text (none with one channel);
    ``optics``: the efficiency result's ``meta["optics"]``."""
    chans = optics.get("channels")
    if not chans:
        return []
    head = optics["headline"]["channel"]
    out = [f"per channel ({LIGHT_RULE}):"]
    for name, c in chans.items():
        mark = " (the headline: the weakest)" if name == head else ""
        out.append(
            f"  {name} channel: wave in band {c['wave_in_band_um2sr']:.4g} µm²·sr, all light "
            f"{c['etendue_um2sr']:.4g} (far light traced at {c['traced_at_um']:.3f} µm){mark}"
        )
    return out


def one_light_optics(design: Design, optics: Optics) -> Optics:
    """The optics of the analyses that take one light (the report's background search
    and tolerance study), where ``optics`` was resolved for a colour scanner's channels
    taken one by one (``resolve_optics(..., channels=True)``: the RMTF, the depth of
    field, the light, the spots; the scan kernels mix them into the grey light,
    :func:`~.spectrum.grey_light`): ``optics`` itself, or ray optics, saying why, where
    the wave engine would need a single channel (``electronics.illumination`` "rgb")."""
    if optics.engine != "wave":
        return optics
    why = wave_unavailable(design, maps=False)
    if why is None:
        return optics
    return Optics(optics.asked, "ray", f"ray optics: {why}")
