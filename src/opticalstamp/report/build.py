"""`opticalstamp report`: every analysis of a design as JSON, PNG and one HTML page.

The report is a sequence of sections, one module each: :mod:`.optics` (ghost analysis,
spots, PSFs, the paper's Fig. 1 concepts, diffraction), :mod:`.quality` (RMTF and depth
of field), :mod:`.light` (efficiency, signal and noise), :mod:`.scans` (simulated scans),
:mod:`.restoration`, and the studies that run in background processes meanwhile
(:mod:`.studies` on :mod:`.background`: the parameter study, the rod-lens rows, the
design search, the tolerance study). How much each computes is the :class:`Work`
(:mod:`.work`). Each section gives its result, or "not measurable: reason" where the
design does not allow it (:mod:`.section`: which errors that absorbs); one such section
never takes the report down. The page is :mod:`.html`, a module per section too.

The work is arranged so that nothing is computed twice: one
:class:`~opticalstamp.raytrace.pixel.PixelTracer` (one pilot run per pixel, and each ray
traced once: ``replay``; its pass count, ``passes``, says so) serves the traced analyses
of the design's pixels (ghosts, spots, the Fig. 1 concept that is the design, RMTF, the
wave light and the ray side of ray vs wave, scan kernels, restoration); the
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
from pathlib import Path

from ..analysis.colour import one_light_optics
from ..analysis.responsivity import resolve_optics
from ..defaults import RAYS_MAP
from ..design import Design, load_design
from ..design.describe import stack_rows
from ..design.resolution import dof_chart_dpi, output_pitch_um
from ..io.files import provenance, replace_folder, save_figure, to_json, write_atomic
from ..raytrace.passes import TracePasses
from ..raytrace.pixel import PixelTracer
from ..units import dpi_of_pitch
from .background import Background
from .figures import png, rodlens_figures, section_figures, study_figure
from .fitsection import fit_section
from .html import page
from .light import custom_area_scales, efficiency_section, signal_and_noise
from .optics import concept_section, diffraction_section, ghost_section, psf_section, spot_section
from .quality import rmtf_section
from .restoration import restoration_heights, restoration_section
from .scans import scan_section
from .section import as_data, measure, measured, needs
from .studies import (
    REPORT_ROD_CURVES,
    STUDY_PARTS,
    headline_study,
    join_job,
    rodlens_section,
    study_jobs,
    tolerance_spec,
)
from .wave import wave_section
from .work import CONCEPTS, PAPER_PRESET, Z_MM, StudyBudget, Work, is_paper_preset, report_work

#: the names callers import from here (the report's parts now live in the modules above)
__all__ = [
    "CONCEPTS",
    "PAPER_PRESET",
    "REPORT_ROD_CURVES",
    "STUDY_PARTS",
    "Z_MM",
    "StudyBudget",
    "Work",
    "build_report",
    "custom_area_scales",
    "is_paper_preset",
    "report_work",
    "signal_and_noise",
    "tolerance_spec",
]
#: kept under their former names for callers that import them from here
_Background = Background
_png = png


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
    optics: str = "auto",
    fit: dict | None = None,
    passes: TracePasses | None = None,
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
    optics : the engine of the headline RMTF, depth of field and light: "ray", "wave" or
        "auto" (the measured validity rule,
        :func:`~opticalstamp.analysis.responsivity.resolve_optics`; a colour scanner,
        ``electronics.illumination`` "rgb": one RMTF, depth of field and light per
        channel, the headline the worst channel's depth of field and the weakest
        channel's light, :mod:`~opticalstamp.analysis.colour`); the spots take it (a
        colour scanner's channels one by one), the scans and restoration too (a colour
        scanner's grey light, its LEDs lit together), the background search and
        tolerance study where they can (not a colour scanner's channels: ray optics
        there, report.json's ``optics_one_light`` says so); the ghosts and PSFs are ray
        optics; the "ray vs wave" section shows both
    fit : a fit's JSON (:func:`~opticalstamp.report.fitsection.load_fit`): the section
        "model vs measurement" (:mod:`.fitsection`); None: no such section
    passes : the count of the report's traced passes
        (:class:`~opticalstamp.raytrace.passes.TracePasses`) that its tracer adds to
        (None: a count of its own): how many times each pixel's rays were traced

    Returns
    -------
    dict
        What report.json holds. A section that cannot be computed for this design
        (:data:`~opticalstamp.report.section.MEASURING_ERRORS`) holds
        ``{"not_measurable": reason}`` and its figures are left out; the page says
        "not measurable: reason" there.
    """
    from .paper import paper_vs_model
    from .summary import parse_report_spec, summary

    parse_report_spec(spec)  # a bad spec is refused before any work
    # and a bad or impossible optics: the headline's (RMTF, depth of field, light: a colour
    # scanner's channels one by one), and the one the analyses of one light take
    opt = resolve_optics(design, optics, fresnel=fresnel, channels=True)
    one = one_light_optics(design, opt)
    t0 = time.perf_counter()
    clock = _Clock()
    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    if paper_sections is None:
        paper_sections = is_paper_preset(design)
    work = report_work(quick, n_rays, z_mm, paper_sections, dpi_of_pitch(output_pitch_um(design)))
    tol_spec = tolerance_spec(parse_report_spec(spec))
    jobs = study_jobs(design, seed, fresnel, work, dpi, tol_spec, optics=one)
    traced = dict(seed=seed, fresnel=fresnel)
    # the folder is replaced as a whole once everything is written, or not at all
    with replace_folder(Path(out_dir)) as tmp, Background(jobs, join_job, True) as background:

        def run(compute, *args, **kwargs):  # a section, on the cores the studies leave free
            with background.cores():  # numba threads
                return measure(compute, *args, **kwargs)

        # one pilot per pixel for every traced analysis below, and each ray traced once:
        # the analyses of the design's pixels draw their rays from this tracer, which hands
        # out again the rays it traced (tests/passcount.py counts its passes, in the
        # report's and the quick report's tests)
        tracer = PixelTracer(design, replay=True, passes=passes)
        shown = dict(traced, progress=progress)
        g = run(ghost_section, design, work, **shown, tracer=tracer)
        # the spots take a colour scanner's channels one by one (the widest the headline)
        sp = run(spot_section, design, work, **shown, tracer=tracer, optics=opt)
        psfs = run(psf_section, design, work, **shown)
        clock.lap("ghosts_spots_psf")
        concepts = (
            run(concept_section, design, g, work, **traced, tracer=tracer) if work.paper else None
        )
        clock.lap("concepts")
        rm = run(rmtf_section, design, work, **shown, tracer=tracer, dof_dpi=dpi, optics=opt)
        eff = run(efficiency_section, design, g, work, **traced, optics=opt, tracer=tracer)
        diffraction = run(diffraction_section, design)
        clock.lap("quality")
        wave = run(
            wave_section, design, work, seed=seed, dof_dpi=dpi, tracer=tracer, optics=opt,
            progress=progress,
        )  # fmt: skip
        clock.lap("ray_vs_wave")
        scans = run(
            scan_section,
            design,
            work,
            **traced,
            tracer=tracer,
            rmtf_section=rm,
            chart_dpi=dpi,
            optics=opt,  # a colour scanner's grey scans: its LEDs lit together (grey_light)
            also_z_mm=restoration_heights(work),  # one build of the kernels for both
        )
        clock.lap("scans")
        restoration = run(
            restoration_section, design, work, **traced, tracer=tracer, dof_dpi=dpi, optics=opt,
            kernels=getattr(measured(scans), "kernels", None),
        )  # fmt: skip
        clock.lap("restoration")
        fitted = None if fit is None else measure(fit_section, fit, design)
        figures = section_figures(
            design,
            ghosts=g,
            spots=sp,
            psfs=psfs,
            rmtf=rm,
            efficiency=eff,
            diffraction=diffraction,
            scans=scans,
            restoration=restoration,
            chart_dpi=dpi,
            wave=wave,
            fit=fitted,
        )
        # each figure drawn by a background process that is idle (while the studies run
        # on), or every other one by the drawer (no studies), else here: here first
        drawing = background.share(png, figures)
        for name in [n for n, task in drawing.items() if task is None]:
            write_atomic(tmp / name, png(*figures[name]))
        for name, task in drawing.items():
            if task is not None:
                write_atomic(tmp / name, background.done_or_here(task, png, figures[name]))
        names = list(figures)
        clock.lap("figures")
        # each study's figure as soon as that study is done, while the others run on
        done: dict = {}
        drawing_s = 0.0
        for key in background.as_completed():
            res = measure(background.result, key)
            if key == "parameter_study" and measured(res) is not None:
                # the row that is this design: its headline analyses
                res = measure(headline_study, res, design, g, rm, fresnel)
            done[key] = res
            fig = study_figure(key)
            if fig is None or measured(res) is None:
                continue
            t_draw = time.perf_counter()
            name, plot = fig
            save_figure(plot(res), tmp / name)
            names.append(name)
            drawing_s += time.perf_counter() - t_draw
        rodlens = measure(rodlens_section, design, eff, rm, done.get("rodlens"), **traced)
        if measured(rodlens) is not None:
            for name, (plot, *args) in rodlens_figures(rodlens["rows"]).items():
                save_figure(plot(*args), tmp / name)
                names.append(name)
        clock.lap("wait_for_studies")  # less the study figures, drawn while the others ran on
        clock.laps["wait_for_studies"] -= drawing_s
        clock.laps["study_figures"] = drawing_s
        signal = needs(efficiency=eff) or measure(signal_and_noise, design, eff)
        data = {
            "provenance": provenance(design, seed) | {"fresnel": fresnel},
            "quick": quick,
            "left_out": list(work.left_out),
            "reduced": list(work.reduced),
            "design": design.model_dump(mode="json"),
            "optics": opt.to_dict(),
            # a colour scanner's analyses of one light, where they differ (ray optics)
            "optics_one_light": None if one == opt else one.to_dict(),
            "stack": stack_rows(design),
            "ghosts": as_data(g),
            "spots": as_data(sp),
            "psf": as_data(psfs, lambda ps: [p.to_dict() for p in ps]),
            "concepts": as_data(concepts),
            "rmtf": as_data(rm, lambda r: r.result.to_dict()),
            "rmtf_paraxial_own": as_data(rm, lambda r: r.paraxial.to_dict()),
            "rmtf_traced_own": as_data(rm, lambda r: r.own.to_dict()),
            "chart_profiles": as_data(rm, lambda r: r.profiles),
            "efficiency": as_data(eff),
            "signal": as_data(signal),
            "diffraction": as_data(diffraction),
            "ray_vs_wave": as_data(wave),
            "model_vs_measurement": as_data(fitted),
            "parameter_study": as_data(done.get("parameter_study")),
            "scans": as_data(scans),
            "restoration": as_data(restoration),
            "search": as_data(done.get("search")),
            "tolerance": as_data(done.get("tolerance")),
            "rodlens": as_data(rodlens),
            "figures": sorted(names),
            "elapsed_s": time.perf_counter() - t0,
            "section_elapsed_s": clock.laps,
            # each background study's seconds in its process (wall, CPU)
            "study_elapsed_s": background.seconds(),
        }
        data["paper_vs_model"] = as_data(measure(paper_vs_model, data)) if work.paper else None
        paper = design.fingerprint() == load_design(PAPER_PRESET).fingerprint()
        data["summary"] = as_data(measure(summary, data, parse_report_spec(spec), paper=paper))
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
