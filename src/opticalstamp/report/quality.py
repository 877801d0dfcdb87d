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
    the own path (traced), the paraxial RMTF and the chart profiles (Fig. 12 analogue)."""
    import numpy as np

    from ..analysis.responsivity import folded_lsf_pair, wave_folds
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

    wave = wave_folds(design, optics, float(zs.max()))  # the wave stack once (wave optics)

    def pair(z, show: bool):  # all light and the own path alone from one trace per row
        return folded_lsf_pair(
            design,
            z_mm=z,
            periods_um=periods,
            optics=optics,
            wave=wave,
            n_rays=work.lsf_rays,
            seed=seed,
            fresnel=fresnel,
            progress=show,
            tracer=tracer,
        )

    lsf, lsf_own = pair(zs, progress)
    res = rmtf_from_lsf(lsf, design, dpi=dpis, seed=seed, dof_dpi=dof_dpi, optics=optics)
    own = rmtf_from_lsf(lsf_own, design, dpi=dpis, seed=seed, dof_dpi=dof_dpi)
    # the crossings again on a finer Z step where they need it (the same rays)
    res, own = refine_results([res, own], lambda z: pair(z, False), design)
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
