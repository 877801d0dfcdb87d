"""Designs derived from designs: one validated primitive and the named variants built on it.

:func:`replace` is the only way a design is derived from another: it writes changes into
the design's plain data by path (``"sensor.sensitive_width_um"``,
``"slabs.2.mask_top.size_um"``) and validates the result again, so a variant that breaks a
rule raises :class:`~opticalstamp.design.model.DesignError` naming the field. Every named
variant (new hole sizes and gaps, another resolution, fewer layers, one row of pixels, a
larger sensitive area, the paper's unstated parameters) is a set of such changes, written
once here.

Conventions of the stack (as everywhere a person reads them): layers and slabs are listed
and numbered object side first, from 1, as the paper numbers its aperture layers (layer
1 faces the document): the hole sizes, misregistrations and slab thicknesses of
:func:`with_stack` and :func:`stack_params`, the search's and the tolerancing's variables.
Only the design file lists its slabs from the sensor up (the order the stack is built).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from pydantic import BaseModel

from .files import design_from_dict
from .model import Design, DesignError

__all__ = [
    "drop_mask",
    "one_row",
    "replace",
    "scale_to_dpi",
    "square_holes",
    "stack_params",
    "structural_variants",
    "with_glass_index",
    "with_hole_shape",
    "with_layers",
    "with_sensitive_area",
    "with_stack",
    "with_unstated",
]

#: The grid (um) the lengths :func:`scale_to_dpi` creates are snapped to: 1 nm, the
#: database unit of the mask artwork (:mod:`opticalstamp.io.artwork`), so a scaled design's
#: masks are drawn exactly as designed.
MASK_GRID_UM = 0.001
_GRID_DECIMALS = 3  # MASK_GRID_UM as decimals of a micrometre
#: Sensor lengths that scale with the resolution (:func:`scale_to_dpi`).
_SENSOR_LENGTHS = (
    "pixel_pitch_um",
    "sensitive_width_um",
    "sensitive_height_um",
    "row_pitch_um",
    "row_b_offset_x_um",
    "row_b_offset_y_um",
)


# -- the primitive ------------------------------------------------------------------------
def replace(design: Design, changes: Mapping[str, object] | None = None, /, **fields) -> Design:
    """A validated copy of ``design`` with fields replaced, deep, by path.

    Parameters
    ----------
    design : Design
        The design to derive from; it is not changed (designs are immutable).
    changes : Mapping[str, object], optional
        ``{path: value}``. A path names a field through the design's tables and lists,
        dot-separated, list items by index (negative from the end):
        ``"sensor.sensitive_width_um"``, ``"slabs.2.mask_top.size_um"``,
        ``"reference_gap.medium"``. A mapping value is merged into the table already
        there (``{"sensor": {"lines": 1}}`` is ``{"sensor.lines": 1}``); any other value
        replaces it (``"slabs"`` takes a whole new list of slabs). ``None`` removes the
        entry, so the field takes its default (``"slabs.1.mask_top": None`` drops a
        mask). Models (``Slab``, ``Mask``, ...) are accepted as values.
    **fields
        Top-level fields (``name="variant"``), applied after ``changes``.

    Returns
    -------
    Design
        The new design, validated again as a whole.

    Raises
    ------
    DesignError
        A path that does not lead to a field, or a variant that breaks a rule of the
        design; the message names the field.
    """
    data = design.model_dump(mode="json", exclude_none=True)
    for path, value in {**(changes or {}), **fields}.items():
        if not isinstance(path, str) or not all(path.split(".")):
            raise DesignError(f"variant of {design.name}: {path!r} is not a field path")
        _set_path(data, path.split("."), value, path)
    return design_from_dict(data, f"variant of {design.name}")


def _plain(value: object) -> object:
    """Models as their JSON dumps, tuples as lists: the data ``design_from_dict`` reads."""
    if isinstance(value, BaseModel):
        return value.model_dump(mode="json", exclude_none=True)
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def _key(node: dict | list, part: str, path: str) -> str | int:
    """``part`` as a key of ``node``: a list index (in range) or a table key."""
    if isinstance(node, dict):
        return part
    if isinstance(node, list):
        try:
            i = int(part)
        except ValueError:
            i = None
        if i is None or not -len(node) <= i < len(node):
            raise DesignError(f"{path}: no item {part!r} in a list of {len(node)}")
        return i
    raise DesignError(f"{path}: {part!r} is inside a value, not a table or a list")


def _set_path(data: dict | list, parts: list[str], value: object, path: str) -> None:
    """Write ``value`` at ``parts`` inside ``data`` (see :func:`replace`)."""
    node = data
    for part in parts[:-1]:
        k = _key(node, part, path)
        if isinstance(node, dict) and node.get(k) is None:
            node[k] = {}
        node = node[k]
    k = _key(node, parts[-1], path)
    old = node.get(k) if isinstance(node, dict) else node[k]
    if isinstance(value, Mapping) and isinstance(old, dict | list):
        for sub, v in value.items():
            _set_path(old, str(sub).split("."), v, f"{path}.{sub}")
    elif value is not None:
        node[k] = _plain(value)
    elif isinstance(node, dict):
        node.pop(k, None)
    else:
        raise DesignError(f"{path}: a list item cannot be removed; replace the whole list")


# -- the stack: hole sizes, thicknesses, misregistration ------------------------------------
def _mask_slabs(design: Design) -> list[int]:
    """Indices of the slabs that carry a mask, from the sensor up."""
    return [i for i, sl in enumerate(design.slabs) if sl.mask_top is not None]


def _check_count(values: Sequence, n: int, what: str) -> None:
    if len(values) != n:
        raise DesignError(f"{what}: {len(values)} values given, the design has {n}")


def stack_params(design: Design) -> dict:
    """The stack's free numbers, as :func:`with_stack` takes them.

    Returns
    -------
    dict
        ``holes_um``: hole size of each mask (the smaller side; object side first);
        ``thicknesses_um``: each slab's thickness (object side first); ``offsets_um``: each
        mask's (dx, dy) misregistration (object side first); ``reference_gap_um``.
        ``with_stack(design, **stack_params(design))`` is ``design`` for square or
        circular holes.
    """
    masks = design.masks[::-1]
    return {
        "holes_um": [float(min(m.hole_width_um, m.hole_height_um)) for m in masks],
        "thicknesses_um": [float(sl.thickness_um) for sl in design.slabs[::-1]],
        "offsets_um": [(float(m.offset_x_um), float(m.offset_y_um)) for m in masks],
        "reference_gap_um": float(design.reference_gap.thickness_um),
    }


def with_stack(
    design: Design,
    holes_um: Sequence[float] | None = None,
    thicknesses_um: Sequence[float] | None = None,
    offsets_um: Sequence[tuple[float, float]] | None = None,
    reference_gap_um: float | None = None,
    name: str | None = None,
) -> Design:
    """The design with new hole sizes, slab thicknesses, misregistration and gap.

    Parameters
    ----------
    design : Design
    holes_um : sequence of float, optional
        One size (um) per mask, object side first: the side of a square hole or the
        diameter of a circular one. Rectangular holes are refused (they need a width and
        a height; make them square first with :func:`with_hole_shape`).
    thicknesses_um : sequence of float, optional
        One thickness (um) per slab, object side first (slab 1 carries layer 1).
    offsets_um : sequence of (float, float), optional
        Each mask's (dx, dy) misregistration (um), object side first.
    reference_gap_um : float, optional
        Thickness of the reference gap (um).
    name : str, optional
        The variant's name (default: the design's).

    Returns
    -------
    Design
        Validated again: a hole larger than the pitch raises ``DesignError``.
    """
    masks = _mask_slabs(design)[::-1]
    changes: dict[str, object] = {}
    if holes_um is not None:
        _check_count(holes_um, len(masks), "holes_um")
        for i, h in zip(masks, holes_um, strict=True):
            changes[f"slabs.{i}.mask_top"] = {
                "size_um": float(h),
                "width_um": None,
                "height_um": None,
            }
    if offsets_um is not None:
        _check_count(offsets_um, len(masks), "offsets_um")
        for i, (dx, dy) in zip(masks, offsets_um, strict=True):
            changes[f"slabs.{i}.mask_top.offset_x_um"] = float(dx)
            changes[f"slabs.{i}.mask_top.offset_y_um"] = float(dy)
    if thicknesses_um is not None:
        _check_count(thicknesses_um, len(design.slabs), "thicknesses_um")
        n = len(design.slabs)  # object side first; the design file lists the sensor's first
        for j, t in enumerate(thicknesses_um):
            changes[f"slabs.{n - 1 - j}.thickness_um"] = float(t)
    if reference_gap_um is not None:
        changes["reference_gap.thickness_um"] = float(reference_gap_um)
    if name:
        changes["name"] = name
    return replace(design, changes)


# -- resolution and structure ---------------------------------------------------------------
def scale_to_dpi(design: Design, dpi: float) -> Design:
    """The design's sensor and holes scaled so the merged pixel pitch is 25.4 mm / dpi,
    on the artwork's 1-nm grid.

    The merged pitch (the row pitch over the rows) is 25.4 mm / dpi rounded to the mask
    grid, ``MASK_GRID_UM`` (1 nm, the GDSII database unit), and the row pitch is that
    times the rows; pixel pitch, sensitive area and the row-B stagger scale by the same
    factor, each rounded to the grid (a stagger of half the row pitch stays exactly
    half, 42.333 um of 84.666 um at 600 dpi); hole sizes scale too, rounded to 0.1 um;
    slab thicknesses, the reference gap and the masks' misregistration are kept. The
    scaled design's masks are thus drawn exactly (``opticalstamp masks``), with no
    off-grid array. The price: the resolution is 25.4 mm over the rounded pitch, off
    ``dpi`` by at most 0.5 nm over the pitch, below 1e-4 relative for any pitch above
    5 um (600 dpi: 42.333 um, 600.0047 dpi, 7.9e-6). The variant is named
    ``"<name> at <dpi> dpi"``.
    """
    s = design.sensor
    pitch = round(25400.0 / dpi, _GRID_DECIMALS)
    if pitch <= 0:
        raise DesignError(f"dpi: {dpi:g} dpi is a pitch below the {MASK_GRID_UM} um grid")
    k = pitch * s.rows / s.row_pitch_um
    changes: dict[str, object] = {
        f"sensor.{key}": round(getattr(s, key) * k, _GRID_DECIMALS) for key in _SENSOR_LENGTHS
    }
    changes["sensor.row_pitch_um"] = round(pitch * s.rows, _GRID_DECIMALS)
    for i in _mask_slabs(design):
        m = design.slabs[i].mask_top
        for key in ("size_um", "width_um", "height_um"):
            if getattr(m, key) is not None:
                changes[f"slabs.{i}.mask_top.{key}"] = round(getattr(m, key) * k, 1)
    changes["name"] = f"{design.name} at {dpi:g} dpi"
    return replace(design, changes)


def drop_mask(design: Design, index: int) -> Design:
    """The design without the mask on top of ``slabs[index]`` (the slab stays)."""
    if not -len(design.slabs) <= index < len(design.slabs):
        raise DesignError(f"slabs.{index}: the design has {len(design.slabs)} slabs")
    if design.slabs[index].mask_top is None:
        raise DesignError(f"slabs.{index}.mask_top: this slab carries no mask")
    return replace(design, {f"slabs.{index}.mask_top": None})


def _layers_changes(design: Design, n: int) -> dict[str, object]:
    idx = _mask_slabs(design)
    if not 1 <= n <= len(idx):
        raise DesignError(f"layers: between 1 and {len(idx)} (got {n})")
    keep = {idx[0], idx[-1]} if n >= 2 else {idx[-1]}
    middle = [i for i in idx if i not in keep]
    keep |= set(middle[: max(0, n - len(keep))])
    return {f"slabs.{i}.mask_top": None for i in idx if i not in keep}


def with_layers(design: Design, n: int) -> Design:
    """The design with ``n`` of its masks (the slabs stay).

    One layer keeps the object-side mask; two or more keep the object-side and the
    sensor-side masks and then the middle ones from the sensor up (3 -> 2 gives the
    paper's Fig. 1c/d two-layer stack).
    """
    return replace(design, _layers_changes(design, n))


def _one_row_changes(design: Design) -> dict[str, object]:
    s = design.sensor
    if s.rows != 2:
        return {}
    return {
        "sensor.rows": 1,
        "sensor.row_pitch_um": s.row_pitch_um / 2,
        "sensor.row_b_offset_x_um": None,
        "sensor.row_b_offset_y_um": None,
    }


def one_row(design: Design) -> Design:
    """Every used pixel in one row at the merged pitch (no stagger, paper Fig. 1c).

    The resolution is the same; the row-B offsets return to their defaults (unused). A
    design that has one row already is returned validated again, unchanged.
    """
    return replace(design, _one_row_changes(design))


def structural_variants(
    design: Design, layers: Sequence[int] = (3,), stagger: Sequence[str] = ("yes",)
) -> dict[str, Design]:
    """Variants that differ in the number of mask layers and the stagger pattern.

    Parameters
    ----------
    design : Design
    layers : sequence of int
        How many masks to keep (:func:`with_layers`).
    stagger : sequence of {"yes", "no"}
        "yes" keeps the design's rows, "no" puts every pixel in one row (:func:`one_row`).

    Returns
    -------
    dict
        ``{name: design}``, named ``"<name>, <n> layers, staggered"`` or ``"... one row"``.
    """
    out = {}
    for n in layers:
        drop = _layers_changes(design, n)
        for st in stagger:
            if st not in ("yes", "no"):
                raise DesignError(f"stagger: yes or no (got {st!r})")
            name = f"{design.name}, {n} layers, {'staggered' if st == 'yes' else 'one row'}"
            rows = _one_row_changes(design) if st == "no" else {}
            out[name] = replace(design, drop | rows | {"name": name})
    return out


# -- the pixel and the paper's unstated parameters ----------------------------------------
def with_sensitive_area(design: Design, width_um: float, height_um: float) -> Design:
    """The design with a sensitive area of ``width_um`` x ``height_um`` (um).

    The pixel pitch grows to the larger side if needed. The variant is named
    ``"<name> (sensitive <w> x <h> um)"``.
    """
    pitch = max(design.sensor.pixel_pitch_um, width_um, height_um)
    return replace(
        design,
        {
            "sensor.pixel_pitch_um": pitch,
            "sensor.sensitive_width_um": width_um,
            "sensor.sensitive_height_um": height_um,
            "name": f"{design.name} (sensitive {width_um:g} x {height_um:g} um)",
        },
    )


def _hole_shape_changes(design: Design, shape: str) -> dict[str, object]:
    return {
        f"slabs.{i}.mask_top": {
            "shape": shape,
            "size_um": design.slabs[i].mask_top.size_um or design.slabs[i].mask_top.width_um,
            "width_um": None,
            "height_um": None,
        }
        for i in _mask_slabs(design)
    }


def with_hole_shape(design: Design, shape: str) -> Design:
    """Every hole made ``shape`` ("square" or "circle") of the same size.

    The size is a square's side or a circle's diameter; a rectangle's width is used.
    """
    return replace(design, _hole_shape_changes(design, shape))


def square_holes(design: Design) -> Design:
    """Circular holes replaced by their circumscribed squares (the same size).

    Square and rectangular holes are kept; a design without circular holes is returned
    as it is.
    """
    changes = {
        f"slabs.{i}.mask_top.shape": "square"
        for i in _mask_slabs(design)
        if design.slabs[i].mask_top.shape == "circle"
    }
    return replace(design, changes) if changes else design


def _glass_index_changes(design: Design, index: float | str) -> dict[str, object]:
    return {
        f"slabs.{i}.medium": index
        for i, sl in enumerate(design.slabs)
        if design.index(sl.medium) != 1.0
    }


def with_glass_index(design: Design, index: float | str) -> Design:
    """Every slab that is not air (index 1: air, vacuum) made of ``index``.

    ``index`` is a refractive index or a material of the catalogue.
    """
    return replace(design, _glass_index_changes(design, index))


def with_unstated(
    design: Design,
    *,
    hole_shape: str | None = None,
    sensitive_um: float | None = None,
    gap_medium: float | str | None = None,
    glass_index: float | str | None = None,
) -> Design:
    """The design with values for the paper's unstated parameters (DESIGN.md §2).

    The variants of the paper study (:mod:`opticalstamp.analysis.paper_study`); the name
    is kept. ``None`` leaves a parameter as it is.

    Parameters
    ----------
    hole_shape : {"square", "circle"}, optional
        Every hole's shape, same size (:func:`with_hole_shape`).
    sensitive_um : float, optional
        Side of the pixel's square sensitive area (um), at most the pixel pitch.
    gap_medium : float or str, optional
        Medium of the reference gap.
    glass_index : float or str, optional
        Medium of every slab that is not air (:func:`with_glass_index`).
    """
    changes: dict[str, object] = {}
    if glass_index is not None:
        changes |= _glass_index_changes(design, glass_index)
    if hole_shape is not None:
        changes |= _hole_shape_changes(design, hole_shape)
    if gap_medium is not None:
        changes["reference_gap.medium"] = gap_medium
    if sensitive_um is not None:
        changes["sensor.sensitive_width_um"] = sensitive_um
        changes["sensor.sensitive_height_um"] = sensitive_um
    return replace(design, changes)
