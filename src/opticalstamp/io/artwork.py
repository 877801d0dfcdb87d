"""Mask artwork: the aperture-array layers of a stamp as GDSII (gdstk) or DXF (ezdxf).

Coordinates are the design's, in micrometres: x along the sensor line, y across it, the
hole of used pixel k of row A at (k p, 0) and of row B at (b_x + k p, b_y), k centred on
0 over the sensor line (``sensor.pixels_per_row``, default one A4 line), each mask's
designed misregistration (``offset_x_um``, ``offset_y_um``) applied to its holes. Seen
from the object side (the side the masks are drawn on, looking down at the sensor).

Tone: the drawn polygons are the holes, the clear (transparent) openings of the mask;
everything not drawn is the absorbing layer (chrome on a photomask: a dark-field mask,
drawn = clear). The alignment crosses are drawn the same way: clear crosses in the
absorber. A process that draws the absorber instead needs the tone reversed.

Grid: the GDSII database unit is 1 nm (``DBU_UM``; user unit 1 um), and every length the
artwork draws is a whole number of it, so KLayout and mask writers read the arrays
exactly as designed (an off-grid array vector is split into sub-arrays whose pitches
alternate, 84.667/84.666 um for a pitch of 84.66667 um). :func:`grid_problems` lists the
design's fields that break the rule: the row pitch (the array's pitch), the row-B stagger
and each mask's misregistration must be whole nanometres, hole sizes whole multiples of
2 nm (a hole is centred on its grid point, so its half-size is drawn). Such a design is
refused (:class:`OffGridError`) rather than snapped: the artwork carries the design's
fingerprint and must be that design; the message gives the nearest values on the grid
and the error snapping would make over the line. Designs from ``scale_to_dpi`` (and so
``search --dpi``) are on the grid. DXF has no database unit; it follows the same rule so
that both formats hold the same geometry.

Layers: GDS layer n (datatype 0) is the mask counted from the object side, as the
paper numbers them (layer 1 faces the document); its holes are array references of one
hole cell, one per row of used pixels, so a file for an A4 line stays a few kilobytes.
GDSII stores an array's column count in 16 bits: a row of more than ``MAX_ARRAY``
(32,767) holes is drawn as several references end to end (DXF's MINSERT count is 16
bits too and is split the same way). Its coordinates are 32-bit whole database units:
an artwork reaching beyond ``MAX_EXTENT_UM`` (+-2.147 m) from the line's centre cannot
be written and is refused (:class:`ArtworkError`, naming the sensor's fields).
Datatype 1 of every layer holds the alignment marks (crosses at both ends of the line,
at the same nominal place on every layer, no misregistration); a text label on each
layer names the design, its fingerprint and the mask. DXF: one layer per mask named
after it, the hole as a block inserted as a grid (MINSERT), marks on "<mask> marks".
"""

from __future__ import annotations

import tempfile
import unicodedata
from dataclasses import dataclass
from pathlib import Path

from ..design import Design, DesignError
from ..design.variants import MASK_GRID_UM
from .files import file_stem, write_atomic

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
#: GDSII database unit (um): every coordinate is a whole number of it (1 nm).
DBU_UM = MASK_GRID_UM
#: GDSII user unit (um): lengths in the file are read in micrometres.
USER_UNIT_UM = 1.0
#: How far (in database units) a length may sit from the grid and count as on it: the
#: rounding of a decimal number like 84.6 um in binary floating point.
GRID_SLACK_DBU = 1e-6
#: Most columns (or rows) of one GDSII array reference (AREF's COLROW: 16-bit signed) and
#: of one DXF MINSERT (group codes 70/71: 16-bit): longer rows are split.
MAX_ARRAY = 32_767
#: Farthest any point of the artwork may lie from the origin (um): GDSII coordinates are
#: 32-bit signed whole database units (2^31 - 1 nm, 2.147 m).
MAX_EXTENT_UM = (2**31 - 1) * DBU_UM


class OffGridError(DesignError):
    """A design whose artwork would not sit on the database grid (1 nm)."""


class ArtworkError(DesignError):
    """A design whose artwork the file formats cannot hold (a line longer than GDSII's
    coordinates reach)."""


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


def _grid_lengths(design: Design) -> list[tuple[str, float, int]]:
    """``(field, value um, grid step in database units)`` of every length the artwork
    draws, by the design field it comes from (see :func:`grid_problems`)."""
    s = design.sensor
    out = [("sensor.row_pitch_um", s.row_pitch_um, 1)]
    if s.rows == 2:
        out += [("sensor.row_b_offset_x_um", s.row_b_offset_x_um, 1)]
        out += [("sensor.row_b_offset_y_um", s.row_b_offset_y_um, 1)]
    for i, sl in enumerate(design.slabs):
        m = sl.mask_top
        if m is None:
            continue
        where = f"slabs.{i}.mask_top"
        sizes = ("width_um", "height_um") if m.shape == "rectangle" else ("size_um",)
        out += [(f"{where}.{key}", getattr(m, key), 2) for key in sizes]
        out += [(f"{where}.{key}", getattr(m, key), 1) for key in ("offset_x_um", "offset_y_um")]
    return out


def grid_problems(design: Design) -> list[str]:
    """The design's lengths that the artwork cannot draw on its database grid.

    Parameters
    ----------
    design : Design

    Returns
    -------
    list of str
        One line per field off the grid (empty: the artwork is exact): the field, its
        value, the nearest value on the grid and what snapping to it would do. The row
        pitch (``sensor.row_pitch_um``, the arrays' pitch) and the row-B stagger and each
        mask's misregistration (the arrays' origins) must be whole multiples of
        ``DBU_UM`` (1 nm); hole sizes whole multiples of 2 nm, as a hole is drawn centred
        on its grid point (+-half its size).
    """
    n = design.sensor.n_per_row
    out = []
    for field, value, step in _grid_lengths(design):
        steps = value / DBU_UM / step
        if abs(steps - round(steps)) <= GRID_SLACK_DBU:
            continue
        near = round(round(steps) * step * DBU_UM, 3)
        err_nm = (near - value) * 1000
        if field == "sensor.row_pitch_um":
            cost = (
                f"the pitch {abs(err_nm):.3g} nm {'longer' if err_nm > 0 else 'shorter'}, "
                f"adding up to {abs(err_nm) * (n - 1) / 1000:.3g} µm at the end of a row of "
                f"{n} holes"
            )
        elif step == 2:
            cost = (
                f"the hole {abs(err_nm):.3g} nm {'larger' if err_nm > 0 else 'smaller'}; "
                "hole sizes are whole multiples of 2 nm, as a hole is drawn centred"
            )
        else:
            cost = f"the holes moved by {abs(err_nm):.3g} nm"
        out.append(
            f"{field} = {value!r} µm is off the grid; nearest on it: {near!r} µm (snapped: {cost})"
        )
    return out


def check_on_grid(design: Design) -> None:
    """Raise :class:`OffGridError` naming every field :func:`grid_problems` finds."""
    problems = grid_problems(design)
    if problems:
        raise OffGridError(
            "\n  ".join(
                [
                    f"masks: design {design.name!r}: the artwork's database unit is "
                    f"{DBU_UM * 1000:g} nm (GDSII) and every length it draws must be a whole "
                    "number of it; these are not (refused rather than snapped: the artwork "
                    "carries the design's fingerprint, so put the values on the grid in the "
                    "design file; designs scaled by search --dpi or scale_to_dpi are on it):",
                    *problems,
                ]
            )
        )


def check_extent(design: Design) -> None:
    """Raise :class:`ArtworkError` where the artwork reaches beyond ``MAX_EXTENT_UM``.

    The line of ``sensor.pixels_per_row`` holes at ``sensor.row_pitch_um``, centred on 0,
    with its alignment marks and labels, must lie within GDSII's 32-bit coordinates at
    the 1-nm database unit (+-2.147 m); DXF is held to the same rule so that both formats
    hold the same geometry.
    """
    s = design.sensor
    xs = [x for (x0, _), (x1, _) in mark_rectangles(design) for x in (x0, x1)]
    margin = MARK_GAP_UM + MARK_ARM_UM + (abs(s.row_b_offset_x_um) if s.rows == 2 else 0.0)
    margin += max(abs(m.offset_x_um) for m in design.masks)  # the holes beyond the marks
    reach = max(abs(x) for x in xs) + margin - MARK_GAP_UM - MARK_ARM_UM
    if reach <= MAX_EXTENT_UM:  # y: a few mm at most (offsets <= 10 mm)
        return
    n, p = s.n_per_row, s.row_pitch_um
    most = int(2 * (MAX_EXTENT_UM - margin) // p)
    raise ArtworkError(
        f"masks: design {design.name!r}: sensor.pixels_per_row = {n:,} holes at "
        f"sensor.row_pitch_um = {p:g} µm make a line {n * p / 1e6:.3g} m long, and its "
        f"artwork would reach {reach / 1e6:.3g} m from the centre; GDSII coordinates (32-bit, "
        f"1-nm database unit) reach {MAX_EXTENT_UM / 1e6:.4g} m: at most {max(most, 0):,} "
        "holes per row at this pitch (no photomask is that long either)"
    )


def _runs(m: MaskLayout) -> list[tuple[int, int]]:
    """(first hole, count) of each array reference of one row: at most MAX_ARRAY each."""
    return [(j, min(MAX_ARRAY, m.count - j)) for j in range(0, m.count, MAX_ARRAY)]


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


def _on_grid(value_um: float) -> float:
    """``value_um`` rounded to the database grid (a whole number of ``DBU_UM``), as the
    float nearest that decimal (42.3, not 42.300000000000004)."""
    return round(value_um / DBU_UM) / round(1 / DBU_UM)


def mark_positions(design: Design) -> list[tuple[float, float]]:
    """Centres of the alignment crosses: beyond both ends of the line, between the rows
    (halfway, rounded to the database grid: 21.166 um for a stagger of 42.333 um)."""
    s = design.sensor
    n = s.n_per_row
    k_lo = -(n // 2)
    x0 = k_lo * s.row_pitch_um - MARK_GAP_UM
    x1 = (k_lo + n - 1) * s.row_pitch_um + max(0.0, s.row_b_offset_x_um) + MARK_GAP_UM
    y = s.row_b_offset_y_um / 2 if s.rows == 2 else 0.0
    return [(_on_grid(x0), _on_grid(y)), (_on_grid(x1), _on_grid(y))]


def mark_rectangles(design: Design) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """The alignment crosses as rectangles ((x0, y0), (x1, y1)): two arms per cross."""
    a, t = MARK_ARM_UM, MARK_WIDTH_UM / 2
    out = []
    for cx, cy in mark_positions(design):
        out += [((cx - a, cy - t), (cx + a, cy + t)), ((cx - t, cy - a), (cx + t, cy + a))]
    return out


def _label(design: Design, m: MaskLayout) -> str:
    """The text on each layer, printable ASCII: the design's name as a file stem (no
    spaces; an exported design's file name without ``.toml``), its fingerprint, the
    layer and the mask's name."""
    text = unicodedata.normalize("NFKD", m.name).encode("ascii", "ignore").decode("ascii")
    mask = "".join(c for c in text if " " <= c <= "~")
    return f"{file_stem(design.name)} {design.fingerprint()} layer {m.layer}: {mask}"


def gds_bytes(design: Design) -> bytes:
    """The design's masks as a GDSII stream (gdstk): user unit 1 um, database unit 1 nm.

    Raises
    ------
    OffGridError
        A length the artwork draws is not on the 1-nm grid (:func:`grid_problems`).
    ArtworkError
        The line is longer than GDSII's coordinates reach (:func:`check_extent`).
    """
    import gdstk

    check_on_grid(design)
    check_extent(design)
    lib = gdstk.Library(
        f"opticalstamp-{file_stem(design.name)}", unit=USER_UNIT_UM * 1e-6, precision=DBU_UM * 1e-6
    )
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
            for j, cols in _runs(m):  # GDSII: at most MAX_ARRAY columns a reference
                at = (_on_grid(x + j * m.pitch_um), y)
                top.add(gdstk.Reference(hole, at, columns=cols, rows=1, spacing=(m.pitch_um, 0)))
        for p, q in mark_rectangles(design):
            top.add(gdstk.rectangle(p, q, layer=m.layer, datatype=1))
        x, y = mark_positions(design)[0]
        top.add(gdstk.Label(_label(design, m), (x, y - 2 * MARK_ARM_UM), layer=m.layer))
    with tempfile.TemporaryDirectory(prefix="opticalstamp_gds_") as tmp:
        path = Path(tmp) / "masks.gds"
        lib.write_gds(str(path))
        return path.read_bytes()


def dxf_bytes(design: Design) -> bytes:
    """The design's masks as DXF (ezdxf): lengths in um, one layer per mask; the same
    grid rule as GDSII (:class:`OffGridError`), so both formats hold the same geometry."""
    import io

    import ezdxf

    check_on_grid(design)
    check_extent(design)

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
            for j, cols in _runs(m):  # MINSERT: at most MAX_ARRAY columns
                at = (_on_grid(x + j * m.pitch_um), y)
                ref = msp.add_blockref(block.name, at, dxfattribs={"layer": layer})
                ref.grid(size=(1, cols), spacing=(0, m.pitch_um))
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
    """Write the mask artwork atomically; ``fmt`` gds or dxf (default: the suffix).

    Raises
    ------
    ValueError
        An unknown format.
    OffGridError
        The design's lengths are not on the artwork's 1-nm grid (nothing is written).
    ArtworkError
        The line is longer than GDSII's coordinates reach (nothing is written).
    """
    path = Path(path)
    fmt = (fmt or path.suffix.lstrip(".")).lower()
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)} (got {fmt!r})")
    data = gds_bytes(design) if fmt == "gds" else dxf_bytes(design)
    return write_atomic(path, data)
