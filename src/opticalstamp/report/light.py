"""The report's light sections: the efficiency (paper Fig. 13) with the sensitive-area
study, and the signal and noise of a used pixel with the design's electronics."""

from __future__ import annotations

from ..analysis.responsivity import RAY, Optics
from ..design import Design
from ..raytrace.pixel import PixelTracer
from .section import measured
from .work import Work


def efficiency_section(
    design: Design,
    g,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    optics: Optics = RAY,
    tracer: PixelTracer | None = None,
):
    """Light efficiency of the design (own path and all light) against the reference
    lens, and with the larger sensitive areas that fit (:func:`custom_area_scales`).
    ``g``: the report's ghost analysis, reused (traced again where it is not
    measurable). ``optics``: the engine of the headline light (own path: geometric).
    ``tracer``: the report's, whose rays the design's traces reuse."""
    from ..analysis.efficiency import efficiency

    return efficiency(
        design,
        seed=seed,
        fresnel=fresnel,
        ghosts=measured(g),
        area_scales=custom_area_scales(design, work.area_scales),
        optics=optics,
        tracer=tracer,
    )


def custom_area_scales(design: Design, scales) -> tuple[float, ...]:
    """The sensitive-area scales (sides x k) a custom sensor could have for this design:
    the paper's suggestion (§5, 4x the area) is a sensor whose used pixels are larger than
    the design's sensor's pitch, as large as the used-pixel lattice leaves room for (the
    row pitch along x; across y the distance to the other row, or the row pitch with one
    row). A scale that does not fit is not studied."""
    s = design.sensor
    room_y = abs(s.row_b_offset_y_um) if s.rows == 2 else s.row_pitch_um
    return tuple(
        k
        for k in scales
        if k * s.sensitive_width_um <= s.row_pitch_um + 1e-9
        and k * s.sensitive_height_um <= room_y + 1e-9
    )


def signal_and_noise(design: Design, eff) -> dict:
    """The report's "Signal and noise": a used pixel's electrons and temporal SNR at white
    and at 18 % grey, its full-well fraction, and the exposure and line rate for the target
    SNR at white (:func:`~opticalstamp.imaging.sensor.signal_budget`), with the design's
    electronics and its own-path etendue per pixel (``eff``: the efficiency section's
    :class:`~opticalstamp.analysis.efficiency.EfficiencyResult`; a white page adds its
    ghost light)."""
    from ..imaging.sensor import signal_budget

    g = float(eff.etendue_own_um2sr)
    return signal_budget(design.electronics, g) | {
        "etendue_own_um2sr": g,
        "electronics": design.electronics.model_dump(mode="json"),
    }
