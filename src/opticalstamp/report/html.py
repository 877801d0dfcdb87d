"""The HTML page of `opticalstamp report`: tables and sections from the report's numbers."""

from __future__ import annotations

import html
import math

from ..analysis.dof import dof_text
from ..design import Design
from ..design.describe import describe, sensor_warnings
from ..design.resolution import dof_chart_dpi, nominal_dpi
from ..raytrace.stack import output_pitch
from .paper import one_in
from .summary import PAPER


def _scans_html(s: dict, pitch_um: float, ghost_span: str = "") -> str:
    chart = s.get("chart_dpi", 200.0)
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
        else "<p>(tesseract not installed: no OCR)</p>"
    )
    prof = [
        [p["z_mm"], p["rmtf_measured"], p["rmtf_computed_min"], p["rmtf_computed_max"]]
        for p in s["profiles"]
    ]
    return f"""<h2>Simulated scans (paper Figs. 8, 9, 12)</h2>
<p>Built-in charts at 1200 dpi through the scan simulation ({html.escape(s["settings"])}):
the document moves one {pitch_um:.1f} um line per period, the rows are merged with the line delay,
and dark/white shading correction is applied. See <code>opticalstamp scan</code>.</p>
<img src="scan_text.png"><img src="scan_text_zoom.png">{ocr_p}
<img src="scan_bars.png"><img src="scan_profiles.png">
<p>RMTF measured on simulated {chart:g}-dpi scans (own path, ghost light off, noise on) against
the RMTF computed from the folded line-spread functions (own path; minimum and maximum
over chart positions). With ghost light on they differ for a reason, not an error: ghost
light comes from {ghost_span or "far from the pixel's axis"}, so a finite chart on a white
page gets a different veiling background than the infinite chart of the computed RMTF.</p>
{table(prof, ["Z (mm)", "measured on the scan", "computed min", "computed max"])}
<p>Slanted-edge SFR (ISO 12233) of the simulated scans of the slanted-square chart, along
x (main scan) and y (sub-scan, which adds the motion smear of one line):</p>
{table(sfr, ["Z (mm)", "axis", "MTF50 (cycles/mm)", *(f"SFR at {k} dpi" for k in at)])}
<img src="scan_lines.png"><img src="scan_tilt.png">
"""


def _restoration_html(r: dict | None) -> str:
    """Raw against restored: the restored depth of field per method, noise gain, OCR."""
    if not r:
        return ""
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
{st["cnr_floor"]:g} ({html.escape(r["settings"])}). The own path's transfer at {st["dpi"]:g}
dpi falls with height; {ceiling}.</p>
{table(rows, ["", "depth of field (mm)", "largest overshoot", "noise gain (white page)"])}
<img src="restore_curves.png"><img src="restore_text.png">{ocr_p}
"""


def _headline_dof(rmtf: dict | None) -> str:
    """The report's own depth of field beside a study's estimate of it."""
    if rmtf is None:
        return "fewer rays than the RMTF section"
    return (
        f"fewer rays than the RMTF section, whose figure of record is {html.escape(dof_text(rmtf))}"
    )


def _search_html(
    s: dict | None, t: dict | None, quick: bool = False, rmtf: dict | None = None
) -> str:
    """The design search and the tolerance study; ``rmtf``: the RMTF section's result,
    whose depth of field is this design's figure of record (the search's own estimate of
    the base, with fewer rays, stands beside it)."""
    if s is None:
        why = "left out of this quick report" if quick else "needs square holes"
        return f"<h2>Design search and tolerancing</h2><p>({why})</p>"

    def sur(p: dict, k: str):
        return (p.get("surrogate") or {}).get(k)

    def flags(p: dict) -> str:
        out = list(p.get("disagrees") or [])
        if p.get("exact_dominated_by"):
            out.append(f"dominated by {p['exact_dominated_by']} (exact)")
        return ", ".join(out)

    front = [
        [
            "/".join(f"{v:g}" for v in p["holes_um"]),
            "/".join(f"{v:g}" for v in p["thicknesses_um"]),
            f"1/{1 / p['efficiency_ratio']:.0f}",
            p["dof_mm"],
            sur(p, "dof_mm"),
            p["ghost_fraction"],
            sur(p, "ghost_fraction"),
            flags(p),
        ]
        for p in s["pareto"]
    ]
    ref = s["reference"]
    verified = "verified_by" in s["meta"]
    acc = s["meta"].get("surrogate_accuracy", {})
    note = (
        "Each point of the front was then traced exactly: the exact figures are the figures "
        "of record, the surrogate's are beside them, and a point is flagged where they differ "
        f"by more than the surrogate's measured accuracy (depth of field "
        f"{acc.get('dof_mm', 0):g} mm where the ghost fraction is below 0.2, "
        f"{acc.get('dof_mm_high_ghost', 0):g} mm above; docs/search.md)."
        if verified
        else "The front was not re-verified by the exact tracer."
    )
    if t is None:
        tol = ""
    else:
        key = f"rmtf{t['dpi']:g}"
        sens = [
            [r["error"], r["sigma"], r["d_dof_mm"], r.get("d_rmtf@2", None), r["d_ghost_fraction"]]
            for r in t["sensitivity"][:10]
        ]
        rm = [
            [z, v["p5"], v["p50"], v["p95"], t["nominal"]["rmtf_at"][z]] for z, v in t[key].items()
        ]
        ex = t["meta"].get("nominal_exact")
        nominal = ""
        if ex:
            off = t["meta"].get("nominal_disagrees") or []
            nominal = (
                f" The nominal design traced exactly: depth of field {ex['dof_mm']:.2f} mm "
                f"(surrogate {t['nominal']['dof_mm']:.2f} mm), ghost fraction "
                f"{ex['ghost_fraction']:.3f}"
                + (
                    f"; the surrogate is off beyond its accuracy in {', '.join(off)}."
                    if off
                    else "; the surrogate agrees within its accuracy."
                )
            )
        yld = (
            'No yield: no spec given (report --spec "dof>=2.2,light>=0.03" asks for one).'
            if not t.get("spec")
            else f"Yield for {html.escape(t['spec'])}: "
            + ("not computed." if t["yield"] is None else f"{t['yield']:.1%}.")
        )
        tol = f"""<h2>Tolerancing (paper §5)</h2>
<p>{t["n_samples"]} Monte Carlo samples: misregistration {t["sigmas"]["misregistration_um"]:g}
um, holes {t["sigmas"]["hole_um"]:g} µm, plates and gaps {t["sigmas"]["thickness_um"]:g} µm,
tilt {t["sigmas"]["tilt_deg"]:g} deg (1 sigma), each evaluated by the
{html.escape(t["meta"]["estimator"])}. {yld}{nominal}
Errors are named from the object side: dx1 is layer 1's x misregistration, slab1 the
thickness of the slab under layer 1.</p>
{table(rm, ["Z (mm)", f"RMTF {t['dpi']:g} dpi 5 %", "median", "95 %", "nominal"])}
{table(sens, ["error", "sigma", "DOF change (mm)", "RMTF@2mm change", "ghost change"])}
<img src="tolerance.png">
"""
    return f"""<h2>Design search (paper §3)</h2>
<p>NSGA-II over hole sizes and slab thicknesses ({s["n_evaluations"]} designs,
{s["n_feasible"]} feasible: no ghost light within {s["meta"]["near_mm"]:g} mm, stack within
{s["meta"]["budget_mm"]:g} mm, diffraction spill below {s["meta"]["max_spill"]:g}; a compact
run, `opticalstamp search` runs 480), ranked by the {html.escape(s["meta"]["estimator"])}.
{note} This design: efficiency 1/{1 / ref["efficiency_ratio"]:.0f}, depth of field
{ref["dof_mm"]:.2f} mm at {s["meta"]["dof_dpi"]:g} dpi by the search's exact check
({_headline_dof(rmtf)}), dominated by
{ref.get("dominated_by", 0)} of the designs found (the Fresnel setting of the report does
not apply). Layers and slabs object side first.</p>
{
        table(
            front,
            [
                "holes (µm)",
                "slabs (µm)",
                "efficiency",
                "DOF (mm)",
                "DOF, surrogate",
                "ghost fraction",
                "ghosts, surrogate",
                "flagged",
            ],
        )
    }
<img src="pareto.png">
{tol}"""


def table(rows: list[list], head: list[str]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(_fmt(c))}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><tr>{th}</tr>{body}</table>"


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "-" if v is None else str(v)


def page(design: Design, d: dict) -> str:
    g, sp = d["ghosts"], d["spots"]
    pitch_um = output_pitch(design)
    ghost_rows = [
        [
            " / ".join(f"{h['mask']}: {h['row']} {h['dk']:+d}" for h in p["holes"]),
            p["etendue_um2sr"],
            p["etendue_se"],
            p["share"],
            f"{p['emission_angle_deg'][0]:.1f}-{p['emission_angle_deg'][1]:.1f}",
            p["nearest_landing_um"].get("0"),
        ]
        for p in g["paths"][:15]
    ]
    land_rows = [
        [
            z,
            v["nearest_um"],
            f"≥ {v['median_um']:.0f}" if v.get("median_beyond") else v["median_um"],
            v["within_detector_um2sr"],
        ]
        for z, v in g["landing"].items()
    ]
    spot_rows = [
        [
            z,
            sp["extent_x_um"][i],
            sp["extent_y_um"][i],
            sp["fwhm_x_um"][i],
            sp["fwhm_y_um"][i],
            sp["center_cell_fraction"][i],
        ]
        for i, z in enumerate(sp["z_mm"])
    ]
    psf_rows = [
        [
            p["x_obj_um"],
            p["z_mm"],
            p["own_pixel"],
            p["neighbour_own_path"],
            p["neighbour_ghost"],
            p["insensitive"],
            p["reaching_sensor"],
        ]
        for p in d["psf"]
    ]
    conc = [
        [
            c["design"],
            c["etendue_own_um2sr"],
            c["etendue_ghost_um2sr"],
            c["ghost_fraction"],
            c["nearest_ghost_um_z0"],
        ]
        for c in d["concepts"] or ()
    ]
    prov = d["provenance"]
    return f"""<!doctype html><html><head><meta charset="utf-8">
<title>opticalstamp report: {html.escape(design.name)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}}
table{{border-collapse:collapse;margin:.5em 0}}td,th{{border:1px solid #bbb;padding:2px 6px;
font-size:13px;text-align:right}}img{{max-width:100%}}</style></head><body>
<h1>opticalstamp report: {html.escape(design.name)}</h1>{_quick_html(d)}
{_summary_html(d.get("summary"))}
{_paper_html(d.get("paper_vs_model"))}
<p>{html.escape(describe(design))}{
        f" The design file's note: <i>{html.escape(design.description)}</i>"
        if design.description
        else ""
    }</p>{"".join(f"<p><b>warning:</b> {html.escape(w)}</p>" for w in sensor_warnings(design))}
<p>design fingerprint {prov["design_fingerprint"]}, seed {prov["seed"]},
opticalstamp {prov["opticalstamp_version"]}, Fresnel losses {"on" if prov["fresnel"] else "off"},
pixel acceptance half-angle {design.sensor.acceptance_half_angle_deg:g} deg.
Numbers: <a href="report.json">report.json</a>.</p>
{_stack_html(d.get("stack"))}
<h2>Ghost analysis (paper Figs. 2 and 4)</h2>
<p>Own-path etendue {g["etendue_own_um2sr"]:.4g} &plusmn; {g["etendue_own_se"]:.2g} µm²·sr,
ghost etendue {g["etendue_ghost_um2sr"]:.4g} &plusmn; {g["etendue_ghost_se"]:.2g} µm²·sr,
ghost fraction {g["ghost_fraction"]:.4g} &plusmn; {g["ghost_fraction_se"]:.2g}
({g["n_rays"]:,} importance-sampled rays).</p>
{
        table(
            ghost_rows,
            [
                "holes (object side first)",
                "etendue",
                "se",
                "share of ghost",
                "emission angle (deg)",
                "nearest landing at Z=0 (µm)",
            ],
        )
    }
<p>Where ghost light meets the object plane (distance from the pixel's axis) and how much
lands inside the virtual detector (&plusmn;{
        g["landing"][next(iter(g["landing"]))]["detector_half_um"]:g} µm):</p>
{table(land_rows, ["Z (mm)", "nearest (µm)", "median (µm)", "inside detector (µm²·sr)"])}
<img src="ghosts.png">
{
        ""
        if d["concepts"] is None
        else "<h3>The paper's Fig. 1 concepts</h3>"
        + table(
            conc,
            [
                "design",
                "own etendue",
                "ghost etendue",
                "ghost fraction",
                "nearest ghost at Z=0 (µm)",
            ],
        )
    }
<h2>Spots on the object plane (paper Fig. 5)</h2>
{
        table(
            spot_rows,
            [
                "Z (mm)",
                "extent x (µm)",
                "extent y (µm)",
                "FWHM x (µm)",
                "FWHM y (µm)",
                f"fraction in centre {pitch_um:.1f} µm cell",
            ],
        )
    }
<img src="spots.png">
<h2>PSFs on the sensor (paper Fig. 10)</h2>
{
        table(
            psf_rows,
            [
                "X obj (µm)",
                "Z (mm)",
                "own pixel",
                "neighbour, own-path blur",
                "ghost",
                "insensitive",
                "fraction of emitted power reaching sensor",
            ],
        )
    }
<img src="psf_x0.png"><img src="psf_x42.png">
{_quality_html(d, design)}
{_scans_html(d["scans"], pitch_um, _ghost_span(g))}
{_restoration_html(d.get("restoration"))}
{_search_html(d["search"], d["tolerance"], d.get("quick", False), d["rmtf"])}
{rodlens_html(d.get("rodlens"), paper=d.get("paper_vs_model") is not None)}
<p>Generated in {d["elapsed_s"]:.1f} s.</p>
</body></html>
"""


def _quick_html(d: dict) -> str:
    """The label of a quick report: what it left out and what it computed with less."""
    if not d.get("quick"):
        return ""
    out = "".join(f"<li>{html.escape(x)}</li>" for x in d["left_out"])
    less = "".join(f"<li>{html.escape(x)}</li>" for x in d["reduced"])
    return f"""
<p style="border:2px solid #c60;padding:.5em"><b>Quick report</b>
(<code>opticalstamp report --quick</code>): a first look, not the numbers to quote.
Left out:</p><ul>{out}</ul><p>Computed with less work:</p><ul>{less}</ul>"""


def _study_html(st: dict | None, quick: bool = False) -> str:
    """The parameter-study section (left out of a quick report and of a report without
    the paper's sections)."""
    if st is None:
        return (
            """<h2>The paper's unstated parameters</h2>
<p>(left out of this quick report)</p>"""
            if quick
            else ""
        )
    st_rows = [
        [
            x["hole_shape"],
            x["sensitive_um"],
            x["gap_medium"],
            x["fresnel"],
            x["glass_index"],
            x["inverse_ratio"],
            x["working_f_number"],
            x["dof_mm"],
            x["rmtf200_at_3_5mm"],
            x["ghost_fraction"],
            "yes"
            if x["consistent_efficiency"] and x["consistent_dof"]
            else (
                "F only"
                if x["consistent_efficiency"]
                else ("DOF only" if x["consistent_dof"] else "")
            ),
        ]
        for x in st["rows"]
    ]
    return f"""<h2>The paper's unstated parameters</h2>
<p>Every combination of hole shape, sensitive-area size, reference-gap medium, Fresnel
losses and glass index; consistent with the paper when the working F-number is within
{st["meta"]["f_tolerance"]:g} of 60 and the depth of field at least
{st["paper"]["dof_mm"] - st["meta"]["dof_tolerance_mm"]:g} mm.</p>
{
        table(
            st_rows,
            [
                "holes",
                "sensitive (µm)",
                "gap",
                "Fresnel",
                "glass n",
                "1/ratio",
                "working F",
                "DOF (mm)",
                "RMTF200 at 3.5 mm",
                "ghost fraction",
                "consistent with paper",
            ],
        )
    }
<img src="study.png">"""


def _dof(res: dict, key: str) -> str:
    """A depth of field from an RMTF result's JSON: "2.48 mm", or ">= 4.50 mm" where the
    RMTF never fell below the threshold in the Z range."""
    v = res["dof_mm"][key]
    return f"≥ {v:.2f} mm" if res.get("dof_open_ended", {}).get(key) else f"{v:.2f} mm"


def _quality_html(d: dict, design: Design) -> str:
    r, own, par = d["rmtf"], d["rmtf_traced_own"], d["rmtf_paraxial_own"]
    keys = list(r["rmtf_max"])
    dk = f"{r['dof_dpi']:g}"
    paper = d.get("paper_vs_model") is not None
    rows = [
        [z] + [r["rmtf_max"][k][i] for k in keys] + [r["rmtf_max_se"][dk][i]]
        for i, z in enumerate(r["z_mm"])
    ]
    dof_keys = [dk] + [k for k in keys if k != dk]
    dof_rows = [
        [name] + [_dof(res, k) for k in dof_keys]
        for name, res in (
            ("exact tracer, own + ghost light", r),
            ("exact tracer, own path only", own),
            (f"{par['method']}, own path only", par),
        )
    ]
    prof = [
        [p["z_mm"], p["shift_um"], p["rmtf_computed"], p["rmtf_measured_from_waveform"]]
        for p in d["chart_profiles"]
    ]
    e = d["efficiency"]
    eff_rows = [
        [
            "own path: the signal (the headline figure)",
            e["etendue_own_um2sr"],
            e["ratio_own"],
            1 / e["ratio_own"],
            e["working_f_number_own"],
        ],
        [
            "own + ghost light (ghost light is crosstalk)",
            e["etendue_um2sr"],
            e["ratio"],
            1 / e["ratio"],
            e["working_f_number"],
        ],
    ] + ([["paper (Fig. 13)", None, 1 / 36, 36.0, 60.0]] if paper else [])
    area_rows = [
        [
            a["sensitive_um"][0],
            a["area_scale"],
            a["gain_own_vs_design"],
            a["gain_vs_design"],
            a["ghost_fraction"],
        ]
        for a in e["sensitive_area"]
    ]
    df = d["diffraction"]
    slit_rows = [[k, df["fresnel_number"][k], v] for k, v in df["fraction_outside"].items()]
    bud_rows = []
    for row in df["budget"]["layers"]:
        for k in row["outside_shadow"]:
            bud_rows.append(
                [
                    row["layer"],
                    row["next"],
                    row["hole_um"],
                    k,
                    row["fresnel_number"][k],
                    row["outside_shadow"][k],
                    row["outside_next"][k],
                    row["outside_next_geometric"],
                ]
            )
    warn = "".join(f"<p><b>warning:</b> {html.escape(w)}</p>" for w in df["budget"]["warnings"])
    merged = (
        "shading-corrected (each pixel over its own white response), as a scanner delivers it"
        if r.get("shading", True)
        else "raw (no shading correction)"
    )
    return f"""<h2>RMTF and depth of field (paper Eq. 1, Fig. 11)</h2>
<p>Bar charts of {", ".join(f"{k} dpi" for k in keys)} over a {r["window_um"]:g} µm window,
shifted in {r["shift_step_um"]:g} µm steps; RMTF is the maximum over shifts ({r["method"]},
ghost light {"included" if r["ghosts"] else "left out"}, {r["n_rays"]:,} rays per pixel row).
The merged line {merged}.
Depth of field: first Z where RMTF on the {r["dof_dpi"]:g}-dpi chart{_chart_why(r, design)}
falls below {r["dof_threshold"]:g}:
<b>{html.escape(dof_text(r, dk))}</b>{" (paper: 3.5 mm measured)" if paper else ""}.{
        _spurious_html(r)
    }</p>
{table(rows, ["Z (mm)"] + [f"{k} dpi" for k in keys] + [f"SE ({dk} dpi)"])}
<img src="rmtf.png">
<p>Depth of field (mm) by model: the paraxial closed form against the exact tracer shows
how far the paraxial limit is off; the ghost light's uniform background lowers contrast.</p>
{table(dof_rows, ["model"] + [f"{k} dpi" for k in dof_keys])}
<h3>The {r["dof_dpi"]:g}-dpi chart as the merged line sees it (paper Fig. 12 c, d)</h3>
<p>Signals of the pixels under the chart at the best shift; the RMTF measured back from
this waveform as from an image agrees with the computed one.</p>
{table(prof, ["Z (mm)", "chart shift (µm)", "RMTF computed", "RMTF measured from waveform"])}
<img src="chart_profiles.png">
<h2>Light efficiency (paper Fig. 13)</h2>
<p>Reference: 1:1 lens, f = 10 mm, 2 mm pupil, 20 mm conjugates, a pixel of the
design's output pitch ({e["meta"]["reference_lens"]["pixel_um"]:.1f} µm; the paper's 84.6 µm):
{e["reference_etendue_um2sr"]:.4g} µm²·sr (working F {e["reference_f_number"]:g}).</p>
{table(eff_rows, ["light", "etendue (µm²·sr)", "ratio", "1/ratio", "working F"])}
{_area_html(area_rows)}
<img src="efficiency.png">
{signal_html(d.get("signal"), e)}
<h2>Diffraction (paper Fig. 6)</h2>
<p>This design's object-side hole as a slit: {df["slit_um"]:g} µm in
{html.escape(df["budget"]["layers"][0]["layer"])}, point source at Z = {df["z_mm"]:g} mm
(R1 = {df["r1_um"]:.0f} µm), observed at {html.escape(df["budget"]["layers"][0]["next"])}
(R2 = {df["r2_um"]:.0f} µm air-equivalent): geometric edge X =
{df["geometric_edge_um"]:.2f} µm.{
        " (The paper's Fig. 6, for its 48 µm slit at R1 2000 µm and R2 658 µm: an edge of "
        "32 µm and about 7 % of the light outside it.)"
        if paper
        else ""
    }</p>
{table(slit_rows, ["wavelength (µm)", "Fresnel number", "fraction outside the edge"])}
<img src="diffraction.png">
<p>Per-layer budget of this design (2-D holes, point source on the axis at
Z = {df["budget"]["z_mm"]:g} mm):</p>
{
        table(
            bud_rows,
            [
                "layer",
                "next aperture",
                "hole (µm)",
                "wavelength (µm)",
                "Fresnel number",
                "outside own shadow",
                "outside next (diffraction)",
                "outside next (geometric)",
            ],
        )
    }
{warn}
{_study_html(d["parameter_study"], d.get("quick", False))}
"""


def _percent(v: float) -> str:
    """A percentage to two significant digits, never in exponent form (4.2, 17, 171)."""
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    return f"{v:.{max(0, 1 - math.floor(math.log10(abs(v))))}f}"


def signal_html(s: dict | None, eff: dict | None = None) -> str:
    """The "Signal and noise" block: a used pixel's electrons and temporal SNR at white and
    18 % grey with the design's electronics, and the exposure and line rate for the target
    SNR. ``s``: report.json's "signal" (None: no block); ``eff``: its "efficiency" (for
    the ghost light a white page adds)."""
    if not s:
        return ""

    def num(v: float) -> str:  # whole numbers from 100 up, three digits below
        return f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3g}"

    el = s["electronics"]
    grey = s["electrons_grey18"] / s["electrons_white"] if s["electrons_white"] > 0 else 0.18
    well = el["full_well_e"]
    dark = el["dark_current_e_per_s"] * el["exposure_ms"] * 1e-3
    rows = [
        [name, num(e), f"{100 * e / well:.3g} %", "clipped" if e + dark > well else f"{snr:.3g}"]
        for name, e, snr in (
            ("white", s["electrons_white"], s["snr_white"]),
            (f"{100 * grey:.0f} % grey", s["electrons_grey18"], s["snr_grey18"]),
        )
    ]
    ghost = ""
    if eff and s["etendue_own_um2sr"] > 0:
        more = eff["etendue_um2sr"] / s["etendue_own_um2sr"]
        ghost = (
            f". The table counts the own path (the signal); a white page adds its ghost "
            f"light, {_percent(100 * (more - 1))} % more: {num(s['electrons_white'] * more)} e- at "
            "white in all, the figure <code>opticalstamp scan</code> prints"
        )
    target = (
        f"SNR {s['target_snr_white']:g} at white needs an exposure of "
        f"<b>{s['exposure_for_target_ms']:.3g} ms</b> per line: at most "
        f"<b>{num(s['max_line_rate_for_target_hz'])} lines/s</b>"
        + ("" if el["exposure_duty"] == 1 else f" (exposing {el['exposure_duty']:g} of a line)")
    )
    if s["saturates_at_target"]:
        target += (
            ", more than the full well holds: out of reach (a full well gives an SNR of at "
            f"most about {math.sqrt(well):.0f})"
        )
    fill = 100 * s["full_well_fraction_white"]
    warn = (
        f"<p><b>warning:</b> white saturates the pixels ({fill:.0f} % of the full well with "
        f"the dark signal): an exposure below {s['exposure_to_full_well_ms']:.3g} ms or less "
        "light keeps it in range.</p>"
        if s["saturated_white"]
        else ""
    )
    return f"""<h3>Signal and noise</h3>
<p>A used pixel with the design's electronics ({el["illuminance_lux"]:,.0f} lux on the
page, {el["exposure_ms"]:.3g} ms per line, QE {el["quantum_efficiency"]:.2g},
{well:,.0f} e- full well, {el["read_noise_e"]:.3g} e- read noise,
{el["adc_bits"]}-bit ADC; a design file's <code>[electronics]</code>) and its own-path
etendue of {s["etendue_own_um2sr"]:.4g} µm²·sr{ghost}. Temporal SNR: photon and dark
shot noise, read noise, quantisation (the shading correction removes PRNU).</p>
{table(rows, ["reflectance", "electrons (own path)", "of the full well", "SNR"])}
<p>{target}.</p>
{warn}"""


def _ghost_span(g: dict) -> str:
    """Where the ghost light lands on the object plane, as "6.1-34 mm away" (at Z = 0)."""
    land = [v for v in g["landing"].values() if v.get("nearest_um") is not None]
    if not land:
        return ""
    near = min(v["nearest_um"] for v in land) / 1000
    med = max(v.get("median_um") or 0.0 for v in land) / 1000
    return f"{near:.1f} mm (nearest) to {med:.0f} mm (median) from the pixel's axis"


def rodlens_html(r: dict | None, paper: bool = False) -> str:
    """The report's "stamp against a rod-lens array" section: the paper's statements next
    to the model's for each rod-lens design, and which class the paper's figure fits.

    ``r``: report.json's "rodlens" (None where it was not run): ``rows``, the stamp first,
    then rod-lens arrays; ``area_gain``, the stamp's own light with its sensitive area's
    sides doubled over the design's (None if not computed).
    """
    if r is None:
        return ""
    rows, area_gain = r["rows"], r["area_gain"]
    stamp, rods = rows[0], rows[1:]
    body = []
    for r in rods:
        ratio = r["light_vs_f10"] / stamp["light_vs_f10"]
        custom = ratio / area_gain if area_gain else None
        body.append(
            [
                r["name"],
                f"1/{ratio:.0f}",
                "-" if custom is None else f"1/{custom:.0f}",
                r["thickness_mm"],
                "{:.2f} .. {:.2f}".format(*r["dof_mm"]),
            ]
        )
    if paper:  # the paper's statements, for its own prototype only
        body.append(
            [
                f"the paper's statement (its prototype, {stamp['name']})",
                f"about {one_in(PAPER['vs_rod_lens'])}",
                one_in(PAPER["vs_rod_lens_4x_area"]),
                f"≥ {PAPER['rod_lens_thickness_min']:g} (stamp {PAPER['thickness']:g})",
                "-",
            ]
        )
    head = [
        "rod-lens array",
        "stamp's light / array's",
        "with a 4x sensor area",
        "array thickness (mm)",
        f"array's {stamp.get('dof_dpi', 200.0):g}-dpi DOF (mm from focus)",
    ]
    best = min(
        rods,
        key=lambda r: abs(
            math.log(r["light_vs_f10"] / stamp["light_vs_f10"] * PAPER["vs_rod_lens"])
        ),
    )
    fit = best["light_vs_f10"] / stamp["light_vs_f10"]
    return (
        "<h2>The stamp against a rod-lens array (paper §4, §5)</h2>"
        + table(body, head)
        + (
            f"<p>The paper's ~1/100 fits <b>{html.escape(best['name'])}</b> (model 1/{fit:.0f}). "
            if paper
            else "<p>"
        )
        + f"The stamp ({html.escape(stamp['name'])}) is {stamp['thickness_mm']:.2f} mm from "
        f"sensor to document reference and keeps {stamp.get('dof_dpi', 200.0):g}-dpi contrast "
        f"≥ 0.3 up to "
        f"{stamp['dof_mm'][1]:.2f} mm; light is the stamp's own path (ghost light is "
        "crosstalk, not signal). Model and assumptions: docs/rodlens.md; any designs side by "
        "side: <code>opticalstamp compare</code>.</p>"
        + '<img src="rodlens_contrast.png" alt="contrast vs height">'
        + '<img src="rodlens_light.png" alt="light and thickness">'
    )


def _stack_html(rows: list[dict] | None) -> str:
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


def _summary_html(s: dict | None) -> str:
    """The verdict card at the top of the report."""
    if not s:
        return ""
    body = []
    paper = any(f["paper"] is not None for f in s["figures"])
    for f in s["figures"]:
        v = f["value"]
        if v is None:
            continue
        unit = f" {f['unit']}" if f["unit"] else ""
        ratio = f["figure"] in ("light", "vs_rod_lens")  # written as 1/N
        shown = f"{'≥ ' if f['bound'] else ''}{one_in(v) if ratio else _fmt(float(v))}{unit}"
        shown = f.get("text") or shown
        c = f["check"]
        if ratio and c is not None:  # the spec's unit too: a ratio, not 1/N
            shown += f" (ratio {float(v):.4f})"
        verdict = (
            "-"
            if c is None
            else f"{c['spec']}: "
            + ("PASS" if c["pass"] else ("FAIL" if c["pass"] is False else "not computed"))
        )
        dof_like = f["figure"] in ("dof", "raw_dof", "restored_dof")
        what = f["what"] + (f" at {s['dof_dpi']:g} dpi" if dof_like else "")
        row = [what, shown, verdict]
        if paper:
            p = f["paper"]
            row.append("-" if p is None else (one_in(p) if ratio else _fmt(p)))
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
    return (
        f"<div style='border:2px solid #444;padding:.5em 1em;margin:1em 0'>"
        f"<h2>Verdict</h2><p>{top}</p>"
        + table(body, head)
        + (f"<p>{html.escape(s['yield_note'])}.</p>" if s.get("yield_note") else "")
        + f"<p>Ghost light ({s['ghost_fraction']:.3g} of all light) lands no nearer than "
        f"{html.escape(near)} from the pixel's axis: the design is ghost-free within that "
        "radius; own-path light is the signal.</p></div>"
    )


def _spurious_html(r: dict) -> str:
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


def _chart_why(r: dict, design: Design) -> str:
    """Why the depth-of-field chart is the one it is, where it is the default."""
    line = nominal_dpi(design)
    if abs(r["dof_dpi"] - dof_chart_dpi(design)) < 1e-9:
        return f" (2/3 of the design's {line:g} dpi, as the paper's 200 dpi for its 300)"
    return f" (chosen; the default is {dof_chart_dpi(design):g} dpi, 2/3 of {line:g} dpi)"


def _area_html(area_rows: list) -> str:
    """The sensitive-area study, where it could be run (a larger area that fits the pitch)."""
    if len(area_rows) < 2:
        return (
            "<p>Sensitive-area study: not run (a sensitive area twice as wide would not fit "
            "between this design's used pixels).</p>"
        )
    return (
        "<p>Effect of the sensitive-area size: a custom sensor whose used pixels are larger "
        "than this sensor's pitch allows, as large as the used-pixel lattice leaves room "
        "for (the paper, §5, expects 4x the light from 4x the area):</p>"
        + table(
            area_rows, ["side (µm)", "area ratio", "own-path gain", "total gain", "ghost fraction"]
        )
    )


def _paper_html(rows: list[dict] | None) -> str:
    """The paper's statements on its prototype against the model's figures (computed)."""
    if not rows:
        return ""
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
