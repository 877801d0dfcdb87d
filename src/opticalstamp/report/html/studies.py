"""The page's sections of the report's background studies: the paper's unstated
parameters, the design search and tolerancing, the stamp against a rod-lens array."""

from __future__ import annotations

import html
import math

from ...analysis.dof import dof_text
from ..paper import one_in
from ..summary import PAPER
from .common import table, unmeasured


def headline_dof(rmtf: dict | None) -> str:
    """The report's own depth of field beside a study's estimate of it."""
    if rmtf is None:
        return "fewer rays than the RMTF section"
    return (
        f"fewer rays than the RMTF section, whose figure of record is {html.escape(dof_text(rmtf))}"
    )


def search_html(
    s: dict | None, t: dict | None, quick: bool = False, rmtf: dict | None = None
) -> str:
    """The design search and the tolerance study; ``rmtf``: the RMTF section's result,
    whose depth of field is this design's figure of record (the search's own estimate of
    the base, with fewer rays, stands beside it; None where it is not measurable)."""
    if s is None:
        why = "left out of this quick report" if quick else "needs square holes"
        return f"<h2>Design search and tolerancing</h2><p>({why})</p>"
    tol = tolerance_html(t)
    missing = unmeasured("Design search (paper §3)", s)
    if missing is not None:
        return missing + tol

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
            one_in(p["efficiency_ratio"]),
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
    wave = s["meta"].get("optics") == "wave"
    wacc = s["meta"].get("wave_accuracy", {})
    note = (
        "The front was not re-verified."
        if not verified
        else "Each point of the front was then evaluated by the exact wave figures: they are "
        "the figures of record, the wave estimator's are beside them (the columns "
        "'surrogate'), and a point is flagged where they differ by more than the estimator's "
        f"measured accuracy (depth of field {wacc.get('dof_mm', 0):g} mm; docs/search.md)."
        if wave
        else "Each point of the front was then traced exactly: the exact figures are the "
        "figures of record, the surrogate's are beside them, and a point is flagged where they "
        f"differ by more than the surrogate's measured accuracy (depth of field "
        f"{acc.get('dof_mm', 0):g} mm where the ghost fraction is below 0.2, "
        f"{acc.get('dof_mm_high_ghost', 0):g} mm above; docs/search.md)."
    )
    ranked = s["meta"].get("wave_estimator", "") if wave else s["meta"]["estimator"]
    return f"""<h2>Design search (paper §3)</h2>
<p>NSGA-II over hole sizes and slab thicknesses ({s["n_evaluations"]} designs,
{s["n_feasible"]} feasible: no ghost light within {s["meta"]["near_mm"]:g} mm, stack within
{s["meta"]["budget_mm"]:g} mm; a compact run, `opticalstamp search` runs 480), ranked by the
{html.escape(ranked)}, every candidate by
{html.escape(s["meta"].get("optics", "ray"))} optics (the report's).
{note} This design: efficiency {one_in(ref["efficiency_ratio"])}, depth of field
{ref["dof_mm"]:.2f} mm at {s["meta"]["dof_dpi"]:g} dpi by the search's exact check
({headline_dof(rmtf)}), dominated by
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


def optics_engine(t: dict) -> str:
    """The engine that gave a tolerance study's figures ("ray" for a study run before the
    optics was recorded)."""
    return (t["meta"].get("optics") or {}).get("engine", "ray")


def tolerance_html(t: dict | None) -> str:
    """The tolerance study (paper §5): the RMTF's spread, the sensitivities, the yield
    (empty where it was not run)."""
    if t is None:
        return ""
    missing = unmeasured("Tolerancing (paper §5)", t)
    if missing is not None:
        return missing
    key = f"rmtf{t['dpi']:g}"
    sens = [
        [r["error"], r["sigma"], r["d_dof_mm"], r.get("d_rmtf@2", None), r["d_ghost_fraction"]]
        for r in t["sensitivity"][:10]
    ]
    rm = [[z, v["p5"], v["p50"], v["p95"], t["nominal"]["rmtf_at"][z]] for z, v in t[key].items()]
    ex = t["meta"].get("nominal_exact")
    wave = optics_engine(t) == "wave"
    est = "wave estimator" if wave else "surrogate"
    nominal = ""
    if ex:
        off = t["meta"].get("nominal_disagrees") or []
        nominal = (
            f" The nominal design {'by the exact wave figures' if wave else 'traced exactly'}"
            f": depth of field {ex['dof_mm']:.2f} mm ({est} {t['nominal']['dof_mm']:.2f} mm), "
            f"ghost fraction {ex['ghost_fraction']:.3f}"
            + (
                f"; the {est} is off beyond its accuracy in {', '.join(off)}."
                if off
                else f"; the {est} agrees within its accuracy."
            )
        )
    yld = (
        'No yield: no spec given (report --spec "dof>=2.2,light>=0.03" asks for one).'
        if not t.get("spec")
        else f"Yield for {html.escape(t['spec'])}: "
        + ("not computed." if t["yield"] is None else f"{t['yield']:.1%}.")
    )
    return f"""<h2>Tolerancing (paper §5)</h2>
<p>{t["n_samples"]} Monte Carlo samples: misregistration {t["sigmas"]["misregistration_um"]:g}
um, holes {t["sigmas"]["hole_um"]:g} µm, plates and gaps {t["sigmas"]["thickness_um"]:g} µm,
tilt {t["sigmas"]["tilt_deg"]:g} deg (1 sigma), each evaluated by the
{html.escape(t["meta"]["estimator"])}; {optics_engine(t)} optics, the report's, for every
sample. {yld}{nominal}
Errors are named from the object side: dx1 is layer 1's x misregistration, slab1 the
thickness of the slab under layer 1.</p>
{table(rm, ["Z (mm)", f"RMTF {t['dpi']:g} dpi 5 %", "median", "95 %", "nominal"])}
{table(sens, ["error", "sigma", "DOF change (mm)", "RMTF@2mm change", "ghost change"])}
<img src="tolerance.png">
"""


def study_html(st: dict | None, quick: bool = False) -> str:
    """The parameter-study section (left out of a quick report and of a report without
    the paper's sections)."""
    if st is None:
        return (
            """<h2>The paper's unstated parameters</h2>
<p>(left out of this quick report)</p>"""
            if quick
            else ""
        )
    missing = unmeasured("The paper's unstated parameters", st)
    if missing is not None:
        return missing
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


def rodlens_html(r: dict | None, paper: bool = False) -> str:
    """The report's "stamp against a rod-lens array" section: the paper's statements next
    to the model's for each rod-lens design, and which class the paper's figure fits.

    ``r``: report.json's "rodlens" (None where it was not run): ``rows``, the stamp first,
    then rod-lens arrays; ``area_gain``, the stamp's own light with its sensitive area's
    sides doubled over the design's (None if not computed).
    """
    if r is None:
        return ""
    missing = unmeasured("The stamp against a rod-lens array (paper §4, §5)", r)
    if missing is not None:
        return missing
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
