"""`opticalstamp report`: every analysis of a design as JSON, PNG and one HTML page.

The work is arranged so that nothing is computed twice: one
:class:`~opticalstamp.raytrace.pixel.PixelTracer` (one pilot run per pixel, and each chunk
of rays traced once: ``replay``) serves the traced analyses and the scan kernels; the
folded LSF is traced once for all light and the own path
(:func:`~opticalstamp.analysis.lsf.traced_folded_lsf_pair`), and the scans' computed RMTF
is folded from it; the scan kernels of every simulated scan come from one trace per pixel
row (:func:`~opticalstamp.imaging.scan.prepare_kernels`); the parameter study (in two
parts, without the design's own row, which the headline analyses give), the design search
and the tolerance study run in background processes while the other sections run here,
on the cores those leave free (every analysis and evaluation carries its own seed, so no
number depends on where it runs or on how many threads it uses).

``quick`` reduces the work (fewer rays and distances, 600-dpi scans, no OCR) and leaves
out the parameter study, the search and the tolerance study; the page and report.json
say so.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType

from ..analysis.ghosts import analyse_ghosts
from ..analysis.paper_study import with_headline
from ..analysis.spots import psf, spots
from ..defaults import RAYS_LSF, RAYS_MAP
from ..design import Design, load_design
from ..design.describe import stack_rows
from ..design.resolution import chart_dpis, dof_chart_dpi
from ..io.files import (
    figure_png,
    provenance,
    replace_folder,
    save_figure,
    to_json,
    write_atomic,
)
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import output_pitch
from ..units import dpi_of_pitch
from .html import page

Z_MM = (0.0, 1.0, 2.0, 3.0, 4.0)
CONCEPTS = ("fig1b", "fig1c", "fig1d", "three-layer-single-row", "paper2016")


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


def report_work(
    quick: bool = False,
    n_rays: int = RAYS_MAP,
    z_mm: tuple[float, ...] | None = None,
    paper: bool = True,
) -> Work:
    """The work of a full report (``n_rays`` for its maps), or of a quick one.

    ``z_mm``: the heights of the ghost landings and the spots (default 0 ... 4 mm); the
    RMTF curves run at least as far. ``paper``: with the paper's own sections (its Fig. 1
    concepts and the study of its unstated parameters).
    """
    work = _work(quick, n_rays)
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
        ),
    )


def build_report(
    design: Design,
    out_dir: str | Path,
    *,
    seed: int = 0,
    n_rays: int = RAYS_MAP,
    fresnel: bool = False,
    progress: bool = False,
    quick: bool = False,
    spec: str | None = None,
    z_mm: tuple[float, ...] | None = None,
    dpi: float | None = None,
    paper_sections: bool | None = None,
) -> dict:
    """Run every analysis and write report.json, PNG figures and index.html to out_dir.

    Parameters
    ----------
    design : Design
    out_dir : folder to write; replaced as a whole once everything is computed and
        written (see :func:`opticalstamp.io.atomic.replace_folder`): a run that fails or
        is killed leaves the previous report as it was
    seed : random seed of every analysis
    n_rays : rays of the spots and PSFs
    fresnel : Fresnel transmission losses in the traced analyses and the scans
    progress : show progress bars
    quick : a quick report (:func:`report_work`): fewer rays, distances and pixels, no
        parameter study, search, tolerance study or OCR; labelled as such on the page
        and in report.json (``quick``, ``left_out``, ``reduced``)
    spec : figures the design must meet (:func:`~opticalstamp.report.summary.parse_report_spec`);
        its depth of field, light and ghost-radius bounds are also the tolerance study's
        yield spec (:func:`tolerance_spec`; no yield without them)
    z_mm : heights (mm) of the ghost landings and the spots (default 0 ... 4 mm); the RMTF
        curves run at least as far
    dpi : the chart (dpi) of the depth of field, the verdict, the search, the tolerance
        study, the chart scans and the restoration (default 2/3 of the design's
        resolution: 200 dpi for 300, as the paper; 400 for 600)
    paper_sections : the paper's own sections (its Fig. 1 concepts, the study of its
        unstated parameters, the paper-vs-model table); None: only for the paper's presets

    Returns
    -------
    dict
        What report.json holds.
    """
    from . import plotting
    from .paper import paper_vs_model
    from .summary import parse_report_spec, summary

    parse_report_spec(spec)  # a bad spec is refused before any work
    from .plotting.stack import plot_stack

    t0 = time.perf_counter()
    clock = _Clock()
    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    if paper_sections is None:
        paper_sections = is_paper_preset(design)
    work = report_work(quick, n_rays, z_mm, paper_sections)
    tol_spec = tolerance_spec(parse_report_spec(spec))
    jobs = _studies(design, seed, fresnel, work, dpi, tol_spec) if work.studies else {}
    # the folder is replaced as a whole once everything is written, or not at all
    with replace_folder(Path(out_dir)) as tmp, _Background(jobs) as background:
        # one pilot per pixel for every traced analysis below, and each chunk of rays traced
        # once (the ghost analysis, the folded LSFs and the scan kernels share chunks)
        tracer = PixelTracer(design, replay=True)
        with background.cores():  # numba threads: the cores the studies leave free
            g = analyse_ghosts(
                design,
                z_mm=work.z_mm,
                n_rays=work.ghost_rays,
                seed=seed,
                fresnel=fresnel,
                progress=progress,
                tracer=tracer,
            )
            sp = spots(
                design,
                z_mm=work.z_mm,
                seed=seed,
                n_rays=work.map_rays,
                fresnel=fresnel,
                progress=progress,
                tracer=tracer,
            )
            psfs = [
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
        clock.lap("ghosts_spots_psf")
        with background.cores():
            concepts = (
                _concepts(design, g, work, seed=seed, fresnel=fresnel) if work.paper else None
            )
        clock.lap("concepts")
        with background.cores():
            quality = _quality(
                design,
                g,
                work,
                seed=seed,
                fresnel=fresnel,
                progress=progress,
                tracer=tracer,
                dof_dpi=dpi,
            )
        clock.lap("quality")
        with background.cores():
            scans = _scans(
                design,
                work,
                seed=seed,
                fresnel=fresnel,
                tracer=tracer,
                own_lsf=quality.pop("lsf_own"),
                chart_dpi=dpi,
            )
        clock.lap("scans")
        with background.cores():
            restoration = _restoration(
                design, work, seed=seed, fresnel=fresnel, tracer=tracer, dof_dpi=dpi
            )
        clock.lap("restoration")
        panels = plotting.plot_scan_panels
        figures = {  # name: (plot, its arguments)
            "stack.png": (plot_stack, design),
            "ghosts.png": (plotting.plot_ghosts, g),
            "spots.png": (plotting.plot_spots, sp),
            "psf_x0.png": (plotting.plot_psf, psfs[0]),
            "psf_x42.png": (plotting.plot_psf, psfs[1]),
            "rmtf.png": (plotting.plot_rmtf, quality["rmtf_result"]),
            "chart_profiles.png": (plotting.plot_chart_profiles, quality["profiles"]),
            "efficiency.png": (plotting.plot_efficiency, quality["efficiency_result"]),
            "diffraction.png": (plotting.plot_diffraction, quality["slit_result"]),
            "scan_text.png": (panels, scans.pop("text_panels"), "8-pt text (paper Fig. 8)"),
            "scan_text_zoom.png": (
                panels,
                scans.pop("text_zoom"),
                "the first words of the 8-pt text, each scan pixel enlarged",
                1,
            ),
            "scan_bars.png": (
                panels,
                scans.pop("bar_panels"),
                f"{dpi:g}-dpi chart (paper Fig. 12 a, b)",
                2,
            ),
            "scan_profiles.png": (plotting.plot_scan_profiles, scans["profiles"]),
            "scan_lines.png": (
                panels,
                scans.pop("line_panels"),
                "fine line work (paper Fig. 9 analogue)",
                3,
            ),
            "scan_tilt.png": (
                panels,
                scans.pop("tilt_panels"),
                "text on a page tilted from 0 to 4 mm",
            ),
            "restore_curves.png": (plotting.plot_restoration, restoration["study"]),
            "restore_text.png": (
                panels,
                restoration.pop("panels"),
                f"{restoration['panel_points']:g}-pt text, scanned and restored (crops)",
                restoration["panel_cols"],
            ),
        }
        # each figure drawn by a background process that is idle (while the studies run
        # on), else here; written in this order either way
        drawing = {name: background.submit(_png, *task) for name, task in figures.items()}
        for name, task in drawing.items():
            write_atomic(tmp / name, _png(*figures[name]) if task is None else task.get())
        names = list(figures)
        clock.lap("figures")
        # each study's figure as soon as that study is done, while the others run on
        plots = {
            "parameter_study": ("study.png", plotting.plot_study),
            "search": ("pareto.png", plotting.plot_pareto),
            "tolerance": ("tolerance.png", plotting.plot_tolerance),
        }
        done: dict = {}
        drawing = 0.0
        for key in background.as_completed():
            res = background.result(key)
            if key == "parameter_study":  # the row that is this design: its headline analyses
                res = with_headline(res, design, g, quality["rmtf_result"], fresnel)
            done[key] = res
            if key not in plots:
                continue
            t_draw = time.perf_counter()
            name, plot = plots[key]
            save_figure(plot(res), tmp / name)
            names.append(name)
            drawing += time.perf_counter() - t_draw
        st, sr, tr = (done.get(k) for k in ("parameter_study", "search", "tolerance"))
        rodlens = _rodlens(design, quality, done.get("rodlens"), seed, fresnel)
        if rodlens is not None:
            for name, fig in (
                ("rodlens_contrast.png", plotting.plot_compare_contrast(rodlens["rows"])),
                ("rodlens_light.png", plotting.plot_compare_light(rodlens["rows"])),
            ):
                save_figure(fig, tmp / name)
                names.append(name)
        clock.lap("wait_for_studies")  # less the study figures, drawn while the others ran on
        clock.laps["wait_for_studies"] -= drawing
        clock.laps["study_figures"] = drawing
        data = {
            "provenance": provenance(design, seed) | {"fresnel": fresnel},
            "quick": quick,
            "left_out": list(work.left_out),
            "reduced": list(work.reduced),
            "design": design.model_dump(mode="json"),
            "stack": stack_rows(design),
            "ghosts": g.to_dict(),
            "spots": sp.to_dict(),
            "psf": [p.to_dict() for p in psfs],
            "concepts": concepts,
            "rmtf": quality["rmtf_result"].to_dict(),
            "rmtf_paraxial_own": quality["rmtf_paraxial"].to_dict(),
            "rmtf_traced_own": quality["rmtf_own"].to_dict(),
            "chart_profiles": quality["profiles"],
            "efficiency": quality["efficiency_result"].to_dict(),
            "signal": signal_and_noise(design, quality["efficiency_result"]),
            "diffraction": quality["slit_result"].to_dict() | {"budget": quality["budget"]},
            "parameter_study": st.to_dict() if st is not None else None,
            "scans": scans,
            "restoration": restoration,
            "search": sr.to_dict() if sr is not None else None,
            "tolerance": tr.to_dict() if tr is not None else None,
            "rodlens": rodlens,
            "figures": sorted(names),
            "elapsed_s": time.perf_counter() - t0,
            "section_elapsed_s": clock.laps,
        }
        data["paper_vs_model"] = paper_vs_model(data) if work.paper else None
        data["summary"] = summary(
            data,
            parse_report_spec(spec),
            paper=design.fingerprint() == load_design(PAPER_PRESET).fingerprint(),
        )
        write_atomic(tmp / "report.json", to_json(data))
        write_atomic(tmp / "index.html", page(design, data))
    return data


class _Clock:
    """Wall-clock seconds of the report's sections, in the order they ran."""

    def __init__(self) -> None:
        self.laps: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.laps[name] = now - self._t
        self._t = now


def _concepts(design: Design, g, work: Work, *, seed: int, fresnel: bool) -> list[dict]:
    """Own and ghost etendue of the paper's Fig. 1 concepts.

    A concept that is the report's design, analysed with the same rays, is the report's
    ghost analysis ``g`` (its etendues do not depend on the distances it lands ghost light
    at, and ``g`` lands it at Z = 0 too), so it is not run twice.
    """
    out = []
    for name in CONCEPTS:
        d = load_design(name)
        same = d.fingerprint() == design.fingerprint() and work.concept_rays == work.ghost_rays
        if same and 0.0 in work.z_mm:
            c = g
        else:
            c = analyse_ghosts(d, z_mm=(0.0,), n_rays=work.concept_rays, seed=seed, fresnel=fresnel)
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


def _quality(
    design: Design,
    g,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    progress: bool,
    tracer: PixelTracer,
    dof_dpi: float,
) -> dict:
    """RMTF and depth of field (at ``dof_dpi``), chart profiles, efficiency, diffraction."""
    import numpy as np

    from ..analysis.diffraction import design_slit_case, diffraction_budget
    from ..analysis.efficiency import efficiency
    from ..analysis.lsf import traced_folded_lsf_pair
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

    def pair(z, show: bool):  # all light and the own path alone from one trace per row
        return traced_folded_lsf_pair(
            design,
            z_mm=z,
            periods_um=periods,
            n_rays=work.lsf_rays,
            seed=seed,
            fresnel=fresnel,
            progress=show,
            tracer=tracer,
        )

    lsf, lsf_own = pair(zs, progress)
    res = rmtf_from_lsf(lsf, design, dpi=dpis, seed=seed, dof_dpi=dof_dpi)
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
    eff = efficiency(
        design,
        seed=seed,
        fresnel=fresnel,
        ghosts=g,
        area_scales=custom_area_scales(design, work.area_scales),
    )
    return {
        "lsf_own": lsf_own,  # the scans' computed RMTF folds it again (see _scans)
        "rmtf_result": res,
        "rmtf_own": own,
        "rmtf_paraxial": par,
        "profiles": profiles,
        "efficiency_result": eff,
        "slit_result": design_slit_case(design),
        "budget": diffraction_budget(design),
    }


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


def _scans(
    design: Design,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    tracer: PixelTracer,
    own_lsf=None,
    chart_dpi: float = 200.0,
) -> dict:
    """Simulated scans of the built-in charts (paper Figs. 8, 9, 12) and their measures.

    ``chart_dpi``: the bar chart scanned (the depth-of-field chart). ``own_lsf``: the
    own-path folded LSF of the RMTF section (:func:`_quality`), whose folds at 0.5 and
    3.5 mm and ``chart_dpi`` are those of the computed RMTF here where it was traced alike
    (same rays, no Fresnel losses): that RMTF is then not traced again. A measurement
    that the scan does not allow (an edge too blurred for an SFR) is reported as not
    measurable, with the reason, and the section goes on.
    """
    import numpy as np

    from ..analysis.lsf import folded_subset
    from ..analysis.rmtf import rmtf, rmtf_from_lsf
    from ..imaging.charts import bar_chart, clear_crop, edge_chart, line_chart, text_chart
    from ..imaging.heightmap import shape_map
    from ..imaging.measure import measure_rmtf, sfr_xy
    from ..imaging.ocr import (
        OCRUnavailable,
        character_error_rate,
        recognise_all,
        tesseract_available,
    )
    from ..imaging.scan import ScanSettings, prepare_kernels, simulate_scan
    from ..units import period_of_dpi

    dpi = work.scan_dpi
    # the charts are printed on a larger white page; Fresnel losses as in the analyses
    page = ScanSettings(
        surround=1.0, fresnel=fresnel, kernel_rays=work.kernel_rays, sensor=design.electronics
    )
    text, truth = text_chart(dpi)
    hm = shape_map("tilt:0:4", text.shape[0] * 25.4 / dpi, text.shape[1] * 25.4 / dpi)
    ocr = work.ocr and tesseract_available()
    # OCR of small text too, which the prototype loses past its depth of field (the 8-pt
    # text it reads at every Z to 4.5 mm; docs/scan.md): 2.5-pt sans at 0.5 ... 4.5 mm
    small_face, small_points, small_z = "sans", 2.5, (0.5, 1.5, 2.5, 3.5, 4.5)
    # the kernels of every scan below, from one trace per pixel row
    kernels = prepare_kernels(
        design,
        z_mm=tuple(dict.fromkeys((0.5, 1.5, 2.5, 3.5) + (small_z if ocr else ()))),
        height_maps=[hm],
        settings=page,
        seed=seed,
        tracer=tracer,
    )

    def scan(doc, **kw):
        return simulate_scan(doc, dpi, design, seed=seed, settings=page, kernels=kernels, **kw)

    res: dict = {"text_panels": [], "ocr": [], "profiles": [], "bar_panels": []}
    reads = []  # the scans to read, read at once below (one Tesseract process per core)

    def read(r, z: float, truth: str, face: str, points: float) -> None:
        from ..io.files import linear_to_srgb

        reads.append(((linear_to_srgb(r.image), r.dpi), (truth, face, points, z)))

    res["text_zoom"] = []  # the first words, pixels enlarged: the blur by height
    for z in (0.5, 1.5, 2.5):
        r = scan(text, z_mm=z)
        res["text_panels"].append((f"Z = {z:g} mm", r.image))
        h, w = r.image.shape
        rows, cols = clear_crop(text, dpi / r.dpi, slice(h // 12, h // 6), slice(0, w // 7))
        res["text_zoom"].append((f"Z = {z:g} mm", r.image[rows, cols]))
        if ocr:
            read(r, z, truth, "sans", 8.0)
    if ocr:
        small, small_truth = text_chart(dpi, small_points, face=small_face)
        for z in small_z:
            read(scan(small, z_mm=z), z, small_truth, small_face, small_points)
        try:
            texts = recognise_all([image for image, _ in reads])
        except OCRUnavailable:
            texts = []
        for got, (_, (truth_, face, points, z)) in zip(texts, reads, strict=False):
            cer = character_error_rate(truth_, got)
            res["ocr"].append({"face": face, "points": points, "z_mm": z, "cer": cer})
    bars = bar_chart(dpi, chart_dpi=(chart_dpi,), block_mm=10.0, height_mm=4.0)
    # RMTF compared on the own path: the chart is a finite patch on a white page, so its
    # ghost background differs from the infinite chart of the computed RMTF
    ref_dpi = [float(chart_dpi)]
    key = f"{chart_dpi:g}"
    ref_args = dict(seed=seed, window_um=8000.0, dof_dpi=chart_dpi)
    sub = None  # own_lsf was traced with work.lsf_rays rays, seed, and this tracer's pilots
    if own_lsf is not None and own_lsf.method == "trace":
        if not own_lsf.ghosts and not own_lsf.fresnel:  # as the rmtf() call below
            periods = [period_of_dpi(d) for d in ref_dpi]
            sub = folded_subset(own_lsf, (0.5, 3.5), periods)
    if sub is not None:
        ref = rmtf_from_lsf(sub, design, dpi=ref_dpi, **ref_args)
    else:
        ref = rmtf(
            design,
            dpi=ref_dpi,
            z_mm=(0.5, 3.5),
            ghosts=False,
            n_rays=work.lsf_rays,
            tracer=tracer,
            **ref_args,
        )
    for iz, z in enumerate((0.5, 3.5)):
        r = scan(bars, z_mm=z)
        own = scan(bars, z_mm=z, ghosts=False)
        blocks = measure_rmtf(own.image, own.dpi)
        mid = r.image[r.image.shape[0] // 2]
        res["bar_panels"].append((f"Z = {z:g} mm", r.image))
        res["profiles"].append(
            {
                "z_mm": z,
                "x_mm": (np.arange(mid.size) + 0.5) * r.pitch_um / 1000,
                "profile": mid,
                "rmtf_measured": blocks[0]["rmtf"] if blocks else float("nan"),
                "rmtf_computed_max": ref.rmtf_max[key][iz],
                "rmtf_computed_min": ref.rmtf_min[key][iz],
            }
        )
    edge = edge_chart(dpi)
    res["sfr"] = []
    for z in (0.5, 3.5):
        r = scan(edge, z_mm=z)
        try:  # at the depth-of-field chart and half its frequency (200, 100 dpi at 300)
            measured = sfr_xy(r.image, r.dpi, at_dpi=(chart_dpi / 2, chart_dpi))
        except ValueError as err:  # an edge too blurred (or ghost-ridden) to measure
            res["sfr"].append({"z_mm": z, "not_measurable": str(err)})
            continue
        for axis, v in measured.items():
            res["sfr"].append(
                {
                    "z_mm": z,
                    "axis": axis,
                    "mtf50_cy_per_mm": v["mtf50_cy_per_mm"],
                    "sfr_at_dpi": v["sfr_at_dpi"],
                }
            )
    lines = line_chart(dpi, size_mm=12.0)
    res["line_panels"] = [(f"document ({dpi:g} dpi)", lines)] + [
        (f"Z = {z:g} mm", scan(lines, z_mm=z).image) for z in (0.5, 3.5)
    ]
    tilt = scan(text, z_mm=None, height_map=hm)
    res["tilt_panels"] = [("tilt: Z = 0 mm at the top, 4 mm at the bottom", tilt.image)]
    res["profiles"] = [
        p | {"x_mm": p["x_mm"].tolist(), "profile": p["profile"].tolist()} for p in res["profiles"]
    ]
    res["chart_dpi"] = float(chart_dpi)
    res["settings"] = (
        f"the design's sensor electronics, noise on, ghost light on, white surround, seed {seed}"
        + ("" if work.ocr else f"; {dpi:g}-dpi charts, no OCR (quick report)")
    )
    return res


def _restoration(
    design: Design,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    tracer: PixelTracer,
    dof_dpi: float,
) -> dict:
    """Restoration with the known blur (issue 13): the study against height, text crops
    raw and restored, OCR of small text before and after."""
    import numpy as np

    from ..imaging.charts import clear_crop, text_chart
    from ..imaging.ocr import (
        OCRUnavailable,
        character_error_rate,
        recognise_all,
        tesseract_available,
    )
    from ..imaging.outputkernel import output_kernel
    from ..imaging.restore import METHODS, MODEL_ERROR, noise_sigma, restore
    from ..imaging.scan import ScanSettings, prepare_kernels, simulate_scan
    from ..io.files import linear_to_srgb
    from ..studies.restoration import STUDY_Z_MM, restoration_study

    page = ScanSettings(
        surround=1.0, fresnel=fresnel, kernel_rays=work.kernel_rays, sensor=design.electronics
    )
    quick = not work.studies
    methods = ("wiener",) if quick else METHODS
    study = restoration_study(
        design,
        z_mm=(1.5, 3.0, 4.5) if quick else STUDY_Z_MM,
        methods=methods,
        settings=page,
        seed=seed,
        tracer=tracer,
        dpi=dof_dpi,
    )
    dpi = work.scan_dpi
    panel_z = (2.5, 3.5, 4.5)
    # OCR where it tells: 2.5-pt text past the depth of field, 6-pt text at the end
    reads = ((2.5, 3.5), (2.5, 4.5), (6.0, 4.5)) if work.ocr and tesseract_available() else ()
    kernels = prepare_kernels(design, z_mm=panel_z, settings=page, seed=seed, tracer=tracer)
    ocr_methods = ("wiener",) if quick else ("wiener", "tv")
    panels, ocr = [], []
    charts = {p: text_chart(dpi, p) for p in dict.fromkeys((6.0,) + tuple(p for p, _ in reads))}

    def restored(img, z, methods, region=None):
        ok = output_kernel(design, z, settings=page, seed=seed, kernels=kernels)
        sigma = noise_sigma(page.sensor, ok.white, MODEL_ERROR)
        part = img if region is None else img[region]
        out = {"raw": part}
        for m in methods:
            out[m] = restore(part, ok, method=m, sigma=sigma, surround=1.0).image
        return out

    for z in panel_z:
        r = simulate_scan(
            charts[6.0][0], dpi, design, z_mm=z, seed=seed, settings=page, kernels=kernels
        )
        h, w = r.image.shape
        crop = clear_crop(  # no letter cut at the crop's edges
            charts[6.0][0],
            dpi / r.dpi,
            slice(h // 8, h // 8 + max(h // 3, 8)),
            slice(w // 20, w // 20 + w // 3),
        )
        m = 48  # restore the crop with a margin of context, then cut the margin off
        region = tuple(slice(max(c.start - m, 0), c.stop + m) for c in crop)
        inner = tuple(
            slice(c.start - rg.start, c.stop - rg.start) for c, rg in zip(crop, region, strict=True)
        )
        for name, img in restored(r.image, z, methods, region).items():
            panels.append((f"{name}, Z = {z:g} mm", np.clip(img[inner], 0, 1)))
    pending = []  # read at once below (one Tesseract process per core)
    for points, z in reads:
        doc, truth = charts[points]
        r = simulate_scan(doc, dpi, design, z_mm=z, seed=seed, settings=page, kernels=kernels)
        for name, img in restored(r.image, z, ocr_methods).items():
            image = (linear_to_srgb(np.clip(img, 0, 1)), r.dpi)
            pending.append((image, {"points": points, "z_mm": z, "version": name}, truth))
    try:
        texts = recognise_all([image for image, _, _ in pending])
    except OCRUnavailable:
        texts = []
    for got, (_, entry, truth) in zip(texts, pending, strict=False):
        ocr.append({**entry, "cer": character_error_rate(truth, got)})
    return {
        "study": study,
        "panels": panels,
        "panel_cols": 1 + len(methods),
        "panel_points": 6.0,
        "ocr": ocr,
        "settings": "the design's electronics, noise and ghost light on, white surround, "
        f"seed {seed}; the height known",
    }


def _png(plot, *args) -> bytes:
    """``plot(*args)`` as PNG bytes (a figure drawn here or in a background process)."""
    return figure_png(plot(*args))


def _one_numba_thread() -> None:  # pragma: no cover - runs in the background processes
    import numba

    numba.set_num_threads(1)


def _run_study(
    design: Design, seed: int, fresnel: bool, part: tuple[int, int]
):  # pragma: no cover - a background process
    """Part ``part`` of the study of the paper's unstated parameters (background). The row
    of the design itself is left to :func:`~opticalstamp.analysis.paper_study.with_headline`
    (the report's own analyses of the design, computed meanwhile)."""
    from ..analysis.paper_study import parameter_study

    deferred = {(design.fingerprint(), fresnel)}
    return parameter_study(design, seed=seed, deferred=deferred, part=part)


def _run_rodlens(seed: int, fresnel: bool, dof_dpi: float):  # pragma: no cover - background
    """The rod-lens presets' comparison rows (the report's "stamp against a rod-lens
    array" section): each preset evaluated as `compare` does, its depth of field on the
    report's chart ``dof_dpi``."""
    from ..studies.compare import RODLENS_PRESETS, evaluate_rodlens, labelled

    rows = []
    for name in RODLENS_PRESETS:
        d = load_design(name)
        curves = REPORT_ROD_CURVES | {"dpi": tuple(sorted({*REPORT_ROD_CURVES["dpi"], dof_dpi}))}
        row = evaluate_rodlens(d, seed=seed, fresnel=fresnel, dof_dpi=dof_dpi, **curves)
        rows.append(labelled(d, row, seed, fresnel))
    return rows


#: The preset whose report shows the paper's own figures beside the model's.
PAPER_PRESET = "paper2016"
#: The report's rod-lens contrast curves: the report's chart resolutions that `compare`
#: draws, every 0.25 mm (`compare`: 100/200/300 dpi every 0.125 mm); the same rays, so
#: light and depth of field are `compare`'s (the DOF to 1e-3 mm: bisection from another
#: bracket).
REPORT_ROD_CURVES = MappingProxyType(
    {"dpi": (100.0, 200.0), "heights_mm": tuple(0.25 * i - 1.5 for i in range(13))}
)


def _rodlens(design: Design, quality: dict, rod_rows: list | None, seed: int, fresnel: bool):
    """The report's rod-lens section: the design's row (from the report's own efficiency
    and RMTF) before the presets' rows; None where the presets were not evaluated."""
    if rod_rows is None:
        return None
    from ..studies.compare import labelled, relative_to_first, stamp_row

    eff = quality["efficiency_result"]
    row = stamp_row(design, eff, quality["rmtf_result"])
    gains = [a["gain_own_vs_design"] for a in eff.sensitive_area if a["area_scale"] == 4.0]
    return {
        "rows": relative_to_first([labelled(design, row, seed, fresnel), *rod_rows]),
        "area_gain": gains[0] if gains else None,
    }


def _run_search(design: Design, seed: int, dof_dpi: float):  # pragma: no cover - background
    """The compact design search of a report (the CLI's `search` runs the full budget)."""
    from ..studies.search import search, verify_front

    dpi = dpi_of_pitch(output_pitch(design))
    res = search(
        design,
        dpi=dpi,
        dof_dpi=dof_dpi,
        population=24,
        generations=10,
        seed=seed,
        ghost_rays=1 << 16,
        workers=1,
    )
    return verify_front(res, ghost_rays=1 << 18, lsf_rays=1 << 18, workers=1)


def _run_tolerance(design: Design, seed: int, dpi: float, spec: str):  # pragma: no cover
    """The report's tolerance study (the CLI's `tolerance` runs more samples); a
    background process."""
    from ..studies.tolerance import tolerance

    return tolerance(design, samples=200, seed=seed, dpi=dpi, spec=spec, workers=1)


#: report --spec figures that the tolerance study evaluates -> its name for them
_TOLERANCE_FIGURES = MappingProxyType(
    {"dof": "dof", "light": "efficiency", "ghost_radius": "ghost_radius"}
)


def tolerance_spec(spec: list[tuple[str, str, float]]) -> str | None:
    """The tolerance study's yield spec from a report spec (:func:`parse_report_spec`): its
    bounds on the depth of field, the light and the ghost-free radius; None (no yield:
    no hidden specification) when it bounds none of them."""
    parts = [f"{_TOLERANCE_FIGURES[n]}{op}{v:g}" for n, op, v in spec if n in _TOLERANCE_FIGURES]
    return ",".join(parts) or None


def is_paper_preset(design: Design) -> bool:
    """The design is one of the paper's presets (its prototype or its Fig. 1 concepts)."""
    return design.fingerprint() in {load_design(n).fingerprint() for n in CONCEPTS}


#: parts the parameter study is run in (each a background task): the study is the
#: smallest job, and in two parts it fills two processes beside the search and the
#: tolerance study (one each), so the processes end together
STUDY_PARTS = 2


def _studies(
    design: Design,
    seed: int,
    fresnel: bool,
    work: Work,
    dpi: float,
    tol_spec: str | None = None,
) -> dict:
    """The report's studies as background jobs: name -> list of (function, arguments),
    the tasks whose results make the job (:func:`_joined`). The parameter study of the
    paper's unstated parameters only with the paper's sections (``work.paper``); the
    search and the tolerance study evaluate in closed form, which needs square holes."""
    jobs = {}
    if work.paper:
        parts = [(i, STUDY_PARTS) for i in range(STUDY_PARTS)]
        jobs["parameter_study"] = [(_run_study, (design, seed, fresnel, p)) for p in parts]
    jobs["rodlens"] = [(_run_rodlens, (seed, fresnel, dpi))]
    if all(m.shape != "circle" for m in design.masks):
        jobs["search"] = [(_run_search, (design, seed, dpi))]
        jobs["tolerance"] = [(_run_tolerance, (design, seed, dpi, tol_spec))]
    return jobs


def _joined(name: str, results: list):
    """The result of job ``name`` from the results of its tasks."""
    if name == "parameter_study":
        from ..analysis.paper_study import join_parts

        return join_parts(results)
    (result,) = results
    return result


def _workers(n_tasks: int) -> int:
    """Background processes for ``n_tasks`` tasks: one per core but the one this process
    works on, and at least two (so that on two cores the three processes share them)."""
    import os

    return max(1, min(n_tasks, max(2, (os.cpu_count() or 1) - 1)))


class _Background:
    """Jobs that run in processes of their own (spawned, one numba thread each), started
    at once while the report goes on here.

    Parameters
    ----------
    jobs : name -> list of (function, arguments), the tasks of each job; functions and
        results are pickled. The tasks go to :func:`_workers` processes in the order
        given, each to the next process that is free.
    """

    def __init__(self, jobs: dict) -> None:
        self._pool = None
        self._jobs: dict[str, list] = {}
        self._extra: list = []  # tasks given by submit()
        self._n = 0
        tasks = [(name, task) for name, job in jobs.items() for task in job]
        if not tasks:
            return
        import multiprocessing as mp

        ctx = mp.get_context("spawn")  # no fork of numba's threads
        self._n = _workers(len(tasks))
        self._pool = ctx.Pool(self._n, initializer=_one_numba_thread)
        for name, (fn, args) in tasks:
            self._jobs.setdefault(name, []).append(self._pool.apply_async(fn, args))

    def __enter__(self) -> _Background:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def result(self, name: str):
        """The result of job ``name`` (waits for it; re-raises its error), or None if it
        was not started."""
        if name not in self._jobs:
            return None
        return _joined(name, [task.get() for task in self._jobs[name]])

    def _ready(self, name: str) -> bool:
        return all(task.ready() for task in self._jobs[name])

    def running(self) -> int:
        """How many background processes are at work (tasks not finished, at most one per
        process)."""
        return min(self._n, sum(not task.ready() for task in self._all()))

    def submit(self, fn, *args):
        """``fn(*args)`` in a background process if one is idle now: its AsyncResult
        (``get()`` gives the result); else None (nothing started)."""
        if self._pool is None or self.running() >= self._n:
            return None
        task = self._pool.apply_async(fn, args)
        self._extra.append(task)
        return task

    def _all(self) -> list:
        return [task for job in self._jobs.values() for task in job] + self._extra

    def as_completed(self, poll_s: float = 0.05):
        """The names of the jobs, each as soon as its tasks have finished (failed ones
        too)."""
        left = list(self._jobs)
        while left:
            ready = [name for name in left if self._ready(name)]
            if not ready:
                waiting = next(t for t in self._jobs[left[0]] if not t.ready())
                waiting.wait(poll_s)
                continue
            for name in ready:
                left.remove(name)
                yield name

    @contextmanager
    def cores(self):
        """Numba threads of this process for a section: one per core the running jobs
        leave free, at least one (more threads than free cores only burn CPU time that
        the jobs could use; a result does not depend on the thread count)."""
        import numba

        before = numba.get_num_threads()
        free = max(1, numba.config.NUMBA_NUM_THREADS - self.running())
        numba.set_num_threads(min(before, free))
        try:
            yield
        finally:
            numba.set_num_threads(before)

    def close(self) -> None:
        """End the processes: at once where jobs are still running (the report failed)."""
        if self._pool is None:
            return
        if all(self._ready(name) for name in self._jobs):
            self._pool.close()
        else:
            self._pool.terminate()
        self._pool.join()
        self._pool = None


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
