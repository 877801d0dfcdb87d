"""`opticalstamp report`: every analysis of a design as JSON, PNG and one HTML page.

The work is arranged so that nothing is computed twice: one
:class:`~opticalstamp.raytrace.pixel.PixelTracer` (one pilot run per pixel) serves the
traced analyses and the scan kernels; the folded LSF is traced once for all light and the
own path (:func:`~opticalstamp.analysis.lsf.traced_folded_lsf_pair`); the scan kernels of
every simulated scan come from one trace per pixel row
(:func:`~opticalstamp.imaging.scan.prepare_kernels`); the parameter study, the design
search and the tolerance study run in processes of their own while the other sections run
here (every analysis and evaluation carries its own seed, so no number depends on where it
runs).

``quick`` reduces the work (fewer rays and distances, 600-dpi scans, no OCR) and leaves
out the parameter study, the search and the tolerance study; the page and report.json
say so.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ..analysis.ghosts import analyse_ghosts
from ..analysis.paper_study import with_headline
from ..analysis.spots import psf, spots
from ..defaults import RAYS_LSF, RAYS_MAP
from ..design import Design, load_design
from ..io.files import provenance, replace_folder, save_figure, to_json, write_atomic
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


def report_work(quick: bool = False, n_rays: int = RAYS_MAP) -> Work:
    """The work of a full report (``n_rays`` for its maps), or of a quick one."""
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
            "OCR of the simulated text scans",
            "the larger sensitive area of the efficiency section",
        ),
        reduced=(
            "ghost analysis: 2^20 rays (not run to its precision targets), at Z = 0, 2, 4 mm",
            f"spots and PSFs: {map_rays:,} rays; spots at Z = 0, 2, 4 mm",
            "Fig. 1 concepts: 2^18 rays each",
            "RMTF: 2^19 rays per pixel row, Z every 0.5 mm",
            "simulated scans: 600-dpi charts, kernels from 2^18 rays",
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

    Returns
    -------
    dict
        What report.json holds.
    """
    from . import plotting

    t0 = time.perf_counter()
    clock = _Clock()
    work = report_work(quick, n_rays)
    jobs = _studies(design, seed) if work.studies else {}
    # the folder is replaced as a whole once everything is written, or not at all
    with replace_folder(Path(out_dir)) as tmp, _Background(jobs) as background:
        tracer = PixelTracer(design)  # one pilot per pixel for every traced analysis below
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
        concepts = _concepts(design, g, work, seed=seed, fresnel=fresnel)
        clock.lap("concepts")
        quality = _quality(
            design, g, work, seed=seed, fresnel=fresnel, progress=progress, tracer=tracer
        )
        clock.lap("quality")
        scans = _scans(design, work, seed=seed, fresnel=fresnel, tracer=tracer)
        clock.lap("scans")
        figures = {
            "ghosts.png": plotting.plot_ghosts(g),
            "spots.png": plotting.plot_spots(sp),
            "psf_x0.png": plotting.plot_psf(psfs[0]),
            "psf_x42.png": plotting.plot_psf(psfs[1]),
            "rmtf.png": plotting.plot_rmtf(quality["rmtf_result"]),
            "chart_profiles.png": plotting.plot_chart_profiles(quality["profiles"]),
            "efficiency.png": plotting.plot_efficiency(quality["efficiency_result"]),
            "diffraction.png": plotting.plot_diffraction(quality["slit_result"]),
            "scan_text.png": plotting.plot_scan_panels(
                scans.pop("text_panels"), "8-pt text (paper Fig. 8)"
            ),
            "scan_bars.png": plotting.plot_scan_panels(
                scans.pop("bar_panels"), "200-dpi chart (paper Fig. 12 a, b)", cols=2
            ),
            "scan_profiles.png": plotting.plot_scan_profiles(scans["profiles"]),
            "scan_lines.png": plotting.plot_scan_panels(
                scans.pop("line_panels"), "fine line work (paper Fig. 9 analogue)", cols=3
            ),
            "scan_tilt.png": plotting.plot_scan_panels(
                scans.pop("tilt_panels"), "text on a page tilted from 0 to 4 mm"
            ),
        }
        for name, fig in figures.items():  # while the studies run on
            save_figure(fig, tmp / name)
        names = list(figures)
        clock.lap("figures")
        st, sr, tr = (background.result(k) for k in ("parameter_study", "search", "tolerance"))
        if st is not None:  # the row that is this design: its headline analyses, not a re-run
            st = with_headline(st, design, g, quality["rmtf_result"], fresnel)
        clock.lap("wait_for_studies")
        studies = {
            "study.png": (st, plotting.plot_study),
            "pareto.png": (sr, plotting.plot_pareto),
            "tolerance.png": (tr, plotting.plot_tolerance),
        }
        for name, (res, plot) in studies.items():
            if res is not None:
                save_figure(plot(res), tmp / name)
                names.append(name)
        clock.lap("study_figures")
        data = {
            "provenance": provenance(design, seed) | {"fresnel": fresnel},
            "quick": quick,
            "left_out": list(work.left_out),
            "reduced": list(work.reduced),
            "design": design.model_dump(mode="json"),
            "ghosts": g.to_dict(),
            "spots": sp.to_dict(),
            "psf": [p.to_dict() for p in psfs],
            "concepts": concepts,
            "rmtf": quality["rmtf_result"].to_dict(),
            "rmtf_paraxial_own": quality["rmtf_paraxial"].to_dict(),
            "rmtf_traced_own": quality["rmtf_own"].to_dict(),
            "chart_profiles": quality["profiles"],
            "efficiency": quality["efficiency_result"].to_dict(),
            "diffraction": quality["slit_result"].to_dict() | {"budget": quality["budget"]},
            "parameter_study": st.to_dict() if st is not None else None,
            "scans": scans,
            "search": sr.to_dict() if sr is not None else None,
            "tolerance": tr.to_dict() if tr is not None else None,
            "figures": sorted(names),
            "elapsed_s": time.perf_counter() - t0,
            "section_elapsed_s": clock.laps,
        }
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
) -> dict:
    """RMTF and depth of field, chart profiles, efficiency, diffraction."""
    import numpy as np

    from ..analysis.diffraction import design_slit_case, diffraction_budget
    from ..analysis.efficiency import efficiency
    from ..analysis.lsf import traced_folded_lsf_pair
    from ..analysis.rmtf import (
        DEFAULT_Z_MM,
        PAPER_DPI,
        chart_waveform,
        period_of_dpi,
        rmtf,
        rmtf_from_lsf,
    )
    from ..imaging.measure import measure_rmtf

    dpis = list(PAPER_DPI)
    periods = [period_of_dpi(d) for d in dpis]
    zs = np.asarray(DEFAULT_Z_MM if work.lsf_z_mm is None else work.lsf_z_mm)
    # all light and the own path alone from one trace per row
    lsf, lsf_own = traced_folded_lsf_pair(
        design,
        z_mm=zs,
        periods_um=periods,
        n_rays=work.lsf_rays,
        seed=seed,
        fresnel=fresnel,
        progress=progress,
        tracer=tracer,
    )
    res = rmtf_from_lsf(lsf, design, dpi=dpis, seed=seed)
    own = rmtf_from_lsf(lsf_own, design, dpi=dpis, seed=seed)
    rect = all(m.shape != "circle" for m in design.masks)
    par = rmtf(design, dpi=dpis, z_mm=zs, method="paraxial") if rect else own
    # Fig. 12 analogue: the merged line's waveform for the 200-dpi chart at 0.5 and 3.5 mm,
    # and the RMTF measured back from it as from an image
    ip = dpis.index(200.0)
    profiles = []
    px_um = output_pitch(design) / 4  # waveform drawn at 4 samples per output pixel
    for z in (0.5, 3.5):
        iz = int(np.argmin(np.abs(zs - z)))
        shift = res.meta["best_shift_um"]["200"][iz]
        x, sig = chart_waveform(lsf, design, ip, iz, shift)
        img = np.repeat(sig / sig.max(), 4)[None, :].repeat(8, axis=0)
        blocks = measure_rmtf(img, dpi_of_pitch(px_um))
        profiles.append(
            {
                "z_mm": float(zs[iz]),
                "dpi": 200.0,
                "shift_um": shift,
                "x_um": x.tolist(),
                "signal": (sig / sig.max()).tolist(),
                "rmtf_computed": res.rmtf_max["200"][iz],
                "rmtf_measured_from_waveform": blocks[0]["rmtf"] if blocks else None,
            }
        )
    eff = efficiency(design, seed=seed, fresnel=fresnel, ghosts=g, area_scales=work.area_scales)
    return {
        "rmtf_result": res,
        "rmtf_own": own,
        "rmtf_paraxial": par,
        "profiles": profiles,
        "efficiency_result": eff,
        "slit_result": design_slit_case(design),
        "budget": diffraction_budget(design),
    }


def _scans(design: Design, work: Work, *, seed: int, fresnel: bool, tracer: PixelTracer) -> dict:
    """Simulated scans of the built-in charts (paper Figs. 8, 9, 12) and their measures."""
    import numpy as np

    from ..analysis.rmtf import rmtf
    from ..imaging.charts import bar_chart, edge_chart, line_chart, text_chart
    from ..imaging.heightmap import shape_map
    from ..imaging.measure import measure_rmtf, sfr_xy
    from ..imaging.ocr import OCRUnavailable, character_error_rate, recognise, tesseract_available
    from ..imaging.scan import ScanSettings, prepare_kernels, simulate_scan

    dpi = work.scan_dpi
    # the charts are printed on a larger white page; Fresnel losses as in the analyses
    page = ScanSettings(surround=1.0, fresnel=fresnel, kernel_rays=work.kernel_rays)
    text, truth = text_chart(dpi)
    hm = shape_map("tilt:0:4", text.shape[0] * 25.4 / dpi, text.shape[1] * 25.4 / dpi)
    # the kernels of every scan below, from one trace per pixel row
    kernels = prepare_kernels(
        design,
        z_mm=(0.5, 1.5, 2.5, 3.5),
        height_maps=[hm],
        settings=page,
        seed=seed,
        tracer=tracer,
    )

    def scan(doc, **kw):
        return simulate_scan(doc, dpi, design, seed=seed, settings=page, kernels=kernels, **kw)

    res: dict = {"text_panels": [], "ocr": [], "profiles": [], "bar_panels": []}
    for z in (0.5, 1.5, 2.5):
        r = scan(text, z_mm=z)
        res["text_panels"].append((f"Z = {z:g} mm", r.image))
        if work.ocr and tesseract_available():
            from ..io.files import linear_to_srgb

            try:
                got = recognise(linear_to_srgb(r.image), r.dpi)
                res["ocr"].append({"z_mm": z, "cer": character_error_rate(truth, got)})
            except OCRUnavailable:
                pass
    bars = bar_chart(dpi, chart_dpi=(200.0,), block_mm=10.0, height_mm=4.0)
    # RMTF compared on the own path: the chart is a finite patch on a white page, so its
    # ghost background differs from the infinite chart of the computed RMTF
    ref = rmtf(
        design,
        dpi=(200.0,),
        z_mm=(0.5, 3.5),
        ghosts=False,
        seed=seed,
        window_um=8000.0,
        n_rays=work.lsf_rays,
        tracer=tracer,
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
                "rmtf_computed_max": ref.rmtf_max["200"][iz],
                "rmtf_computed_min": ref.rmtf_min["200"][iz],
            }
        )
    edge = edge_chart(dpi)
    res["sfr"] = []
    for z in (0.5, 3.5):
        r = scan(edge, z_mm=z)
        for axis, v in sfr_xy(r.image, r.dpi).items():
            res["sfr"].append(
                {
                    "z_mm": z,
                    "axis": axis,
                    "mtf50_cy_per_mm": v["mtf50_cy_per_mm"],
                    "sfr100": v["sfr_at_dpi"]["100"],
                    "sfr200": v["sfr_at_dpi"]["200"],
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
    res["settings"] = (
        f"default sensor model, noise on, ghost light on, white surround, seed {seed}"
        + ("" if work.ocr else f"; {dpi:g}-dpi charts, no OCR (quick report)")
    )
    return res


def _one_numba_thread() -> None:  # pragma: no cover - runs in the background processes
    import numba

    numba.set_num_threads(1)


def _run_study(design: Design, seed: int):  # pragma: no cover - a background process
    """The study of the paper's unstated parameters."""
    from ..analysis.paper_study import parameter_study

    return parameter_study(design, seed=seed)


def _run_search(design: Design, seed: int):  # pragma: no cover - a background process
    """The compact design search of a report (the CLI's `search` runs the full budget)."""
    from ..studies.search import search

    dpi = dpi_of_pitch(output_pitch(design))
    return search(
        design, dpi=dpi, population=24, generations=10, seed=seed, ghost_rays=1 << 16, workers=1
    )


def _run_tolerance(design: Design, seed: int):  # pragma: no cover - a background process
    """The report's tolerance study (the CLI's `tolerance` runs more samples)."""
    from ..studies.tolerance import tolerance

    return tolerance(design, samples=200, seed=seed, spec="dof>=2.2,ghost<=0.2", workers=1)


def _studies(design: Design, seed: int) -> dict:
    """The report's studies as background jobs: name -> (function, arguments). The search
    and the tolerance study evaluate in closed form, which needs square holes."""
    jobs = {"parameter_study": (_run_study, (design, seed))}
    if all(m.shape != "circle" for m in design.masks):
        jobs["search"] = (_run_search, (design, seed))
        jobs["tolerance"] = (_run_tolerance, (design, seed))
    return jobs


class _Background:
    """Jobs that run in processes of their own (spawned, one numba thread each, one
    process per job), started at once while the report goes on here.

    Parameters
    ----------
    jobs : name -> (function, arguments); functions and results are pickled
    """

    def __init__(self, jobs: dict) -> None:
        self._pool = None
        self._jobs = {}
        if not jobs:
            return
        import multiprocessing as mp

        ctx = mp.get_context("spawn")  # no fork of numba's threads
        self._pool = ctx.Pool(len(jobs), initializer=_one_numba_thread)
        self._jobs = {name: self._pool.apply_async(fn, args) for name, (fn, args) in jobs.items()}

    def __enter__(self) -> _Background:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def result(self, name: str):
        """The result of job ``name`` (waits for it; re-raises its error), or None if it
        was not started."""
        return self._jobs[name].get() if name in self._jobs else None

    def close(self) -> None:
        """End the processes: at once where jobs are still running (the report failed)."""
        if self._pool is None:
            return
        if all(job.ready() for job in self._jobs.values()):
            self._pool.close()
        else:
            self._pool.terminate()
        self._pool.join()
        self._pool = None
