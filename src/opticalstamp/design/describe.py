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
