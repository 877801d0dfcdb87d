"""`opticalstamp report`: every analysis of a design as JSON, PNG and one HTML page."""

from __future__ import annotations

import time
from pathlib import Path

from ..analysis.ghosts import analyse_ghosts
from ..analysis.spots import psf, spots
from ..design import Design, load_design
from ..io.files import provenance, replace_folder, save_figure, to_json, write_atomic
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import output_pitch
from ..units import dpi_of_pitch
from .html import page

Z_MM = (0.0, 1.0, 2.0, 3.0, 4.0)
CONCEPTS = ("fig1b", "fig1c", "fig1d", "three-layer-single-row", "paper2016")


def build_report(
    design: Design,
    out_dir: str | Path,
    *,
    seed: int = 0,
    n_rays: int = 1 << 22,
    fresnel: bool = False,
    progress: bool = False,
) -> dict:
    """Run every analysis and write report.json, PNG figures and index.html to out_dir.

    ``out_dir`` is replaced as a whole once everything is computed and written (see
    :func:`opticalstamp.atomic.replace_folder`): a run that fails or is killed leaves the
    previous report as it was.
    """
    from . import plotting

    out = Path(out_dir)
    t0 = time.perf_counter()
    tracer = PixelTracer(design)  # one pilot per pixel for every traced analysis below
    g = analyse_ghosts(
        design, z_mm=Z_MM, seed=seed, fresnel=fresnel, progress=progress, tracer=tracer
    )
    sp = spots(
        design,
        z_mm=Z_MM,
        seed=seed,
        n_rays=n_rays,
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
            n_rays=n_rays,
            fresnel=fresnel,
            progress=progress,
        )
        for x in (0.0, output_pitch(design) / 2)  # a pixel's axis and half a pitch off
    ]
    concepts = []
    for name in CONCEPTS:
        c = analyse_ghosts(load_design(name), z_mm=(0.0,), seed=seed, fresnel=fresnel)
        concepts.append(
            {
                "design": name,
                "etendue_own_um2sr": c.etendue_own_um2sr,
                "etendue_ghost_um2sr": c.etendue_ghost_um2sr,
                "ghost_fraction": c.ghost_fraction,
                "nearest_ghost_um_z0": c.landing["0"]["nearest_um"],
            }
        )
    quality = _quality(design, g, seed=seed, fresnel=fresnel, progress=progress, tracer=tracer)
    scans = _scans(design, seed=seed, fresnel=fresnel)
    study = _search_and_tolerance(design, seed=seed)
    figs = {
        "ghosts.png": plotting.plot_ghosts(g),
        "spots.png": plotting.plot_spots(sp),
        "psf_x0.png": plotting.plot_psf(psfs[0]),
        "psf_x42.png": plotting.plot_psf(psfs[1]),
        "rmtf.png": plotting.plot_rmtf(quality["rmtf_result"]),
        "chart_profiles.png": plotting.plot_chart_profiles(quality["profiles"]),
        "efficiency.png": plotting.plot_efficiency(quality["efficiency_result"]),
        "diffraction.png": plotting.plot_diffraction(quality["slit_result"]),
        "study.png": plotting.plot_study(quality["study_result"]),
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
        "pareto.png": plotting.plot_pareto(study.pop("search_result")),
        "tolerance.png": plotting.plot_tolerance(study.pop("tolerance_result")),
        "scan_tilt.png": plotting.plot_scan_panels(
            scans.pop("tilt_panels"), "text on a page tilted from 0 to 4 mm"
        ),
    }
    data = {
        "provenance": provenance(design, seed) | {"fresnel": fresnel},
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
        "parameter_study": quality["study_result"].to_dict(),
        "scans": scans,
        "search": study["search"],
        "tolerance": study["tolerance"],
        "elapsed_s": time.perf_counter() - t0,
    }
    with replace_folder(out) as tmp:  # the folder is replaced as a whole, or not at all
        for name, fig in figs.items():
            save_figure(fig, tmp / name)
        write_atomic(tmp / "report.json", to_json(data))
        write_atomic(tmp / "index.html", page(design, data))
    return data


def _quality(
    design: Design, g, *, seed: int, fresnel: bool, progress: bool, tracer: PixelTracer
) -> dict:
    """RMTF and depth of field, chart profiles, efficiency, diffraction, parameter study."""
    import numpy as np

    from ..analysis.diffraction import design_slit_case, diffraction_budget
    from ..analysis.efficiency import efficiency
    from ..analysis.lsf import traced_folded_lsf
    from ..analysis.paper_study import parameter_study
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
    zs = np.asarray(DEFAULT_Z_MM)
    lsf = traced_folded_lsf(
        design,
        z_mm=zs,
        periods_um=periods,
        seed=seed,
        fresnel=fresnel,
        progress=progress,
        tracer=tracer,
    )
    res = rmtf_from_lsf(lsf, design, dpi=dpis, seed=seed)
    own = rmtf(design, dpi=dpis, z_mm=zs, ghosts=False, seed=seed, fresnel=fresnel, tracer=tracer)
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
    return {
        "rmtf_result": res,
        "rmtf_own": own,
        "rmtf_paraxial": par,
        "profiles": profiles,
        "efficiency_result": efficiency(design, seed=seed, fresnel=fresnel, ghosts=g),
        "slit_result": design_slit_case(design),
        "budget": diffraction_budget(design),
        "study_result": parameter_study(design, seed=seed, progress=progress),
    }


def _scans(design: Design, *, seed: int, fresnel: bool) -> dict:
    """Simulated scans of the built-in charts (paper Figs. 8, 9, 12) and their measures."""
    import numpy as np

    from ..analysis.rmtf import rmtf
    from ..imaging.charts import bar_chart, line_chart, text_chart
    from ..imaging.heightmap import shape_map
    from ..imaging.measure import measure_rmtf
    from ..imaging.ocr import OCRUnavailable, character_error_rate, recognise, tesseract_available
    from ..imaging.scan import ScanSettings, simulate_scan

    dpi = 1200.0
    # the charts are printed on a larger white page; Fresnel losses as in the analyses
    page = ScanSettings(surround=1.0, fresnel=fresnel)
    text, truth = text_chart(dpi)
    res: dict = {"text_panels": [], "ocr": [], "profiles": [], "bar_panels": []}
    for z in (0.5, 1.5, 2.5):
        r = simulate_scan(text, dpi, design, z_mm=z, seed=seed, settings=page)
        res["text_panels"].append((f"Z = {z:g} mm", r.image))
        if tesseract_available():
            from ..io.files import linear_to_srgb

            try:
                got = recognise(linear_to_srgb(r.image), r.dpi)
                res["ocr"].append({"z_mm": z, "cer": character_error_rate(truth, got)})
            except OCRUnavailable:
                pass
    bars = bar_chart(dpi, chart_dpi=(200.0,), block_mm=10.0, height_mm=4.0)
    # RMTF compared on the own path: the chart is a finite patch on a white page, so its
    # ghost background differs from the infinite chart of the computed RMTF
    ref = rmtf(design, dpi=(200.0,), z_mm=(0.5, 3.5), ghosts=False, seed=seed, window_um=8000.0)
    for iz, z in enumerate((0.5, 3.5)):
        r = simulate_scan(bars, dpi, design, z_mm=z, seed=seed, settings=page)
        own = simulate_scan(bars, dpi, design, z_mm=z, seed=seed, ghosts=False, settings=page)
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
    from ..imaging.charts import edge_chart
    from ..imaging.measure import sfr_xy

    edge = edge_chart(dpi)
    res["sfr"] = []
    for z in (0.5, 3.5):
        r = simulate_scan(edge, dpi, design, z_mm=z, seed=seed, settings=page)
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
    res["line_panels"] = [("document (1200 dpi)", lines)] + [
        (f"Z = {z:g} mm", simulate_scan(lines, dpi, design, z_mm=z, seed=seed, settings=page).image)
        for z in (0.5, 3.5)
    ]
    hm = shape_map("tilt:0:4", text.shape[0] * 25.4 / dpi, text.shape[1] * 25.4 / dpi)
    tilt = simulate_scan(text, dpi, design, height_map=hm, seed=seed, settings=page)
    res["tilt_panels"] = [("tilt: Z = 0 mm at the top, 4 mm at the bottom", tilt.image)]
    res["profiles"] = [
        p | {"x_mm": p["x_mm"].tolist(), "profile": p["profile"].tolist()} for p in res["profiles"]
    ]
    res["settings"] = f"default sensor model, noise on, ghost light on, white surround, seed {seed}"
    return res


def _search_and_tolerance(design: Design, *, seed: int) -> dict:
    """A compact design search around the design and a tolerance study (the CLI's
    `search` and `tolerance` run the full budgets)."""
    from ..studies.search import search
    from ..studies.tolerance import tolerance

    out: dict = {}
    rect = all(m.shape != "circle" for m in design.masks)
    if not rect:
        return {"search": None, "tolerance": None, "search_result": None, "tolerance_result": None}
    dpi = dpi_of_pitch(output_pitch(design))
    sr = search(design, dpi=dpi, population=24, generations=10, seed=seed, ghost_rays=1 << 16)
    tr = tolerance(design, samples=200, seed=seed, spec="dof>=2.2,ghost<=0.2")
    out["search"] = sr.to_dict()
    out["tolerance"] = tr.to_dict()
    out["search_result"], out["tolerance_result"] = sr, tr
    return out
