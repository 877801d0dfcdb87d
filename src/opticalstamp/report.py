"""`opticalstamp report`: every analysis of a design as JSON, PNG and one HTML page."""

from __future__ import annotations

import html
import time
from pathlib import Path

from .design import Design, load_design
from .ghosts import analyse_ghosts
from .io import provenance, save_figure, to_json, write_atomic
from .response import psf, spots

Z_MM = (0.0, 1.0, 2.0, 3.0, 4.0)
CONCEPTS = ("fig1b", "fig1c", "fig1d", "three-layer-single-row", "paper2016")


def build_report(
    design: Design,
    out_dir: str | Path,
    *,
    seed: int = 0,
    n_rays: int = 1 << 22,
    fresnel: bool = False,
    progress: bool = False,
) -> dict:
    """Run every analysis and write report.json, PNG figures and index.html to out_dir."""
    from . import plotting

    out = Path(out_dir)
    t0 = time.perf_counter()
    g = analyse_ghosts(design, z_mm=Z_MM, seed=seed, fresnel=fresnel, progress=progress)
    sp = spots(design, z_mm=Z_MM, seed=seed, n_rays=n_rays, fresnel=fresnel, progress=progress)
    psfs = [
        psf(
            design,
            x_obj_um=x,
            z_mm=1.0,
            seed=seed,
            n_rays=n_rays,
            fresnel=fresnel,
            progress=progress,
        )
        for x in (0.0, 42.3)
    ]
    concepts = []
    for name in CONCEPTS:
        c = analyse_ghosts(load_design(name), z_mm=(0.0,), seed=seed, fresnel=fresnel)
        concepts.append(
            {
                "design": name,
                "etendue_own_um2sr": c.etendue_own_um2sr,
                "etendue_ghost_um2sr": c.etendue_ghost_um2sr,
                "ghost_fraction": c.ghost_fraction,
                "nearest_ghost_um_z0": c.landing["0"]["nearest_um"],
            }
        )
    figs = {
        "ghosts.png": plotting.plot_ghosts(g),
        "spots.png": plotting.plot_spots(sp),
        "psf_x0.png": plotting.plot_psf(psfs[0]),
        "psf_x42.png": plotting.plot_psf(psfs[1]),
    }
    for name, fig in figs.items():
        save_figure(fig, out / name)
    data = {
        "provenance": provenance(design, seed) | {"fresnel": fresnel},
        "design": design.model_dump(mode="json"),
        "ghosts": g.to_dict(),
        "spots": sp.to_dict(),
        "psf": [p.to_dict() for p in psfs],
        "concepts": concepts,
        "elapsed_s": time.perf_counter() - t0,
    }
    write_atomic(out / "report.json", to_json(data))
    write_atomic(out / "index.html", _html(design, data))
    return data


def _table(rows: list[list], head: list[str]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(_fmt(c))}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><tr>{th}</tr>{body}</table>"


def _fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "-" if v is None else str(v)


def _html(design: Design, d: dict) -> str:
    g, sp = d["ghosts"], d["spots"]
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
        [z, v["nearest_um"], v["median_um"], v["within_detector_um2sr"]]
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
        for c in d["concepts"]
    ]
    prov = d["provenance"]
    return f"""<!doctype html><html><head><meta charset="utf-8">
<title>opticalstamp report: {html.escape(design.name)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto;padding:1em}}
table{{border-collapse:collapse;margin:.5em 0}}td,th{{border:1px solid #bbb;padding:2px 6px;
font-size:13px;text-align:right}}img{{max-width:100%}}</style></head><body>
<h1>opticalstamp report: {html.escape(design.name)}</h1>
<p>{html.escape(design.description)}</p>
<p>design fingerprint {prov["design_fingerprint"]}, seed {prov["seed"]},
opticalstamp {prov["opticalstamp_version"]}, Fresnel losses {"on" if prov["fresnel"] else "off"},
pixel acceptance half-angle {design.sensor.acceptance_half_angle_deg:g} deg.
Numbers: <a href="report.json">report.json</a>.</p>
<h2>Ghost analysis (paper Figs. 2 and 4)</h2>
<p>Own-path etendue {g["etendue_own_um2sr"]:.4g} &plusmn; {g["etendue_own_se"]:.2g} um&sup2;sr,
ghost etendue {g["etendue_ghost_um2sr"]:.4g} &plusmn; {g["etendue_ghost_se"]:.2g} um&sup2;sr,
ghost fraction {g["ghost_fraction"]:.4g} &plusmn; {g["ghost_fraction_se"]:.2g}
({g["n_rays"]:,} importance-sampled rays).</p>
{
        _table(
            ghost_rows,
            [
                "holes (object side first)",
                "etendue",
                "se",
                "share of ghost",
                "emission angle (deg)",
                "nearest landing at Z=0 (um)",
            ],
        )
    }
<p>Where ghost light meets the object plane (distance from the pixel's axis) and how much
lands inside the virtual detector (&plusmn;{
        g["landing"][next(iter(g["landing"]))]["detector_half_um"]:g} um):</p>
{_table(land_rows, ["Z (mm)", "nearest (um)", "median (um)", "inside detector (um2 sr)"])}
<img src="ghosts.png">
<h3>The paper's Fig. 1 concepts</h3>
{
        _table(
            conc,
            [
                "design",
                "own etendue",
                "ghost etendue",
                "ghost fraction",
                "nearest ghost at Z=0 (um)",
            ],
        )
    }
<h2>Spots on the object plane (paper Fig. 5)</h2>
{
        _table(
            spot_rows,
            [
                "Z (mm)",
                "extent x (um)",
                "extent y (um)",
                "FWHM x (um)",
                "FWHM y (um)",
                "fraction in centre 84.6 um cell",
            ],
        )
    }
<img src="spots.png">
<h2>PSFs on the sensor (paper Fig. 10)</h2>
{
        _table(
            psf_rows,
            [
                "X obj (um)",
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
<p>Generated in {d["elapsed_s"]:.1f} s.</p>
</body></html>
"""
