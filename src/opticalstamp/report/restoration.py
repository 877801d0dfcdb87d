"""The report's restoration section (issue 13): the scan deconvolved with the scanner's
own blur at its known height, its depth of field against the raw scan's, text crops raw
and restored, and OCR of small text before and after."""

from __future__ import annotations

from dataclasses import dataclass

from ..analysis.responsivity import RAY, Optics
from ..design import Design
from ..raytrace.pixel import PixelTracer
from .work import Work

#: the type size (points) of the restored text crops
PANEL_POINTS = 6.0
#: the heights (mm) of the restored text crops
PANEL_Z_MM = (2.5, 3.5, 4.5)
#: the study's heights (mm) in a quick report
QUICK_STUDY_Z_MM = (1.5, 3.0, 4.5)


def restoration_heights(work: Work) -> tuple[float, ...]:
    """The heights (mm) the section scans at (each its own scan): those of its study and
    its text crops; kernels built for them (:func:`restoration_section`'s ``kernels``)
    serve it whole."""
    from ..studies.restoration import STUDY_Z_MM

    study = QUICK_STUDY_Z_MM if not work.studies else STUDY_Z_MM
    return tuple(dict.fromkeys(float(z) for z in study + PANEL_Z_MM))


@dataclass(frozen=True)
class RestorationSection:
    """The restoration section: ``data``, report.json's "restoration" (the study against
    height, the panels' layout, OCR, the settings), and ``panels``, the text crops raw
    and restored (list of (title, image), ``data["panel_cols"]`` to a row)."""

    data: dict
    panels: list

    def to_dict(self) -> dict:
        return self.data


def restoration_section(
    design: Design,
    work: Work,
    *,
    seed: int,
    fresnel: bool,
    tracer: PixelTracer,
    dof_dpi: float,
    optics: Optics = RAY,
    kernels=None,
) -> RestorationSection:
    """Restoration with the known blur: the study against height (on the ``dof_dpi``
    chart), text crops raw and restored, OCR of small text before and after (a quick
    report: Wiener only, three heights, no OCR). ``kernels``: a
    :class:`~opticalstamp.imaging.kernels.KernelCache` of this design with this section's
    settings and seed holding each of :func:`restoration_heights` (the scans' section
    builds them with its own: one build of each row's kernels per report); default: built
    here."""
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

    # scanned and restored through the kernels of the report's optics (wave: diffraction
    # blurs the scan, and the restoration knows it)
    page = ScanSettings(
        surround=1.0,
        fresnel=fresnel,
        kernel_rays=work.kernel_rays,
        sensor=design.electronics,
        kernel="wave" if optics.engine == "wave" else "auto",
    )
    quick = not work.studies
    methods = ("wiener",) if quick else METHODS
    study = restoration_study(
        design,
        z_mm=QUICK_STUDY_Z_MM if quick else STUDY_Z_MM,
        methods=methods,
        settings=page,
        seed=seed,
        tracer=tracer,
        dpi=dof_dpi,
        kernels=kernels,
    )
    dpi = work.scan_dpi
    panel_z = PANEL_Z_MM
    # OCR where it tells: 2.5-pt text past the depth of field, 6-pt text at the end
    reads = ((2.5, 3.5), (2.5, 4.5), (6.0, 4.5)) if work.ocr and tesseract_available() else ()
    if kernels is None:
        kernels = prepare_kernels(design, z_mm=panel_z, settings=page, seed=seed, tracer=tracer)
    ocr_methods = ("wiener",) if quick else ("wiener", "tv")
    panels, ocr = [], []
    charts = {
        p: text_chart(dpi, p) for p in dict.fromkeys((PANEL_POINTS,) + tuple(p for p, _ in reads))
    }

    def restored(img, z, methods, region=None):
        ok = output_kernel(design, z, settings=page, seed=seed, kernels=kernels)
        sigma = noise_sigma(page.sensor, ok.white, MODEL_ERROR)
        part = img if region is None else img[region]
        out = {"raw": part}
        for m in methods:
            out[m] = restore(part, ok, method=m, sigma=sigma, surround=1.0).image
        return out

    doc = charts[PANEL_POINTS][0]
    for z in panel_z:
        r = simulate_scan(doc, dpi, design, z_mm=z, seed=seed, settings=page, kernels=kernels)
        h, w = r.image.shape
        crop = clear_crop(  # no letter cut at the crop's edges
            doc,
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
        text, truth = charts[points]
        r = simulate_scan(text, dpi, design, z_mm=z, seed=seed, settings=page, kernels=kernels)
        for name, img in restored(r.image, z, ocr_methods).items():
            image = (linear_to_srgb(np.clip(img, 0, 1)), r.dpi)
            pending.append((image, {"points": points, "z_mm": z, "version": name}, truth))
    try:
        texts = recognise_all([image for image, _, _ in pending])
    except OCRUnavailable:
        texts = []
    for got, (_, entry, truth) in zip(texts, pending, strict=False):
        ocr.append({**entry, "cer": character_error_rate(truth, got)})
    data = {
        "study": study,
        "panel_cols": 1 + len(methods),
        "panel_points": PANEL_POINTS,
        "ocr": ocr,
        "optics": page.kernel if page.kernel == "wave" else "ray",  # the kernels' engine
        "settings": "the design's electronics, noise and ghost light on, white surround, "
        f"seed {seed}; the height known",
    }
    return RestorationSection(data=data, panels=panels)
