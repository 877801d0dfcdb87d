"""The report page's "model vs measurement" section (issue 24)."""

from __future__ import annotations

import html

from .common import table, unmeasured

HEADING = "Model vs measurement"


def fit_html(sec: dict | None) -> str:
    """The fit's table, its notes and figures; "" where the report was given no fit."""
    if sec is None:
        return ""
    missing = unmeasured(HEADING, sec)
    if missing is not None:
        return missing
    which = {
        "fitted": "This report is of the fitted design.",
        "nominal": "This report is of the design that was fitted (the nominal).",
        None: f"The fit was of the design {html.escape(sec['design'])}, not this one.",
    }[sec["this_design"]]
    chi = (
        f"chi2 {sec['chi2']:.1f} for {sec['dof']} degrees of freedom (reduced "
        f"{sec['reduced_chi2']:.2f}"
        + (f"; errors scaled by {sec['error_scale']:.2f}" if sec.get("error_scale") else "")
        + ")"
    )
    images = ", ".join(html.escape(str(i)) for i in sec["images"])
    rows = table(sec["rows"], ["parameter", "nominal", "fitted", "standard error"])
    notes = "".join(f"<li>{html.escape(m)}</li>" for m in sec["degeneracies"])
    figs = ""
    if sec.get("rmtf") and sec["rmtf"].get("points"):
        figs += (
            "<p>RMTF against height: measured (dots), the nominal design (dashed) and the "
            f"fitted design (solid), {html.escape(sec.get('curves', 'paraxial own path'))} "
            "(paper Fig. 11 with its dots).</p>"
            '<img src="fit_rmtf.png" alt="RMTF against height, measured and modelled">'
        )
    if sec.get("residuals"):
        rms = ", ".join(f"{html.escape(r['name'])} {r['rms']:.2f}" for r in sec["residuals"])
        figs += (
            f"<p>Residuals over their noise (rms: {rms}).</p>"
            '<img src="fit_residuals.png" alt="normalised residuals of each image">'
        )
    return f"""<h2>{HEADING}</h2>
<p>The design fitted to a prototype's scans of charts (<code>opticalstamp fit</code>,
docs/fit.md) at {images or "the images given"}. {which} {chi}. Lengths in µm; ref: how far
Z = 0 really lies above the drawn reference plane. A parameter the images did not determine
is held at its nominal value in the fitted design.
{html.escape(sec.get("optics_text", ""))}</p>
{rows}{f"<ul>{notes}</ul>" if notes else ""}
{figs}
"""
