"""What a report computes, and how much: :class:`Work` (rays, distances, resolutions, the
sections it runs) with the budgets of its background studies (:class:`StudyBudget`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from ..defaults import RAYS_LSF, RAYS_MAP
from ..design import Design, load_design

Z_MM = (0.0, 1.0, 2.0, 3.0, 4.0)
CONCEPTS = ("fig1b", "fig1c", "fig1d", "three-layer-single-row", "paper2016")
#: The preset whose report shows the paper's own figures beside the model's.
PAPER_PRESET = "paper2016"


@dataclass(frozen=True)
class StudyBudget:
    """How much the report's background studies compute (the CLI's `search` and
    `tolerance` run more).

    Attributes
    ----------
    search_population, search_generations : the compact design search's NSGA-II
        population and generations (24 x 10 designs; `opticalstamp search` runs 480)
    search_ghost_rays : rays of each design's ghost check during the search
    verify_ghost_rays, verify_lsf_rays : rays of the exact re-verification of the front
        (ghost analysis; folded LSFs per pixel row)
    tolerance_samples : Monte Carlo samples of the tolerance study
    parameter_rays : rays per pixel of each design of the study of the paper's unstated
        parameters (:func:`~opticalstamp.analysis.paper_study.parameter_study`'s default)
    rodlens_rays : rays of the rod-lens rows' contrast curves (`compare`'s,
        :data:`~opticalstamp.analysis.rodlens.RAYS_CONTRAST`)
    """

    search_population: int = 24
    search_generations: int = 10
    search_ghost_rays: int = 1 << 16
    verify_ghost_rays: int = 1 << 18
    verify_lsf_rays: int = 1 << 18
    tolerance_samples: int = 200
    parameter_rays: int = 1 << 19
    rodlens_rays: int = 1 << 21


@dataclass(frozen=True)
class Work:
    """How much each section of a report computes.

    Attributes
    ----------
    z_mm : distances (mm) of the ghost landings and the spots
    ghost_rays : rays of the ghost analysis (None: until its precision targets)
    map_rays : rays of the spots and PSFs
    concept_rays : rays of the ghost analyses of the Fig. 1 concepts (None: precision)
    lsf_rays : rays per pixel row of the folded LSFs (RMTF)
    lsf_z_mm : distances (mm) of the RMTF curves (None: the default grid)
    area_scales : sensitive-area scales of the efficiency section
    studies : run the parameter study, the design search and the tolerance study
    scan_dpi : resolution (dpi) of the charts of the simulated scans
    kernel_rays : rays of the scan kernels
    ocr : read the simulated text scans with Tesseract (where it is installed)
    left_out, reduced : what a quick report leaves out and computes with less
    paper : the paper's own sections (Fig. 1 concepts, the study of its unstated
        parameters, the paper-vs-model table)
    budget : the background studies' budgets (with ``studies``)
    wave_z_step_mm, wave_max_heights : heights of the ray-vs-wave section: the RMTF
        grid's heights every ``wave_z_step_mm`` and its top, at most ``wave_max_heights``
        (:func:`~opticalstamp.analysis.raywave.sub_grid`)
    wave_rays : rays per pixel row of the ray-vs-wave section's ray side
    """

    z_mm: tuple[float, ...]
    ghost_rays: int | None
    map_rays: int
    concept_rays: int | None
    lsf_rays: int
    lsf_z_mm: tuple[float, ...] | None
    area_scales: tuple[float, ...]
    studies: bool
    scan_dpi: float
    kernel_rays: int
    ocr: bool
    left_out: tuple[str, ...] = ()
    reduced: tuple[str, ...] = ()
    paper: bool = True
    budget: StudyBudget = field(default_factory=StudyBudget)
    wave_z_step_mm: float = 0.25
    wave_max_heights: int = 19
    wave_rays: int = RAYS_LSF


#: The simulated scans' charts are drawn at this many times the design's resolution at
#: least (a full report, a quick one): the prototype's 1200 and 600 dpi, a 600-dpi
#: design's 2400 and 1200, so that the bars of its depth-of-field chart (2/3 of its
#: resolution) span 6 and 3 chart pixels, not 3 and 1.5.
SCAN_OVERSAMPLE = (4.0, 2.0)


def report_work(
    quick: bool = False,
    n_rays: int = RAYS_MAP,
    z_mm: tuple[float, ...] | None = None,
    paper: bool = True,
    design_dpi: float | None = None,
) -> Work:
    """The work of a full report (``n_rays`` for its maps), or of a quick one.

    ``z_mm``: the heights of the ghost landings and the spots (default 0 ... 4 mm); the
    RMTF curves run at least as far. ``paper``: with the paper's own sections (its Fig. 1
    concepts and the study of its unstated parameters). ``design_dpi``: the design's
    resolution, which the scans' charts exceed ``SCAN_OVERSAMPLE`` times at least.
    """
    work = _work(quick, n_rays)
    if design_dpi is not None and SCAN_OVERSAMPLE[quick] * design_dpi > work.scan_dpi:
        dpi = float(round(SCAN_OVERSAMPLE[quick] * design_dpi))
        old = f"{work.scan_dpi:g}-dpi charts"
        work = replace(
            work,
            scan_dpi=dpi,
            reduced=tuple(x.replace(old, f"{dpi:g}-dpi charts") for x in work.reduced),
        )
    changes: dict = {}
    if z_mm is not None:
        changes["z_mm"] = tuple(sorted(set(float(z) for z in z_mm)))
        grid = work.lsf_z_mm if work.lsf_z_mm is not None else _default_rmtf_z()
        step = grid[1] - grid[0]
        top = max(changes["z_mm"][-1], grid[-1])
        n = int(round(top / step))
        changes["lsf_z_mm"] = tuple(round(i * step, 9) for i in range(n + 1))
        if n * step < top - 1e-9:
            changes["lsf_z_mm"] += (round((n + 1) * step, 9),)
    if z_mm is not None and work.reduced:
        zs = ", ".join(f"{z:g}" for z in changes["z_mm"])
        changes["reduced"] = tuple(
            x.replace("at Z = 0, 2, 4 mm", f"at Z = {zs} mm").replace(
                "spots at Z = 0, 2, 4 mm", f"spots at Z = {zs} mm"
            )
            for x in work.reduced
        )
    if not paper:
        changes["paper"] = False
        changes["reduced"] = tuple(
            x for x in changes.get("reduced", work.reduced) if "Fig. 1 concepts" not in x
        )
        changes["concept_rays"] = 0
        changes["left_out"] = work.left_out + (
            "the paper's own sections (its Fig. 1 concepts, the study of its unstated "
            "parameters and the paper-vs-model table): not the paper's prototype "
            "(report --paper-sections yes shows them)",
        )
    return replace(work, **changes)


def _default_rmtf_z() -> tuple[float, ...]:
    from ..analysis.rmtf import DEFAULT_Z_MM

    return tuple(float(z) for z in DEFAULT_Z_MM)


def _work(quick: bool, n_rays: int) -> Work:
    if not quick:
        return Work(
            z_mm=Z_MM,
            ghost_rays=None,
            map_rays=n_rays,
            concept_rays=None,
            lsf_rays=RAYS_LSF,
            lsf_z_mm=None,
            area_scales=(1.0, 2.0),
            studies=True,
            scan_dpi=1200.0,
            kernel_rays=RAYS_MAP,
            ocr=True,
        )
    map_rays = min(n_rays, 1 << 19)
    return Work(
        z_mm=(0.0, 2.0, 4.0),
        ghost_rays=1 << 20,
        map_rays=map_rays,
        concept_rays=1 << 18,
        lsf_rays=1 << 19,
        lsf_z_mm=tuple(0.5 * i for i in range(10)),
        area_scales=(1.0,),
        studies=False,
        scan_dpi=600.0,
        kernel_rays=1 << 18,
        ocr=False,
        left_out=(
            "the parameter study of the paper's unstated parameters",
            "the design search",
            "the tolerance study",
            "the comparison with rod-lens arrays",
            "OCR of the simulated text scans",
            "the larger sensitive area of the efficiency section",
        ),
        reduced=(
            "ghost analysis: 2^20 rays (not run to its precision targets), at Z = 0, 2, 4 mm",
            f"spots and PSFs: {map_rays:,} rays; spots at Z = 0, 2, 4 mm",
            "Fig. 1 concepts: 2^18 rays each",
            "RMTF: 2^19 rays per pixel row, Z every 0.5 mm",
            "simulated scans: 600-dpi charts, kernels from 2^18 rays",
            "restoration: Wiener only, at Z = 1.5, 3, 4.5 mm, no OCR",
            "ray vs wave optics: Z every 1 mm, 2^19 rays per pixel row",
        ),
        wave_z_step_mm=1.0,
        wave_max_heights=10,
        wave_rays=1 << 19,
    )


def is_paper_preset(design: Design) -> bool:
    """The design is one of the paper's presets (its prototype or its Fig. 1 concepts)."""
    return design.fingerprint() in {load_design(n).fingerprint() for n in CONCEPTS}
