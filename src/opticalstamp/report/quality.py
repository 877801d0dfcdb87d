"""The report's RMTF and depth-of-field section (paper Eq. 1, Figs. 11, 12): the RMTF of
every chart from one trace per pixel row (all light and the own path), the paraxial
closed form, and the depth-of-field chart as the merged line sees it."""

from __future__ import annotations

from dataclasses import dataclass

from ..analysis.responsivity import RAY, Optics
from ..design import Design
from ..design.resolution import chart_dpis
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import output_pitch
from ..units import dpi_of_pitch
from .work import Work


@dataclass(frozen=True)
class RmtfSection:
    """The RMTF section's results.

    Attributes
    ----------
    result : the RMTF of all light (:class:`~opticalstamp.analysis.rmtf.RMTFResult`),
        whose depth of field is the design's figure of record
    own : the RMTF of the own path alone, from the same trace
    paraxial : the paraxial closed form (own path; ``own`` where the holes are circles)
    profiles : the depth-of-field chart's waveform at 0.5 and 3.5 mm, with the RMTF
        measured back from it (report.json's "chart_profiles")
    lsf_own : the own path's folded LSF, which the scans' computed RMTF folds again
    """

    result: object
    own: object
    paraxial: object
    profiles: list[dict]
    lsf_own: object


def rmtf_section(
    design: Design,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    progress: bool,
    tracer: PixelTracer,
    dof_dpi: float,
    optics: Optics = RAY,
) -> RmtfSection:
    """RMTF and depth of field (at ``dof_dpi``) of all light (by ``optics``: the ray or
    the wave engine, :func:`~opticalstamp.analysis.responsivity.folded_lsf_pair`) and of
    the own path (traced), the paraxial RMTF and the chart profiles (Fig. 12 analogue).

    A colour scanner (``electronics.illumination`` "rgb") under wave optics: all light
    per channel (:func:`~opticalstamp.analysis.colour.folded_lsf_channels_pair`), the
    result the worst channel's with every channel's figures in ``meta["channels"]``
    (:func:`~opticalstamp.analysis.colour.worst_channel`), as ``opticalstamp rmtf``
    gives them; the chart profiles are the worst channel's, the own path and the
    paraxial form geometric, as for one light."""
    import numpy as np

    from ..analysis.colour import channel_folds, folded_lsf_channels_pair, worst_channel
    from ..analysis.rmtf import (
        DEFAULT_Z_MM,
        chart_waveform,
        period_of_dpi,
        refine_results,
        rmtf,
        rmtf_from_lsf,
    )
    from ..imaging.measure import measure_rmtf

    dpis = sorted(set(chart_dpis(design)) | {float(dof_dpi)})
    periods = [period_of_dpi(d) for d in dpis]
    zs = np.asarray(DEFAULT_Z_MM if work.lsf_z_mm is None else work.lsf_z_mm)

    # the wave stack once per channel (wave optics; "rgb": three), for every Z below
    waves = channel_folds(design, optics, float(zs.max()))

    def lsfs(z, show: bool) -> list:  # each channel's light and the own path: one trace a row
        chans, own = folded_lsf_channels_pair(
            design,
            z_mm=z,
            periods_um=periods,
            optics=optics,
            waves=waves,
            n_rays=work.lsf_rays,
            seed=seed,
            fresnel=fresnel,
            progress=show,
            tracer=tracer,
        )
        return [*chans.values(), own]

    *by_channel, lsf_own = lsfs(zs, progress)
    kw = {"dpi": dpis, "seed": seed, "dof_dpi": dof_dpi}
    res = [rmtf_from_lsf(x, design, optics=optics, **kw) for x in by_channel]
    own = rmtf_from_lsf(lsf_own, design, **kw)
    # the crossings again on a finer Z step where they need it (the same rays)
    *res, own = refine_results([*res, own], lambda z: lsfs(z, False), design)
    head = 0
    if len(res) > 1:  # a colour scanner: the worst channel is the headline
        res = worst_channel(design, dict(zip(waves, res, strict=True)))
        head = list(waves).index(res.meta["headline"]["channel"])
    else:
        res = res[0]
    lsf = by_channel[head]
    rect = all(m.shape != "circle" for m in design.masks)
    par = rmtf(design, dpi=dpis, z_mm=zs, method="paraxial", dof_dpi=dof_dpi) if rect else own
    # Fig. 12 analogue: the merged line's waveform for the depth-of-field chart (200 dpi for
    # the paper) at 0.5 and 3.5 mm, and the RMTF measured back from it as from an image
    ip = dpis.index(float(dof_dpi))
    key = res.dof_key
    profiles = []
    px_um = output_pitch(design) / 4  # waveform drawn at 4 samples per output pixel
    for z in (0.5, 3.5):
        iz = int(np.argmin(np.abs(zs - z)))
        shift = res.meta["best_shift_um"][key][iz]
        x, sig = chart_waveform(lsf, design, ip, iz, shift)
        img = np.repeat(sig / sig.max(), 4)[None, :].repeat(8, axis=0)
        blocks = measure_rmtf(img, dpi_of_pitch(px_um))
        profiles.append(
            {
                "z_mm": float(zs[iz]),
                "dpi": float(dof_dpi),
                "shift_um": shift,
                "x_um": x.tolist(),
                "signal": (sig / sig.max()).tolist(),
                "rmtf_computed": res.rmtf_max[key][iz],
                "rmtf_measured_from_waveform": blocks[0]["rmtf"] if blocks else None,
            }
        )
    return RmtfSection(result=res, own=own, paraxial=par, profiles=profiles, lsf_own=lsf_own)
