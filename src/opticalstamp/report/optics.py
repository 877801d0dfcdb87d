"""The report's sections on where a pixel's light goes: the ghost analysis (paper
Figs. 2, 4), the spots on the object plane (Fig. 5), the PSFs on the sensor (Fig. 10), the
paper's Fig. 1 concepts and diffraction (Fig. 6). Each computes its result; the report
measures it (:func:`~opticalstamp.report.section.measure`)."""

from __future__ import annotations

from dataclasses import dataclass

from ..analysis.ghosts import GhostResult, analyse_ghosts
from ..analysis.responsivity import RAY, Optics
from ..analysis.spots import PSF, SpotResult, psf, spots
from ..design import Design, load_design
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import output_pitch
from .section import measured
from .work import CONCEPTS, Work


def ghost_section(
    design: Design, work: Work, *, seed: int, fresnel: bool, progress: bool, tracer: PixelTracer
) -> GhostResult:
    """The design's ghost analysis at ``work.z_mm`` (the tracer's pilots and chunks are
    shared with the later sections)."""
    return analyse_ghosts(
        design,
        z_mm=work.z_mm,
        n_rays=work.ghost_rays,
        seed=seed,
        fresnel=fresnel,
        progress=progress,
        tracer=tracer,
    )


def spot_section(
    design: Design,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    progress: bool,
    tracer: PixelTracer,
    optics: Optics = RAY,
) -> SpotResult:
    """Responsivity maps on the object plane at ``work.z_mm``, by ``optics``."""
    return spots(
        design,
        z_mm=work.z_mm,
        seed=seed,
        n_rays=work.map_rays,
        fresnel=fresnel,
        progress=progress,
        tracer=tracer,
        optics=optics,
    )


def psf_section(
    design: Design, work: Work, *, seed: int, fresnel: bool, progress: bool
) -> list[PSF]:
    """PSFs on the sensor at Z = 1 mm: a point on a pixel's axis and one half a pitch
    off."""
    return [
        psf(
            design,
            x_obj_um=x,
            z_mm=1.0,
            seed=seed,
            n_rays=work.map_rays,
            fresnel=fresnel,
            progress=progress,
        )
        for x in (0.0, output_pitch(design) / 2)  # a pixel's axis and half a pitch off
    ]


def concept_section(
    design: Design,
    g,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    tracer: PixelTracer | None = None,
) -> list[dict]:
    """Own and ghost etendue of the paper's Fig. 1 concepts.

    A concept that is the report's design, analysed with the same rays, is the report's
    ghost analysis ``g`` (its etendues do not depend on the distances it lands ghost light
    at, and ``g`` lands it at Z = 0 too), so it is not run twice; where ``g`` is not
    measurable, or the concepts take fewer rays (a quick report), the concept is analysed
    here with ``tracer`` (the report's: its pilot and the rays it traced already).
    """
    g = measured(g)
    out = []
    for name in CONCEPTS:
        d = load_design(name)
        same = d.fingerprint() == design.fingerprint() and work.concept_rays == work.ghost_rays
        if same and 0.0 in work.z_mm and g is not None:
            c = g
        else:
            mine = d.fingerprint() == design.fingerprint()
            c = analyse_ghosts(
                d,
                z_mm=(0.0,),
                n_rays=work.concept_rays,
                seed=seed,
                fresnel=fresnel,
                tracer=tracer if mine else None,
            )
        out.append(
            {
                "design": name,
                "etendue_own_um2sr": c.etendue_own_um2sr,
                "etendue_ghost_um2sr": c.etendue_ghost_um2sr,
                "ghost_fraction": c.ghost_fraction,
                "nearest_ghost_um_z0": c.landing["0"]["nearest_um"],
            }
        )
    return out


@dataclass(frozen=True)
class Diffraction:
    """The diffraction section: ``slit``, the design's object-side hole as a slit (paper
    Fig. 6, :func:`~opticalstamp.analysis.diffraction.design_slit_case`), and
    ``budget``, its per-layer diffraction budget
    (:func:`~opticalstamp.analysis.diffraction.diffraction_budget`)."""

    slit: object
    budget: dict

    def to_dict(self) -> dict:
        """report.json's "diffraction": the slit case with the budget."""
        return self.slit.to_dict() | {"budget": self.budget}


def diffraction_section(design: Design) -> Diffraction:
    """The design's object-side hole as a slit and its per-layer diffraction budget."""
    from ..analysis.diffraction import design_slit_case, diffraction_budget

    return Diffraction(design_slit_case(design), diffraction_budget(design))
