"""The report's "Ray vs wave optics" section (issue 23): the layers' Fresnel numbers, the
light, spot and RMTF on the depth-of-field chart of the own path and near crosstalk by
the tracer and by the wave engine in the same band
(:func:`~opticalstamp.analysis.wavecompare.compare_wave_ray`), and the verdict on which
optics holds for the design (:func:`~opticalstamp.analysis.raywave.judge`: the measured
differences against stated tolerances)."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..analysis.raywave import NEEDS_RECTANGLES
from ..design import Design
from .work import Work


@dataclass(frozen=True)
class WaveSection:
    """The ray-vs-wave section's results.

    Attributes
    ----------
    comparison : the :class:`~opticalstamp.analysis.wavecompare.WaveRayComparison`
        (its ``profiles``, row A's x LSFs by both engines, feed the figure)
    verdict : :func:`~opticalstamp.analysis.raywave.judge`'s verdict
    prediction : what the validity rule predicts from the geometry alone, at the same
        tolerances (:func:`~opticalstamp.analysis.validity.choose_optics`, ``auto``);
        None where the comparison ran with another sampling than the design's
    """

    comparison: object
    verdict: dict
    prediction: dict | None = field(default=None)

    def to_dict(self) -> dict:
        """report.json's "ray_vs_wave": the comparison's numbers, the verdict and the
        validity rule's prediction."""
        return self.comparison.to_dict() | {
            "verdict": self.verdict,
            "prediction": self.prediction,
        }


def wave_heights(work: Work) -> tuple[float, ...]:
    """The section's heights (mm): the report's RMTF grid every ``work.wave_z_step_mm``
    and its top, at most ``work.wave_max_heights`` of them."""
    from ..analysis.raywave import sub_grid
    from ..analysis.rmtf import DEFAULT_Z_MM

    grid = DEFAULT_Z_MM if work.lsf_z_mm is None else work.lsf_z_mm
    return sub_grid(grid, work.wave_z_step_mm, work.wave_max_heights)


def wave_section(
    design: Design,
    work: Work,
    *,
    seed: int,
    dof_dpi: float,
    sampling=None,
    tracer=None,
    optics=None,
    progress: bool = False,
) -> WaveSection:
    """Ray against wave optics for ``design`` at the heights of :func:`wave_heights`, on
    the ``dof_dpi`` chart, ``work.wave_rays`` rays per pixel row; ``sampling``: the wave
    engine's (:func:`~opticalstamp.analysis.wavebase.wave_sampling`; default from the
    design). ``tracer``: the report's
    :class:`~opticalstamp.raytrace.pixel.PixelTracer`, whose pilots and kept rays the ray
    side reuses. Holes that are not rectangles (circles): the wave side by the 2-D path
    (minutes a height on a CPU; ``progress``: its bar and expected cost) where the
    report's ``optics`` was asked for as "wave" or the run's device is a GPU with CuPy
    (:func:`~opticalstamp.analysis.wave2dmaps.maps_on_gpu`), else ValueError (not
    measurable, :data:`~opticalstamp.analysis.raywave.NEEDS_RECTANGLES`). A colour scanner
    (``electronics.illumination`` "rgb"): the channel that diffracts most, the reddest
    (its LED's light; ``meta["spectrum"]`` names it), as the validity rule judges it."""
    from ..analysis.raywave import LIGHT_TOLERANCE, RMTF_TOLERANCE, compare_and_judge
    from ..analysis.spectrum import channels
    from ..analysis.validity import choose_optics
    from ..analysis.wavebase import rectangular
    from ..analysis.wavespectral import at_wavelength

    if not rectangular(design):
        from ..analysis.wave2dmaps import maps_on_gpu

        if getattr(optics, "asked", None) != "wave" and not maps_on_gpu():
            raise ValueError(NEEDS_RECTANGLES)
    specs = channels(design)
    light = max(specs.values(), key=lambda sp: sp.mean_um) if len(specs) > 1 else None
    c, verdict = compare_and_judge(
        design,
        wave_heights(work),
        sampling=sampling,
        progress=progress,
        n_rays=work.wave_rays,
        seed=seed,
        dof_dpi=dof_dpi,
        tracer=tracer,
        spectrum=light,
    )
    pred = None
    if sampling is None:  # the rule reads the design as it is (not an overridden sampling)
        ruled = design if light is None else at_wavelength(design, light.mean_um)
        choice = choose_optics(ruled, light_tol=LIGHT_TOLERANCE, rmtf_tol=RMTF_TOLERANCE)
        pred = choice.to_dict()
    return WaveSection(c, verdict, pred)
