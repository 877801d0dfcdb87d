"""`opticalstamp compare`: designs of any kind side by side, as JSON, PNGs and one page."""

from __future__ import annotations

import html
from pathlib import Path

from ..analysis.raywave import LIGHT_TOLERANCE, RMTF_TOLERANCE
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
        body.append(
            [
                r["name"],
                r["kind"],
                r["light_vs_f10"],
                r["light_vs_first"],
                r["working_f_number"],
                r["thickness_mm"],
                "{:.2f} .. {:.2f}".format(*r["dof_mm"]),
                r["dof_span_mm"],
                r["ghost_fraction"],
                engine_cell(r),
                *wave_cells(r),
            ]
        )
    head = [
        "design",
        "kind",
        "light vs F/10",
        "light vs first",
        "working F",
        "thickness (mm)",
        f"{rows[0]['dof_dpi']:g}-dpi DOF (mm from nominal)",
        "DOF span (mm)",
        "ghost fraction",
        "optics of these figures",
        "Fresnel number, smallest",
        "light wave/ray",
        "DOF wave / ray, own + near (mm)",
        "ray vs wave optics",
    ]
    return table(body, head)


def engine_cell(r: dict) -> str:
    """Which optics gave a row's light, contrast and depth of field: a stamp's engine
    (ray or wave, and whether asked for or chosen by the validity rule); a rod-lens
    array's own tracer."""
    o = r.get("optics")
    if not o:
        return "rod-lens tracer" if r["kind"] == "rod-lens-array" else "ray"
    how = "asked for" if o.get("asked") == o.get("engine") else "auto"
    return f"{o['engine']} ({how})"


def wave_cells(r: dict) -> list:
    """A row's ray-vs-wave cells: the smallest Fresnel number, the wave/ray light ratio,
    the depth of field by both engines and which optics holds (or why there is none)."""
    w = r.get("wave") or {}
    fres = "n/a" if r.get("fresnel_min") is None else f"{r['fresnel_min']:.2f}"
    if "holds" not in w:
        why = w.get("note") or f"not measurable: {w.get('not_measurable', 'not computed')}"
        return [fres, why, "-", "-"]
    ratio = w["light_wave_over_ray"]
    open_w, open_r = ("≥ " if w["dof_open_ended"][k] else "" for k in ("wave", "ray"))
    return [
        fres,
        "-" if ratio is None else f"{ratio:.3f}",
        f"{open_w}{w['dof_wave_mm']:.2f} / {open_r}{w['dof_ray_mm']:.2f}",
        "ray optics holds" if w["holds"] == "ray" else "diffraction dominates",
    ]


def page(rows: list[dict], figures: dict[str, str]) -> str:
    notes = "".join(
        f"<li><b>{html.escape(r['name'])}</b>: {html.escape(r['ghost_note'])}; "
        f"{html.escape(r['dof_detail']['note'])}"
        + (
            f". Ray vs wave optics: {html.escape(r['wave']['verdict'])}"
            if "verdict" in (r.get("wave") or {})
            else ""
        )
        + "</li>"
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
        "away from the scanner. Thickness: sensor to document reference. Ray vs wave "
        "optics: the smallest Fresnel number a²/(λd) of a stamp's masks over the gaps below "
        "them; light and depth of field of the own path and near crosstalk by the wave "
        "engine and by the tracer's rays in its band (the far ghost light left out on both "
        "sides), at a few heights on the same chart; ray optics holds where the two agree "
        f"within {LIGHT_TOLERANCE * 100:g} % in light and {RMTF_TOLERANCE:g} in RMTF at every "
        "height.</p>"
        f"<ul>{notes}</ul>{imgs}</body></html>"
    )


def write_comparison(
    designs, out_dir: str | Path, *, seed: int = 0, fresnel: bool = False, optics: str = "ray"
) -> list[dict]:
    """Compare ``designs`` (each stamp by ``optics``) and write compare.json, PNGs and
    index.html into ``out_dir`` (replaced as a whole once everything is written)."""
    from . import plotting

    rows = compare(designs, seed=seed, fresnel=fresnel, optics=optics)
    engines = [(r.get("optics") or {}).get("engine") for r in rows]
    figures = {
        "contrast.png": "contrast vs object height",
        "light.png": "light and thickness",
        "text.png": "the same 8-pt text scanned by each design",
    }
    with replace_folder(Path(out_dir)) as tmp:
        save_figure(plotting.plot_compare_contrast(rows), tmp / "contrast.png")
        save_figure(plotting.plot_compare_light(rows), tmp / "light.png")
        panels = text_scans(designs, seed=seed, fresnel=fresnel, engines=engines)
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
                figures[name] = f"{d.name}: ripple, LSF, MTF and point PSFs"
        data = {"designs": rows, "provenance": [provenance(d, seed) for d in designs]}
        write_atomic(tmp / "compare.json", to_json(data))
        write_atomic(tmp / "index.html", page(rows, figures))
    return rows
