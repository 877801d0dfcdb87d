"""Mask artwork: the aperture-array layers of a stamp as GDSII (gdstk) or DXF (ezdxf).

Coordinates are the design's, in micrometres: x along the sensor line, y across it, the
hole of used pixel k of row A at (k p, 0) and of row B at (b_x + k p, b_y), k centred on
0 over the sensor line (``sensor.pixels_per_row``, default one A4 line), each mask's
designed misregistration (``offset_x_um``, ``offset_y_um``) applied to its holes. Seen
from the object side (the side the masks are drawn on, looking down at the sensor).

Layers: GDS layer n (datatype 0) is the mask counted from the object side, as the
paper numbers them (layer 1 faces the document); its holes are array references of one
hole cell, one per row of used pixels, so a file for an A4 line stays a few kilobytes.
Datatype 1 of every layer holds the alignment marks (crosses at both ends of the line,
at the same nominal place on every layer, no misregistration); a text label on each
layer names the design, its fingerprint and the mask. DXF: one layer per mask named
after it, the hole as a block inserted as a grid (MINSERT), marks on "<mask> marks".
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..design import Design
from .files import write_atomic

FORMATS = ("gds", "dxf")
#: Alignment mark: a cross of this arm length and line width (um), this far beyond the
#: last hole of the line (um).
MARK_ARM_UM = 200.0
MARK_WIDTH_UM = 20.0
MARK_GAP_UM = 1000.0
#: DXF $INSUNITS code of micrometres.
DXF_MICRONS = 13
#: Circle holes as polygons: largest distance between the arc and its chords (um).
CIRCLE_TOLERANCE_UM = 0.01


@dataclass(frozen=True)
class MaskLayout:
    """One mask's artwork: GDS layer, name, hole shape and size, the rows of holes."""

    layer: int
    name: str
    shape: str
    width_um: float
    height_um: float
    rows: tuple[tuple[float, float], ...]  # (x, y) of each row's first hole
    pitch_um: float
    count: int  # holes per row


def mask_layouts(design: Design) -> list[MaskLayout]:
    """Every mask's holes, the object-side mask first (GDS layer 1)."""
    s = design.sensor
    n = s.n_per_row
    k_lo = -(n // 2)
    rows = [(0.0, 0.0)]
    if s.rows == 2:
        rows.append((s.row_b_offset_x_um, s.row_b_offset_y_um))
    masks = design.masks
    out = []
    for i, m in enumerate(reversed(masks)):
        first = tuple(
            (x + k_lo * s.row_pitch_um + m.offset_x_um, y + m.offset_y_um) for x, y in rows
        )
        out.append(
            MaskLayout(
                layer=i + 1,
                name=m.name or f"mask {len(masks) - i}",
                shape=m.shape,
                width_um=m.hole_width_um,
                height_um=m.hole_height_um,
                rows=first,
                pitch_um=s.row_pitch_um,
                count=n,
            )
        )
    return out


def mark_positions(design: Design) -> list[tuple[float, float]]:
    """Centres of the alignment crosses: beyond both ends of the line, between the rows."""
    s = design.sensor
    n = s.n_per_row
    k_lo = -(n // 2)
    x0 = k_lo * s.row_pitch_um - MARK_GAP_UM
    x1 = (k_lo + n - 1) * s.row_pitch_um + max(0.0, s.row_b_offset_x_um) + MARK_GAP_UM
    y = s.row_b_offset_y_um / 2 if s.rows == 2 else 0.0
    return [(x0, y), (x1, y)]


def mark_rectangles(design: Design) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The alignment crosses as rectangles ((x0, y0), (x1, y1)): two arms per cross."""
    a, t = MARK_ARM_UM, MARK_WIDTH_UM / 2
    out = []
    for cx, cy in mark_positions(design):
        out += [((cx - a, cy - t), (cx + a, cy + t)), ((cx - t, cy - a), (cx + t, cy + a))]
    return out


def _label(design: Design, m: MaskLayout) -> str:
    return f"{design.name} {design.fingerprint()} layer {m.layer}: {m.name}"


def gds_bytes(design: Design) -> bytes:
    """The design's masks as a GDSII stream (gdstk)."""
    import gdstk

    lib = gdstk.Library(f"opticalstamp {design.name}", unit=1e-6, precision=1e-9)
    top = lib.new_cell("TOP")
    for m in mask_layouts(design):
        hole = lib.new_cell(f"HOLE_L{m.layer}")
        if m.shape == "circle":
            hole.add(
                gdstk.ellipse((0, 0), m.width_um / 2, tolerance=CIRCLE_TOLERANCE_UM, layer=m.layer)
            )
        else:
            w, h = m.width_um / 2, m.height_um / 2
            hole.add(gdstk.rectangle((-w, -h), (w, h), layer=m.layer))
        for x, y in m.rows:
            top.add(gdstk.Reference(hole, (x, y), columns=m.count, rows=1, spacing=(m.pitch_um, 0)))
        for p, q in mark_rectangles(design):
            top.add(gdstk.rectangle(p, q, layer=m.layer, datatype=1))
        x, y = mark_positions(design)[0]
        top.add(gdstk.Label(_label(design, m), (x, y - 2 * MARK_ARM_UM), layer=m.layer))
    with tempfile.TemporaryDirectory(prefix="opticalstamp_gds_") as tmp:
        path = Path(tmp) / "masks.gds"
        lib.write_gds(str(path))
        return path.read_bytes()


def dxf_bytes(design: Design) -> bytes:
    """The design's masks as DXF (ezdxf): lengths in um, one layer per mask."""
    import io

    import ezdxf

    doc = ezdxf.new("R2010")
    doc.units = DXF_MICRONS
    msp = doc.modelspace()
    for m in mask_layouts(design):
        layer = f"L{m.layer} {m.name}"
        doc.layers.add(layer)
        doc.layers.add(f"{layer} marks")
        block = doc.blocks.new(name=f"HOLE_L{m.layer}")
        if m.shape == "circle":
            block.add_circle((0, 0), m.width_um / 2, dxfattribs={"layer": layer})
        else:
            w, h = m.width_um / 2, m.height_um / 2
            pts = [(-w, -h), (w, -h), (w, h), (-w, h)]
            block.add_lwpolyline(pts, close=True, dxfattribs={"layer": layer})
        for x, y in m.rows:
            ref = msp.add_blockref(block.name, (x, y), dxfattribs={"layer": layer})
            ref.grid(size=(1, m.count), spacing=(0, m.pitch_um))
        for (x0, y0), (x1, y1) in mark_rectangles(design):
            msp.add_lwpolyline(
                [(x0, y0), (x1, y0), (x1, y1), (x0, y1)],
                close=True,
                dxfattribs={"layer": f"{layer} marks"},
            )
        x, y = mark_positions(design)[0]
        msp.add_text(
            _label(design, m), height=50.0, dxfattribs={"layer": layer, "insert": (x, y - 400)}
        )
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue().encode("utf-8")


def write_masks(design: Design, path: str | Path, fmt: str | None = None) -> Path:
    """Write the mask artwork atomically; ``fmt`` gds or dxf (default: the suffix)."""
    path = Path(path)
    fmt = (fmt or path.suffix.lstrip(".")).lower()
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)} (got {fmt!r})")
    data = gds_bytes(design) if fmt == "gds" else dxf_bytes(design)
    return write_atomic(path, data)
