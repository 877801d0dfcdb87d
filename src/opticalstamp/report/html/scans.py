"""The page's "Simulated scans" section."""

from __future__ import annotations

import html

from .common import table, unmeasured


def scans_html(s: dict, pitch_um: float, ghost_span: str = "") -> str:
    """Simulated scans of the built-in charts (paper Figs. 8, 9, 12): OCR, the bar chart's
    RMTF measured against the computed one, slanted-edge SFR; ``ghost_span``: where the
    ghost light lands (:func:`~opticalstamp.report.html.optics.ghost_span`)."""
    missing = unmeasured("Simulated scans (paper Figs. 8, 9, 12)", s)
    if missing is not None:
        return missing
    chart = s.get("chart_dpi", 200.0)
    raster = s.get("raster_dpi", 1200.0)  # a report.json written before it was recorded
    at = [f"{chart / 2:g}", f"{chart:g}"]
    sfr = [
        [x["z_mm"], x["axis"], x["mtf50_cy_per_mm"], *(x["sfr_at_dpi"][k] for k in at)]
        if "not_measurable" not in x
        else [x["z_mm"], "x, y", f"not measurable: {x['not_measurable']}", None, None]
        for x in s["sfr"]
    ]
    # OCR: a row per text (face, size), a column per Z
    texts = list(dict.fromkeys((o.get("face", "sans"), o.get("points", 8.0)) for o in s["ocr"]))
    zs = sorted({o["z_mm"] for o in s["ocr"]})
    cer = {(o.get("face", "sans"), o.get("points", 8.0), o["z_mm"]): o["cer"] for o in s["ocr"]}
    ocr_rows = [
        [f"{p:g} pt {f}"] + [f"{cer[f, p, z]:.3f}" if (f, p, z) in cer else None for z in zs]
        for f, p in texts
    ]
    ocr_p = (
        "<p>Tesseract on scans of the text chart, character error rate: the 8-pt text above "
        "(paper Fig. 8) and the same text in smaller type, which shows where reading fails "
        "past the depth of field (<code>opticalstamp ocr-eval</code> gives more sizes and "
        "faces):</p>" + table(ocr_rows, ["text"] + [f"Z = {z:g} mm" for z in zs])
        if ocr_rows
        else ""
        if "no OCR (quick report)" in s["settings"]
        else "<p>(tesseract not installed: no OCR)</p>"
    )
    # under wave optics the scans' near field is the wave engine's band: own path and near
    # crosstalk, which its light does not separate
    near = (
        "the wave engine's light in its band: own path and near crosstalk"
        if s["settings"].startswith("wave-optics kernels")
        else "own path"
    )
    prof = [
        [p["z_mm"], p["rmtf_measured"], p["rmtf_computed_min"], p["rmtf_computed_max"]]
        for p in s["profiles"]
    ]
    return f"""<h2>Simulated scans (paper Figs. 8, 9, 12)</h2>
<p>Built-in charts at {raster:g} dpi through the scan simulation ({html.escape(s["settings"])}):
the document moves one {pitch_um:.1f} um line per period, the rows are merged with the line delay,
and dark/white shading correction is applied. See <code>opticalstamp scan</code>.</p>
<img src="scan_text.png"><img src="scan_text_zoom.png">{ocr_p}
<img src="scan_bars.png"><img src="scan_profiles.png">
<p>RMTF measured on simulated {chart:g}-dpi scans ({near}, ghost light off, noise on)
against the RMTF computed from the folded line-spread functions ({near}; minimum and
maximum over chart positions). With ghost light on they differ for a reason, not an error: ghost
light comes from {ghost_span or "far from the pixel's axis"}, so a finite chart on a white
page gets a different veiling background than the infinite chart of the computed RMTF.</p>
{table(prof, ["Z (mm)", "measured on the scan", "computed min", "computed max"])}
<p>Slanted-edge SFR (ISO 12233) of the simulated scans of the slanted-square chart, along
x (main scan) and y (sub-scan, which adds the motion smear of one line):</p>
{table(sfr, ["Z (mm)", "axis", "MTF50 (cycles/mm)", *(f"SFR at {k} dpi" for k in at)])}
<img src="scan_lines.png"><img src="scan_tilt.png">
"""
