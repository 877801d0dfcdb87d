"""The page's "RMTF and depth of field" section."""

from __future__ import annotations

import html

from ...analysis.dof import dof_text
from ...design import Design
from ...design.resolution import dof_chart_dpi, nominal_dpi
from .common import dof_cell, table, unmeasured


def rmtf_html(d: dict, design: Design) -> str:
    """RMTF and depth of field (paper Eq. 1, Fig. 11) by model, and the depth-of-field
    chart as the merged line sees it (Fig. 12 c, d)."""
    r, own, par = d["rmtf"], d["rmtf_traced_own"], d["rmtf_paraxial_own"]
    title = "RMTF and depth of field (paper Eq. 1, Fig. 11)"
    missing = unmeasured(title, r, own, par, d["chart_profiles"])
    if missing is not None:
        return missing
    keys = list(r["rmtf_max"])
    dk = f"{r['dof_dpi']:g}"
    paper = d.get("paper_vs_model") is not None
    rows = [
        [z] + [r["rmtf_max"][k][i] for k in keys] + [r["rmtf_max_se"][dk][i]]
        for i, z in enumerate(r["z_mm"])
    ]
    dof_keys = [dk] + [k for k in keys if k != dk]
    wave = r.get("meta", {}).get("optics", {}).get("engine") == "wave"
    all_light = (
        "wave optics in its band + the traced far ghosts (the headline)"
        if wave
        else "exact tracer, own + ghost light"
    )
    dof_rows = [
        [name] + [dof_cell(res, k) for k in dof_keys]
        for name, res in (
            (all_light, r),
            ("exact tracer, own path only", own),
            (f"{par['method']}, own path only", par),
        )
    ]
    prof = [
        [p["z_mm"], p["shift_um"], p["rmtf_computed"], p["rmtf_measured_from_waveform"]]
        for p in d["chart_profiles"]
    ]
    merged = (
        "shading-corrected (each pixel over its own white response), as a scanner delivers it"
        if r.get("shading", True)
        else "raw (no shading correction)"
    )
    return f"""<h2>{title}</h2>
<p>Bar charts of {", ".join(f"{k} dpi" for k in keys)} over a {r["window_um"]:g} µm window,
shifted in {r["shift_step_um"]:g} µm steps; RMTF is the maximum over shifts ({
        "wave optics in the band (docs/optics.md), traced beyond it" if wave else r["method"]
    }, ghost light {"included" if r["ghosts"] else "left out"}, {r["n_rays"]:,} rays per pixel row).
The merged line {merged}.
Depth of field: first Z where RMTF on the {r["dof_dpi"]:g}-dpi chart{chart_why(r, design)}
falls below {r["dof_threshold"]:g}:
<b>{html.escape(dof_text(r, dk))}</b>{" (paper: 3.5 mm measured)" if paper else ""}.{
        spurious_html(r)
    }</p>
{table(rows, ["Z (mm)"] + [f"{k} dpi" for k in keys] + [f"SE ({dk} dpi)"])}
{channels_html(r, keys)}<img src="rmtf.png">
<p>Depth of field (mm) by model: the paraxial closed form against the exact tracer shows
how far the paraxial limit is off; the ghost light's uniform background lowers contrast.</p>
{table(dof_rows, ["model"] + [f"{k} dpi" for k in dof_keys])}
<h3>The {r["dof_dpi"]:g}-dpi chart as the merged line sees it (paper Fig. 12 c, d)</h3>
<p>Signals of the pixels under the chart at the best shift; the RMTF measured back from
this waveform as from an image agrees with the computed one.</p>
{table(prof, ["Z (mm)", "chart shift (µm)", "RMTF computed", "RMTF measured from waveform"])}
<img src="chart_profiles.png">
"""


def channels_html(r: dict, keys: list[str]) -> str:
    """A colour scanner's channels (``meta["channels"]`` of an RMTF result): each
    channel's depth of field on every chart and its RMTF on the depth-of-field chart
    against Z, the headline (the worst) marked, and the rule; empty for one light."""
    chans = (r.get("meta") or {}).get("channels")
    if not chans:
        return ""
    from ...analysis.colour import DOF_RULE

    dk = f"{r['dof_dpi']:g}"
    head = r["meta"]["headline"]["channel"]
    dof_keys = [dk] + [k for k in keys if k != dk]
    rows, curves = [], []
    for name, c in chans.items():
        sp = c["spectrum"]
        mean = sum(x * w for x, w in zip(sp["wavelengths_um"], sp["weights"], strict=True))
        label = f"{name} ({mean:.3f} µm){' — the headline' if name == head else ''}"
        rows.append([label] + [dof_cell(r | c, k) for k in dof_keys])
        curves.append(c["rmtf_max"][dk])
    z_rows = [[z] + [cv[i] for cv in curves] for i, z in enumerate(r["z_mm"])]
    return f"""<h3>Colour: one exposure per LED (illumination rgb)</h3>
<p>The red, green and blue LEDs are lit in turn: each channel has its own responsivity,
RMTF and depth of field (wave optics at each LED's spectrum, the far light traced at its
mean wavelength). The depth of field above is the <b>{html.escape(head)}</b> channel's:
{html.escape(DOF_RULE)}. The RMTF table above is that channel's.</p>
{table(rows, ["channel"] + [f"DOF {k} dpi" for k in dof_keys])}
{table(z_rows, ["Z (mm)"] + [f"RMTF {dk} dpi, {n}" for n in chans])}
"""


def spurious_html(r: dict) -> str:
    """Where a chart's RMTF rises back over the threshold past its depth of field: contrast
    after a reversal (spurious resolution), not counted in the depth of field."""
    sp = {k: v for k, v in (r.get("spurious_mm") or {}).items() if v}
    if not sp:
        return ""
    parts = [f"{k} dpi at " + ", ".join(f"{a:.2f}-{b:.2f} mm" for a, b in v) for k, v in sp.items()]
    why = (
        "ghost copies of the periodic chart, landing beside the direct image, add in and "
        "out of phase as Z changes, and past a zero of the transfer function bars come back "
        "reversed; a real page is not periodic, so judge such a design by its own-path "
        "curve and its ghost analysis too"
        if r.get("ghosts", True)
        else "contrast after a reversal of the bars past a zero of the transfer function"
    )
    return (
        " RMTF back over the threshold past the depth of field, not counted in it ("
        + why
        + "; the heights were sampled finely there): "
        + "; ".join(parts)
        + "."
    )


def chart_why(r: dict, design: Design) -> str:
    """Why the depth-of-field chart is the one it is, where it is the default."""
    line = nominal_dpi(design)
    if abs(r["dof_dpi"] - dof_chart_dpi(design)) < 1e-9:
        return f" (2/3 of the design's {line:g} dpi, as the paper's 200 dpi for its 300)"
    return f" (chosen; the default is {dof_chart_dpi(design):g} dpi, 2/3 of {line:g} dpi)"
