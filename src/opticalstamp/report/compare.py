"""`opticalstamp compare`: designs of any kind side by side, as JSON, PNGs and one page."""

from __future__ import annotations

import html
from pathlib import Path

from ..analysis.rodlens import rod_psf
from ..io.files import provenance, replace_folder, save_figure, to_json, write_atomic
from ..studies.compare import TEXT_HEIGHTS_MM, compare, text_scans
from .html import table

_STYLE = (
    "body{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}"
    "table{border-collapse:collapse;font-size:90%}td,th{border:1px solid #ccc;padding:3px 6px}"
    "img{max-width:100%}"
)


def rows_table(rows: list[dict]) -> str:
    """The comparison table (one row per design)."""
    body = []
    for r in rows:
        dof = r["dof_mm"]
        body.append(
            [
                r["name"],
                r["kind"],
                r["light_vs_f10"],
                r["light_vs_first"],
                r["working_f_number"],
                r["thickness_mm"],
                f"{dof['low']:.2f} .. {dof['high']:.2f}",
                dof["span"],
                r["ghost_fraction"],
            ]
        )
    head = [
        "design",
        "kind",
        "light vs F/10",
        "light vs first",
        "working F",
        "thickness (mm)",
        "200-dpi DOF (mm from nominal)",
        "DOF span (mm)",
        "ghost fraction",
    ]
    return table(body, head)


def page(rows: list[dict], figures: dict[str, str]) -> str:
    notes = "".join(
        f"<li><b>{html.escape(r['name'])}</b>: {html.escape(r['ghost_note'])}; "
        f"{html.escape(r['dof_mm'].get('note', 'DOF ends at the first 0.3 crossings'))}</li>"
        for r in rows
    )
    imgs = "".join(
        f'<h2>{html.escape(title)}</h2><img src="{name}" alt="{html.escape(title)}">'
        for name, title in figures.items()
    )
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>opticalstamp compare"
        f"</title><style>{_STYLE}</style></head><body><h1>Designs side by side</h1>"
        f"{rows_table(rows)}<p>Light: etendue of one output pixel from a uniform Lambertian "
        "object over the paper's F/10 1:1 lens for the same pixel (a stamp's own-path light; "
        "a rod-lens array's averaged along the array). Heights from the document reference "
        "(a stamp's reference plane, a rod-lens array's cover-glass top or focus), positive "
        "away from the scanner. Thickness: sensor to document reference.</p>"
        f"<ul>{notes}</ul>{imgs}</body></html>"
    )


def write_comparison(
    designs, out_dir: str | Path, *, seed: int = 0, fresnel: bool = False
) -> list[dict]:
    """Compare ``designs`` and write compare.json, PNGs and index.html into ``out_dir``
    (replaced as a whole once everything is written)."""
    from . import plotting

    rows = compare(designs, seed=seed, fresnel=fresnel)
    figures = {
        "contrast.png": "contrast vs object height",
        "light.png": "light and thickness",
        "text.png": "the same 8-pt text scanned by each design",
    }
    with replace_folder(Path(out_dir)) as tmp:
        save_figure(plotting.plot_compare_contrast(rows), tmp / "contrast.png")
        save_figure(plotting.plot_compare_light(rows), tmp / "light.png")
        panels = text_scans(designs, seed=seed, fresnel=fresnel)
        fig = plotting.plot_scan_panels(
            panels,
            "heights from each design's document reference",
            cols=len(TEXT_HEIGHTS_MM),
            interpolation="antialiased",
        )
        save_figure(fig, tmp / "text.png")
        for i, (d, r) in enumerate(zip(designs, rows, strict=True)):
            if r["kind"] == "rod-lens-array":
                name = f"rodlens-{i}.png"
                psf = rod_psf(d, seed=seed)
                save_figure(plotting.plot_rod_details(r, psf), tmp / name)
                figures[name] = f"{d.name}: ripple, MTF and point PSFs"
        data = {"designs": rows, "provenance": [provenance(d, seed) for d in designs]}
        write_atomic(tmp / "compare.json", to_json(data))
        write_atomic(tmp / "index.html", page(rows, figures))
    return rows


#: The paper's statements on the rod-lens-array scanner (section 4 and 5).
PAPER_LIGHT_RATIO = 100.0  # rod-lens array / stamp
PAPER_LIGHT_RATIO_CUSTOM = 25.0  # with a sensor customised for the stamp (4x area)
PAPER_ROD_THICKNESS_MM = 15.0  # "at least"
PAPER_STAMP_THICKNESS_MM = 5.0


def section_html(rows: list[dict], area_gain: float | None) -> str:
    """The report's "stamp against a rod-lens array" section: the paper's statements next
    to the model's for each rod-lens design, and which class the paper's figure fits.

    ``rows``: the stamp first, then rod-lens arrays; ``area_gain``: the stamp's own light
    with its sensitive area's sides doubled over the design's (None if not computed).
    """
    import math

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
                f"{r['dof_mm']['low']:.2f} .. {r['dof_mm']['high']:.2f}",
            ]
        )
    body.append(
        [
            f"paper (stamp: {stamp['name']})",
            f"about 1/{PAPER_LIGHT_RATIO:.0f}",
            f"1/{PAPER_LIGHT_RATIO_CUSTOM:.0f}",
            f">= {PAPER_ROD_THICKNESS_MM:g} (stamp {PAPER_STAMP_THICKNESS_MM:g})",
            "-",
        ]
    )
    head = [
        "rod-lens array",
        "stamp's light / array's",
        "with a 4x sensor area",
        "array thickness (mm)",
        "array's 200-dpi DOF (mm from focus)",
    ]
    best = min(
        rods,
        key=lambda r: abs(math.log(r["light_vs_f10"] / stamp["light_vs_f10"] / PAPER_LIGHT_RATIO)),
    )
    fit = best["light_vs_f10"] / stamp["light_vs_f10"]
    return (
        "<h2>The stamp against a rod-lens array (paper §4, §5)</h2>"
        + table(body, head)
        + f"<p>The paper's ~1/100 fits <b>{html.escape(best['name'])}</b> (model 1/{fit:.0f}). "
        f"The stamp ({html.escape(stamp['name'])}) is {stamp['thickness_mm']:.2f} mm from sensor "
        f"to document reference and keeps 200-dpi contrast >= 0.3 up to "
        f"{stamp['dof_mm']['high']:.2f} mm; light is the stamp's own path (ghost light is "
        "crosstalk, not signal). Model and assumptions: docs/rodlens.md; any designs side by "
        "side: <code>opticalstamp compare</code>.</p>"
        + '<img src="rodlens_contrast.png" alt="contrast vs height">'
        + '<img src="rodlens_light.png" alt="light and thickness">'
    )
