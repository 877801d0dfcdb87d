"""The page's "Restoration with the known blur" section."""

from __future__ import annotations

import html

from .common import table, unmeasured


def _kernels(st: dict) -> str:
    """Which kernels made the scans and restored them."""
    if st.get("kernels") != "wave":
        return "Scanned and restored through ray-optics kernels."
    return (
        "Scanned and restored through wave-optics kernels (the wave engine in its band, "
        "the far ghosts traced: diffraction blurs the scan and the restoration knows it); "
        "the own path's transfer below is ray optics."
    )


def restoration_html(r: dict | None) -> str:
    """Raw against restored: the restored depth of field per method, noise gain, OCR."""
    if not r:
        return ""
    missing = unmeasured("Restoration with the known blur", r)
    if missing is not None:
        return missing
    st = r["study"]
    rows = []
    for name, dof in st["dof"].items():
        s = st["series"][name]
        rows.append(
            [
                name,
                (">= " if dof["open_ended"] else "") + f"{dof['dof_mm']:.2f}",
                f"{max(s['overshoot']):.2f}",
                f"{sum(s['noise_gain']) / len(s['noise_gain']):.2f}",
            ]
        )
    zero = st.get("transfer_zero_mm")
    ceiling = (
        f"its first zero at {zero:.2f} mm is the ceiling: past it the {st['dpi']:g}-dpi detail "
        "is gone, whatever the method"
        if zero is not None
        else "it has no zero within the heights studied"
    )
    ocr = r.get("ocr") or []
    keys = list(dict.fromkeys((o["points"], o["z_mm"]) for o in ocr))
    versions = list(dict.fromkeys(o["version"] for o in ocr))
    cer = {(o["points"], o["z_mm"], o["version"]): o["cer"] for o in ocr}
    ocr_rows = [
        [f"{p:g} pt", z] + [f"{cer[p, z, v]:.3f}" if (p, z, v) in cer else None for v in versions]
        for p, z in keys
    ]
    ocr_p = (
        "<p>Tesseract on the text chart, raw and restored (character error rate; 6-pt text is "
        "read even unrestored, 2.5-pt text tells):</p>"
        + table(ocr_rows, ["text", "Z (mm)"] + versions)
        if ocr_rows
        else ""
    )
    return f"""<h2>Restoration with the known blur</h2>
<p>The scan deconvolved with the scanner's own blur at its (known) height: the responsivity
band-limited to the output grid, the two staggered rows' kernels solved exactly, ghost
light removed as a background, the regularisation from the design's sensor noise and the
model's error ({st["model_error"]:g} rms), nothing tuned per image
(<code>opticalstamp restore</code>, docs/restore.md). Judged on a {st["dpi"]:g}-dpi chart by
the fundamental's fitted amplitude relative to the ideal's and its contrast to noise, not by
RMTF (overshoot clipped to [0, 1] pins RMTF at 1): the restored depth of field is where the
amplitude is at least {st["threshold"]:g} of the ideal's and the contrast to noise at least
{st["cnr_floor"]:g} ({html.escape(r["settings"])}). {_kernels(st)} The own path's transfer
at {st["dpi"]:g} dpi falls with height; {ceiling}.</p>
{table(rows, ["", "depth of field (mm)", "largest overshoot", "noise gain (white page)"])}
<img src="restore_curves.png"><img src="restore_text.png">{ocr_p}
"""
