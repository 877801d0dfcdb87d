"""The report's figures: which plot draws each PNG from which section's result (a
section that is not measurable has no figure), and a figure as PNG bytes."""

from __future__ import annotations

from types import MappingProxyType

from ..design import Design
from ..io.files import figure_png
from .section import measured

#: the background studies' figures: job -> (file, the plot's name in
#: :mod:`opticalstamp.report.plotting`), drawn as each study is done
STUDY_FIGURES = MappingProxyType(
    {
        "parameter_study": ("study.png", "plot_study"),
        "search": ("pareto.png", "plot_pareto"),
        "tolerance": ("tolerance.png", "plot_tolerance"),
    }
)


def png(plot, *args) -> bytes:
    """``plot(*args)`` as PNG bytes (a figure drawn here or in a background process)."""
    return figure_png(plot(*args))


def section_figures(
    design: Design,
    *,
    ghosts,
    spots,
    psfs,
    rmtf,
    efficiency,
    diffraction,
    scans,
    restoration,
    chart_dpi: float,
    wave=None,
    fit=None,
) -> dict:
    """The figures of the sections computed here, in the page's order: file name ->
    (plot, its arguments); none for a section that is not measurable."""
    from . import plotting
    from .plotting.stack import plot_stack

    panels = plotting.plot_scan_panels
    figures: dict = {"stack.png": (plot_stack, design)}
    if measured(ghosts) is not None:
        figures["ghosts.png"] = (plotting.plot_ghosts, ghosts)
    if measured(spots) is not None:
        figures["spots.png"] = (plotting.plot_spots, spots)
    if measured(psfs) is not None:
        figures["psf_x0.png"] = (plotting.plot_psf, psfs[0])
        figures["psf_half_pitch.png"] = (plotting.plot_psf, psfs[1])
    if measured(rmtf) is not None:
        figures["rmtf.png"] = (plotting.plot_rmtf, rmtf.result)
        figures["chart_profiles.png"] = (plotting.plot_chart_profiles, rmtf.profiles)
    if measured(efficiency) is not None:
        figures["efficiency.png"] = (plotting.plot_efficiency, efficiency)
    if measured(diffraction) is not None:
        figures["diffraction.png"] = (plotting.plot_diffraction, diffraction.slit)
    if measured(wave) is not None:
        from .plotting.wave import plot_wave_report

        figures["raywave.png"] = (plot_wave_report, wave.comparison, wave.verdict)
    if fit is not None and measured(fit) is not None:
        from .fitsection import fit_figures

        figures |= fit_figures(fit)
    if measured(scans) is not None:
        p = scans.panels
        figures |= {
            "scan_text.png": (panels, p["scan_text"], "8-pt text (paper Fig. 8)"),
            "scan_text_zoom.png": (
                panels,
                p["scan_text_zoom"],
                "the first words of the 8-pt text, each scan pixel enlarged",
                1,
            ),
            "scan_bars.png": (
                panels,
                p["scan_bars"],
                f"{chart_dpi:g}-dpi chart (paper Fig. 12 a, b)",
                2,
            ),
            "scan_profiles.png": (plotting.plot_scan_profiles, scans.data["profiles"]),
            "scan_lines.png": (
                panels,
                p["scan_lines"],
                "fine line work (paper Fig. 9 analogue)",
                3,
            ),
            "scan_tilt.png": (panels, p["scan_tilt"], "text on a page tilted from 0 to 4 mm"),
        }
    if measured(restoration) is not None:
        r = restoration.data
        figures["restore_curves.png"] = (plotting.plot_restoration, r["study"])
        figures["restore_text.png"] = (
            panels,
            restoration.panels,
            f"{r['panel_points']:g}-pt text, scanned and restored (crops)",
            r["panel_cols"],
        )
    return figures


def study_figure(key: str):
    """(file name, plot) of background study ``key``'s figure; None where it has none."""
    if key not in STUDY_FIGURES:
        return None
    from . import plotting

    name, plot = STUDY_FIGURES[key]
    return name, getattr(plotting, plot)


def rodlens_figures(rows: list[dict]) -> dict:
    """The rod-lens section's figures: file name -> (plot, its arguments)."""
    from . import plotting

    return {
        "rodlens_contrast.png": (plotting.plot_compare_contrast, rows),
        "rodlens_light.png": (plotting.plot_compare_light, rows),
    }
