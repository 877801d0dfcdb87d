"""The report's simulated scans (paper Figs. 8, 9, 12): the built-in charts scanned at
several heights with the design's kernels, and what is measured on them (OCR, RMTF of the
bar chart, slanted-edge SFR)."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..analysis.responsivity import RAY, Optics
from ..design import Design
from ..raytrace.pixel import PixelTracer
from .section import measured
from .work import Work


@dataclass(frozen=True)
class ScanSection:
    """The simulated scans: ``data``, report.json's "scans" (OCR, profiles, SFR, the
    chart, the settings), ``panels``, the scanned images the figures show (figure
    name without .png -> list of (title, image)), and ``kernels``, the
    :class:`~opticalstamp.imaging.kernels.KernelCache` they were scanned with (holding
    the heights of ``also_z_mm`` too)."""

    data: dict
    panels: dict
    kernels: object = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        return self.data


def scan_section(
    design: Design,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    tracer: PixelTracer,
    rmtf_section=None,
    chart_dpi: float = 200.0,
    optics: Optics = RAY,
    also_z_mm: tuple[float, ...] = (),
) -> ScanSection:
    """Simulated scans of the built-in charts (paper Figs. 8, 9, 12) and their measures.

    ``chart_dpi``: the bar chart scanned (the depth-of-field chart). ``rmtf_section``: the RMTF
    section (:class:`~opticalstamp.report.quality.RmtfSection`, or not measurable), whose
    own-path folded LSF at 0.5 and 3.5 mm and ``chart_dpi`` gives the computed RMTF here
    where it was traced alike (same rays, no Fresnel losses): that RMTF is then not traced
    again. A measurement that the scan does not allow (an edge too blurred for an SFR) is
    reported as not measurable, with the reason, and the section goes on. ``also_z_mm``:
    heights of later scans at one height each (the restoration's,
    :func:`~opticalstamp.report.restoration.restoration_heights`) whose kernels are built
    with these, each row's wave kernels by one run of the wave engine; the section's
    ``kernels`` hold them.
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

    own_lsf = getattr(measured(rmtf_section), "lsf_own", None)
    dpi = work.scan_dpi
    # the charts are printed on a larger white page; Fresnel losses as in the analyses
    wave = optics.engine == "wave"  # the scans through the kernels of the report's optics
    page = ScanSettings(
        surround=1.0,
        fresnel=fresnel,
        kernel_rays=work.kernel_rays,
        sensor=design.electronics,
        kernel="wave" if wave else "auto",
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
        z_mm=tuple(
            dict.fromkeys((0.5, 1.5, 2.5, 3.5) + (small_z if ocr else ()) + tuple(also_z_mm))
        ),
        height_maps=[hm],
        settings=page,
        seed=seed,
        tracer=tracer,
    )

    def scan(doc, **kw):
        return simulate_scan(doc, dpi, design, seed=seed, settings=page, kernels=kernels, **kw)

    res: dict = {"ocr": [], "profiles": []}
    panels: dict = {"scan_text": [], "scan_text_zoom": [], "scan_bars": []}
    reads = []  # the scans to read, read at once below (one Tesseract process per core)

    def read(r, z: float, truth: str, face: str, points: float) -> None:
        from ..io.files import linear_to_srgb

        reads.append(((linear_to_srgb(r.image), r.dpi), (truth, face, points, z)))

    for z in (0.5, 1.5, 2.5):
        r = scan(text, z_mm=z)
        panels["scan_text"].append((f"Z = {z:g} mm", r.image))
        h, w = r.image.shape
        rows, cols = clear_crop(text, dpi / r.dpi, slice(h // 12, h // 6), slice(0, w // 7))
        # the first words, pixels enlarged: the blur by height
        panels["scan_text_zoom"].append((f"Z = {z:g} mm", r.image[rows, cols]))
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
    if wave:  # the wave engine's light in its band (own path and near crosstalk), under
        # the light of the kernels (a colour scanner's grey light: its LEDs lit together)
        from ..analysis.responsivity import folded_lsf
        from ..analysis.spectrum import grey_light
        from ..analysis.wavecompare import WaveFolds
        from ..imaging.kernels import GREY_POINTS

        folds = WaveFolds(
            design, 3.5, sampling=optics.sampling, spectrum=grey_light(design, GREY_POINTS),
            fresnel=optics.fresnel,
        )  # fmt: skip
        near = folded_lsf(
            design, z_mm=(0.5, 3.5), periods_um=[period_of_dpi(chart_dpi)], optics=optics,
            ghosts=False, fresnel=optics.fresnel, wave=folds,
        )  # fmt: skip
        ref = rmtf_from_lsf(near, design, dpi=ref_dpi, optics=optics, **ref_args)
    elif sub is not None:
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
        panels["scan_bars"].append((f"Z = {z:g} mm", r.image))
        res["profiles"].append(
            {
                "z_mm": z,
                "x_mm": ((np.arange(mid.size) + 0.5) * r.pitch_um / 1000).tolist(),
                "profile": mid.tolist(),
                "rmtf_measured": _chart_block(blocks, chart_dpi),
                "rmtf_computed_max": ref.rmtf_max[key][iz],
                "rmtf_computed_min": ref.rmtf_min[key][iz],
            }
        )
    res["sfr"] = _sfr(scan, edge_chart(dpi), chart_dpi, sfr_xy)
    lines = line_chart(dpi, size_mm=12.0)
    panels["scan_lines"] = [(f"document ({dpi:g} dpi)", lines)] + [
        (f"Z = {z:g} mm", scan(lines, z_mm=z).image) for z in (0.5, 3.5)
    ]
    tilt = scan(text, z_mm=None, height_map=hm)
    panels["scan_tilt"] = [("tilt: Z = 0 mm at the top, 4 mm at the bottom", tilt.image)]
    res["chart_dpi"] = float(chart_dpi)
    res["raster_dpi"] = float(dpi)  # the charts' own pixels (work.scan_dpi)
    res["optics"] = "wave" if wave else "ray"  # the engine of the kernels (the verdict says)
    res["settings"] = (
        f"{'wave' if wave else 'ray'}-optics kernels, "
        f"the design's sensor electronics, noise on, ghost light on, white surround, seed {seed}"
        + ("" if work.ocr else f"; {dpi:g}-dpi charts, no OCR (quick report)")
    )
    return ScanSection(data=res, panels=panels, kernels=kernels)


def _chart_block(blocks: list[dict], chart_dpi: float) -> float:
    """The RMTF of the chart's bar block: the longest block found at the chart's frequency
    (a few periods of ripple beside it, a diffraction fringe at the chart's edge, are not
    it); NaN where none is found."""
    found = [b for b in blocks if abs(b["dpi"] / chart_dpi - 1) < 0.06]
    return max(found, key=lambda b: b["n_periods"])["rmtf"] if found else float("nan")


def _sfr(scan, edge, chart_dpi: float, sfr_xy) -> list[dict]:
    """Slanted-edge SFR of the edge chart scanned at 0.5 and 3.5 mm, at the depth-of-field
    chart and half its frequency (200, 100 dpi at 300); a row "not_measurable" with the
    reason where the edge is too blurred (or ghost-ridden) to measure."""
    out = []
    for z in (0.5, 3.5):
        r = scan(edge, z_mm=z)
        try:
            found = sfr_xy(r.image, r.dpi, at_dpi=(chart_dpi / 2, chart_dpi))
        except ValueError as err:
            out.append({"z_mm": z, "not_measurable": str(err)})
            continue
        for axis, v in found.items():
            out.append(
                {
                    "z_mm": z,
                    "axis": axis,
                    "mtf50_cy_per_mm": v["mtf50_cy_per_mm"],
                    "sfr_at_dpi": v["sfr_at_dpi"],
                }
            )
    return out
