"""The report's page: the sections' HTML in order, with the verdict, the paper against
the model, the design as built and what a quick report left out."""

from __future__ import annotations

import html
from types import MappingProxyType

from ...analysis.responsivity import light_words
from ...design import Design
from ...design.describe import describe, sensor_warnings
from ...raytrace.stack import output_pitch
from ..paper import one_in
from ..section import not_measurable
from .common import fmt, table, unmeasured
from .fit import fit_html
from .light import efficiency_html
from .optics import concepts_html, diffraction_html, ghost_span, ghosts_html, psf_html, spots_html
from .quality import rmtf_html
from .restoration import restoration_html
from .scans import scans_html
from .studies import rodlens_html, search_html, study_html
from .wave import wave_html


def page(design: Design, d: dict) -> str:
    """The report's page from report.json's numbers ``d``: a section per part of the
    report, in order; a section that was not measurable says so, with the reason."""
    pitch_um = output_pitch(design)
    prov = d["provenance"]
    paper = d.get("paper_vs_model") is not None
    rmtf = d["rmtf"] if not_measurable(d["rmtf"]) is None else None
    wave = wave_html(d.get("ray_vs_wave"), prov["fresnel"])
    return f"""<!doctype html><html><head><meta charset="utf-8">
<title>opticalstamp report: {html.escape(design.name)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}}
table{{border-collapse:collapse;margin:.5em 0}}td,th{{border:1px solid #bbb;padding:2px 6px;
font-size:13px;text-align:right}}img{{max-width:100%}}</style></head><body>
<h1>opticalstamp report: {html.escape(design.name)}</h1>{quick_html(d)}
{summary_html(d.get("summary"))}
{paper_html(d.get("paper_vs_model"))}
<p>{html.escape(describe(design))}{
        f" The design file's note: <i>{html.escape(design.description)}</i>"
        if design.description
        else ""
    }</p>{"".join(f"<p><b>warning:</b> {html.escape(w)}</p>" for w in sensor_warnings(design))}
<p>design fingerprint {prov["design_fingerprint"]}, seed {prov["seed"]},
opticalstamp {prov["opticalstamp_version"]}, Fresnel losses {"on" if prov["fresnel"] else "off"},
pixel acceptance half-angle {design.sensor.acceptance_half_angle_deg:g} deg.
Numbers: <a href="report.json">report.json</a>.</p>
{stack_html(d.get("stack"))}
{ghosts_html(d["ghosts"])}{concepts_html(d["concepts"])}
{spots_html(d["spots"], pitch_um)}{psf_html(d["psf"])}{rmtf_html(d, design)}{
        efficiency_html(d["efficiency"], d.get("signal"), paper)
    }{diffraction_html(d["diffraction"], paper)}{wave}{fit_html(d.get("model_vs_measurement"))}{
        study_html(d["parameter_study"], d.get("quick", False))
    }

{scans_html(d["scans"], pitch_um, ghost_span(d["ghosts"]))}
{restoration_html(d.get("restoration"))}
{search_html(d["search"], d["tolerance"], d.get("quick", False), rmtf)}
{rodlens_html(d.get("rodlens"), paper=paper)}
<p>Generated in {d["elapsed_s"]:.1f} s.</p>
</body></html>
"""


def quick_html(d: dict) -> str:
    """The label of a quick report: what it left out and what it computed with less."""
    if not d.get("quick"):
        return ""
    out = "".join(f"<li>{html.escape(x)}</li>" for x in d["left_out"])
    less = "".join(f"<li>{html.escape(x)}</li>" for x in d["reduced"])
    return f"""
<p style="border:2px solid #c60;padding:.5em"><b>Quick report</b>
(<code>opticalstamp report --quick</code>): a first look, not the numbers to quote.
Left out:</p><ul>{out}</ul><p>Computed with less work:</p><ul>{less}</ul>"""


def stack_html(rows: list[dict] | None) -> str:
    """The design as built: the stack table (object side first) and the drawing."""
    if not rows:
        return ""
    body = []
    for r in rows:
        m = r["mask"]
        hole = "reference gap" if r.get("reference_gap") else ""
        if m is not None:
            hole = f"{m['shape']} {m['width_um']:g} x {m['height_um']:g} µm"
            if m["offset_x_um"] or m["offset_y_um"]:
                hole += f", offset ({m['offset_x_um']:g}, {m['offset_y_um']:g}) µm"
        body.append(
            ["" if r["layer"] is None else r["layer"], str(r["medium"]), r["index"],
             r["thickness_um"], r["z_top_um"], hole]
        )  # fmt: skip
    head = ["layer", "medium", "index", "thickness (µm)", "z of top (µm)", "mask hole"]
    return (
        "<h2>The design as built</h2><p>Object side first; aperture layers numbered from the "
        "object side as the paper does (layer 1 faces the document).</p>"
        + table(body, head)
        + '<img src="stack.png" alt="the stack to scale">'
    )


def summary_html(s: dict | None) -> str:
    """The verdict card at the top of the report."""
    if not s:
        return ""
    missing = unmeasured("Verdict", s)
    if missing is not None:
        return missing
    body = []
    paper = any(f["paper"] is not None for f in s["figures"])
    for f in s["figures"]:
        v, c = f["value"], f["check"]
        if v is None and c is None:
            continue
        unit = f" {f['unit']}" if f["unit"] else ""
        ratio = f["figure"] in ("light", "vs_rod_lens")  # written as 1/N
        if v is None:  # a figure the spec names that was not computed
            shown = "not computed"
        else:
            shown = f"{'≥ ' if f['bound'] else ''}{one_in(v) if ratio else fmt(float(v))}{unit}"
            shown = f.get("text") or shown
        if ratio and c is not None and v is not None:  # the spec's unit too: a ratio
            shown += f" (ratio {float(v):.4f})"
        verdict = (
            "-"
            if c is None
            else f"{c['spec']}: "
            + ("PASS" if c["pass"] else ("FAIL" if c["pass"] is False else "not computed"))
        )
        dof_like = f["figure"] in ("dof", "raw_dof", "restored_dof")
        at = dof_like and s["dof_dpi"] is not None
        what = f["what"] + (f" at {s['dof_dpi']:g} dpi" if at else "")
        row = [what, shown, verdict]
        if paper:
            p = f["paper"]
            row.append("-" if p is None else (one_in(p) if ratio else fmt(p)))
        body.append(row)
    head = ["figure", "model", "spec"] + (["paper"] if paper else [])
    near = ", ".join(f"{v:.1f} mm at Z = {z} mm" for z, v in s["ghost_nearest_mm_by_z"].items())
    if s["meets_spec"] is None:
        top = 'No spec given (report --spec "dof>=2.2,ghost_radius>=5").'
    else:
        top = (
            f"<b>{'Meets' if s['meets_spec'] else 'Does not meet'} the spec</b> "
            f"{html.escape(', '.join(s['spec']))}."
        )
    ghosts = (
        "<p>Ghost light: not measurable (the ghost analysis was not computed).</p>"
        if s["ghost_fraction"] is None
        else f"<p>Ghost light ({s['ghost_fraction']:.3g} of all light) lands no nearer than "
        f"{html.escape(near)} from the pixel's axis: the design is ghost-free within that "
        "radius; own-path light is the signal.</p>"
    )
    optics = f"<p>Ray vs wave optics: {html.escape(s['optics'])}</p>" if s.get("optics") else ""
    optics += _headline_optics(
        s.get("headline_optics"),
        s.get("headline_channels"),
        s.get("optics_one_light"),
        s.get("one_light_engines"),
    )
    return (
        f"<div style='border:2px solid #444;padding:.5em 1em;margin:1em 0'>"
        f"<h2>Verdict</h2><p>{top}</p>"
        + table(body, head)
        + (f"<p>{html.escape(s['yield_note'])}.</p>" if s.get("yield_note") else "")
        + ghosts
        + optics
        + "</div>"
    )


def _headline_optics(
    o: dict | None,
    chans: dict | None = None,
    one: dict | None = None,
    engines: dict | None = None,
) -> str:
    """Which engine gave the verdict's depth of field and light, and why; ``chans``: a
    colour scanner's headline channels (the summary's ``headline_channels``), ``one``:
    the optics of its analyses of one light where it differs, ``engines``: the engine each
    of those ran by (the summary's ``one_light_engines``: :func:`one_light_sentence`)."""
    if not o:
        return ""
    if o["engine"] == "wave":
        at = "at each LED's light" if chans else html.escape(light_words(o))
        what = (
            f"wave optics (scalar diffraction {at} in the band "
            f"|s| &lt; {o['band']:.3f}, the far ghosts traced)"
        )
    else:
        what = "ray optics (the exact tracer)"
    why = html.escape(o["reason"])
    rest = one_light_sentence(engines, one)
    colour = ""
    if chans:
        worst = [f"depth of field the {chans['dof']} channel's (the worst)"] if chans["dof"] else []
        weak = [f"light the {chans['light']} channel's (the weakest)"] if chans["light"] else []
        colour = (
            f" A colour scanner ({', '.join(chans['channels'])} LEDs lit in turn): one RMTF, "
            f"depth of field and light per channel, the verdict's {' and '.join(worst + weak)}."
        )
    return (
        f"<p>The depth of field, RMTF and light above are by {what}: {why} "
        f"(--optics {html.escape(o['asked'])}).{colour} {rest}</p>"
    )


def one_light_sentence(engines: dict | None, one: dict | None = None) -> str:
    """The verdict box's sentence on the engines of the other analyses: the ghosts and PSFs
    are ray optics; the spots, scans and restoration by the engine each ran by
    (``engines``, the summary's ``one_light_engines``; None: a report.json written before
    they were recorded, all ray optics then); ``one``: a colour scanner's optics of one
    light (ray optics, and why): its spots by wave optics are each channel's, its scans
    and restoration by wave optics are grey scans under its three LEDs lit together
    (:func:`~opticalstamp.analysis.spectrum.grey_light`)."""
    engines = engines if engines is not None else dict.fromkeys(_ONE_LIGHT, "ray")
    ray = [_ONE_LIGHT[k] for k, e in engines.items() if e != "wave"]
    wave = [_ONE_LIGHT[k] for k, e in engines.items() if e == "wave"]
    if one:
        why = html.escape(one["reason"].removeprefix("ray optics: "))
        text = "Ghosts and PSFs are ray optics"
        if ray:
            text += f", and so are the {_and(ray)} here ({why})"
        if "spots" in wave:
            text += "; the spots are by wave optics, channel by channel (the widest shown)"
        grey = [n for n in wave if n != "spots"]
        if grey:
            text += (
                f"; the {_and(grey)} are by wave optics, grey scans under the three LEDs lit "
                "together at the luminance weights"
            )
        return text + "."
    text = "G" + f"{_and(['ghosts'] + ray + ['PSFs'])} are ray optics"[1:]
    if wave:
        text += (
            f"; the {_and(wave)} are by wave optics (the wave engine's light in its "
            "band, the far ghosts traced)"
        )
    return text + "."


#: the analyses of one light, as the verdict names them
_ONE_LIGHT = MappingProxyType({"spots": "spots", "scans": "scans", "restoration": "restoration"})


def _and(names: list[str]) -> str:
    """'a', 'a and b', 'a, b and c'."""
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def paper_html(rows: list[dict] | None) -> str:
    """The paper's statements on its prototype against the model's figures (computed)."""
    if not rows:
        return ""
    missing = unmeasured("The paper against the model", rows)
    if missing is not None:
        return missing
    body = [
        [
            r["section"],
            r["statement"],
            r["paper_text"] + (f" {r['unit']}" if r["unit"] and r["paper"] is not None else ""),
            r["model_text"] + (f" {r['unit']}" if r["unit"] and r["model"] is not None else ""),
            "-" if r["ratio"] is None else f"{r['ratio']:.2f}",
            r["note"],
        ]
        for r in rows
    ]
    return (
        "<h2>The paper against the model</h2><p>The paper's statements on its prototype "
        "(Kawano 2016) and this report's figures for them, computed from report.json. "
        "Differences come from parameters the paper does not state "
        "(docs/paper-comparison.md); the model is not tuned to the paper.</p>"
        + table(body, ["paper", "statement", "paper's figure", "model", "model / paper", "note"])
    )
