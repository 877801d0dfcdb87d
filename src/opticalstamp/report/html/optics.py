"""The page's sections on where a pixel's light goes: the ghost analysis with the
paper's Fig. 1 concepts, the spots, the PSFs, diffraction."""

from __future__ import annotations

import html

from .common import table, unmeasured


def ghost_span(g: dict) -> str:
    """Where the ghost light lands on the object plane, as "6.1-34 mm away" (at Z = 0)."""
    land = [v for v in (g.get("landing") or {}).values() if v.get("nearest_um") is not None]
    if not land:
        return ""
    near = min(v["nearest_um"] for v in land) / 1000
    med = max(v.get("median_um") or 0.0 for v in land) / 1000
    return f"{near:.1f} mm (nearest) to {med:.0f} mm (median) from the pixel's axis"


def ghosts_html(g: dict) -> str:
    """The ghost analysis (paper Figs. 2 and 4): etendues, the ghost paths, where ghost
    light lands."""
    title = "Ghost analysis (paper Figs. 2 and 4)"
    missing = unmeasured(title, g)
    if missing is not None:
        return missing
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
    return f"""<h2>{title}</h2>
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
"""


def concepts_html(concepts: list[dict] | dict | None) -> str:
    """The paper's Fig. 1 concepts (none without the paper's sections)."""
    if concepts is None:
        return ""
    title = "The paper's Fig. 1 concepts"
    missing = unmeasured(title, concepts, level=3)
    if missing is not None:
        return missing
    conc = [
        [
            c["design"],
            c["etendue_own_um2sr"],
            c["etendue_ghost_um2sr"],
            c["ghost_fraction"],
            c["nearest_ghost_um_z0"],
        ]
        for c in concepts
    ]
    return f"<h3>{title}</h3>" + table(
        conc,
        ["design", "own etendue", "ghost etendue", "ghost fraction", "nearest ghost at Z=0 (µm)"],
    )


def spots_html(sp: dict, pitch_um: float) -> str:
    """The spots on the object plane (paper Fig. 5)."""
    title = "Spots on the object plane (paper Fig. 5)"
    missing = unmeasured(title, sp)
    if missing is not None:
        return missing
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
    head = [
        "Z (mm)",
        "extent x (µm)",
        "extent y (µm)",
        "FWHM x (µm)",
        "FWHM y (µm)",
        f"fraction in centre {pitch_um:.1f} µm cell",
    ]
    return f"""<h2>{title}</h2>
{table(spot_rows, head)}{_spot_channels(sp)}
<img src="spots.png">
"""


def _spot_channels(sp: dict) -> str:
    """A colour scanner's spots per channel (wave optics): the centre-cell share and the
    FWHM in x of each channel at each Z, and which one the table and figure show."""
    meta = sp.get("meta") or {}
    chans, head = meta.get("channels"), meta.get("headline")
    if not chans or not head:
        return ""
    rows = [
        [name]
        + [
            f"{f:.3f} / {w:.1f}"
            for f, w in zip(c["center_cell_fraction"], c["fwhm_x_um"], strict=True)
        ]
        for name, c in chans.items()
    ]
    cols = ["channel"] + [f"Z = {z:g} mm: centre share / FWHM x (µm)" for z in sp["z_mm"]]
    return (
        f"<p>Colour: one exposure per LED (illumination rgb), the spots channel by channel by "
        f"wave optics; the table above and the figure are the {html.escape(head['channel'])} "
        f"channel's, the widest ({html.escape(head['rule'])}).</p>{table(rows, cols)}"
    )


def psf_html(psfs: list[dict] | dict) -> str:
    """The PSFs on the sensor (paper Fig. 10)."""
    title = "PSFs on the sensor (paper Fig. 10)"
    missing = unmeasured(title, psfs)
    if missing is not None:
        return missing
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
        for p in psfs
    ]
    head = [
        "X obj (µm)",
        "Z (mm)",
        "own pixel",
        "neighbour, own-path blur",
        "ghost",
        "insensitive",
        "fraction of emitted power reaching sensor",
    ]
    return f"""<h2>{title}</h2>
{table(psf_rows, head)}
<img src="psf_x0.png"><img src="psf_half_pitch.png">
"""


def diffraction_html(df: dict, paper: bool = False) -> str:
    """Diffraction (paper Fig. 6): the design's object-side hole as a slit, and the
    per-layer budget; ``paper``: with the paper's own figure for its slit."""
    title = "Diffraction (paper Fig. 6)"
    missing = unmeasured(title, df)
    if missing is not None:
        return missing
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
    return f"""<h2>{title}</h2>
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
"""
