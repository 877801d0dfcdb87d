"""A design described for people: the stack as a table, object side first.

Layers are numbered from the object side, as the paper numbers its aperture layers
("layer 1" faces the document); the design file lists slabs from the sensor upward.
"""

from __future__ import annotations

from .model import Design


def stack_rows(design: Design) -> list[dict]:
    """One row per slab, object side first: layer number (masks only), medium and its index
    at the design's wavelength, thickness, z of its bottom and top (um from the sensor),
    and its mask's hole (shape, size, designed offset)."""
    rows, z = [], 0.0
    n_masks = len(design.masks)
    seen = 0
    for sl in design.slabs:
        m = sl.mask_top
        row = {
            "layer": None,
            "medium": sl.medium,
            "index": design.index(sl.medium),
            "thickness_um": sl.thickness_um,
            "z_bottom_um": z,
            "z_top_um": z + sl.thickness_um,
            "mask": None,
        }
        if m is not None:
            row["layer"] = n_masks - seen
            seen += 1
            row["mask"] = {
                "name": m.name or f"layer {row['layer']}",
                "shape": m.shape,
                "width_um": m.hole_width_um,
                "height_um": m.hole_height_um,
                "offset_x_um": m.offset_x_um,
                "offset_y_um": m.offset_y_um,
            }
        rows.append(row)
        z += sl.thickness_um
    g = design.reference_gap
    rows.append(
        {
            "layer": None,
            "medium": g.medium,
            "index": design.index(g.medium),
            "thickness_um": g.thickness_um,
            "z_bottom_um": z,
            "z_top_um": z + g.thickness_um,
            "mask": None,
            "reference_gap": True,
        }
    )
    return rows[::-1]


def describe(design: Design) -> str:
    """One sentence generated from the design itself (never from its free ``description``):
    layers, holes (object side first), slabs, sensor rows and resolution, thickness."""
    from .resolution import nominal_dpi, output_pitch_um

    rows = stack_rows(design)
    holes = []
    for r in rows:
        m = r["mask"]
        if m is not None:
            size = (
                f"{m['width_um']:g}"
                if m["width_um"] == m["height_um"]
                else f"{m['width_um']:g} × {m['height_um']:g}"
            )
            holes.append(f"{size} µm {m['shape']}")
    slabs = [
        f"{r['thickness_um']:g} µm {_medium(r['medium'])}"
        for r in rows
        if not r.get("reference_gap")
    ]
    s = design.sensor
    stagger = "two staggered rows" if s.rows == 2 else "one row"
    return (
        f"{len(holes)} aperture layer{'s' if len(holes) != 1 else ''} (object side first: "
        f"holes {', '.join(holes)}) over slabs of {', '.join(slabs)}; {stagger} of used pixels "
        f"every {s.row_pitch_um:g} µm on a {s.pixel_pitch_um:g}-µm sensor, merged line "
        f"{output_pitch_um(design):.4g} µm ({nominal_dpi(design):g} dpi); "
        f"{design.reference_gap.thickness_um:g} µm reference gap, "
        f"{design.reference_plane_um / 1000:.3g} mm from sensor to the reference plane; "
        f"λ = {design.wavelength_um:g} µm."
    )


def _medium(medium) -> str:
    return (
        "air"
        if medium == "air"
        else (f"glass n = {medium:g}" if not isinstance(medium, str) else medium)
    )


def sensor_warnings(design: Design) -> list[str]:
    """Where the used pixels leave the sensor's own grid (the figures stay right, but a
    real sensor has no pixel there and a per-pixel picture such as ``psf`` cannot show
    it): row B's offsets and the row pitch off the pixel pitch, row B beyond the declared
    ``lines``. One sentence each, naming the field."""
    s = design.sensor
    p = s.pixel_pitch_um
    out = []

    def off_grid(v: float) -> bool:  # beyond the 1-nm mask grid's rounding
        return abs(v - round(v / p) * p) > 0.005

    checks = [("row_pitch_um", s.row_pitch_um)]
    if s.rows == 2:
        checks += [("row_b_offset_x_um", s.row_b_offset_x_um)]
        checks += [("row_b_offset_y_um", s.row_b_offset_y_um)]
    for name, v in checks:
        if off_grid(v):
            out.append(
                f"sensor.{name} = {v:g} µm is not a whole number of pixels of the sensor's "
                f"{p:g}-µm pitch ({v / p:.3g}): no sensor pixel sits there"
            )
    if s.rows == 2 and abs(s.row_b_offset_y_um) > (s.lines - 0.5) * p + 1e-9:
        out.append(
            f"sensor.row_b_offset_y_um = {s.row_b_offset_y_um:g} µm lies beyond the sensor's "
            f"{s.lines} lines of {p:g} µm (sensor.lines): row B is off the sensor"
        )
    return out
