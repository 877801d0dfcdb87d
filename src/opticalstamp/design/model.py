"""Scanner design: sensor + stack of slabs and masks + reference gap + wavelength.

Designs are frozen, validated pydantic models, immutable all the way down (the slabs are a
tuple); derive one from another with :mod:`.variants`. Lengths are in micrometres (keys name
their unit). The stack is listed from the sensor (z = 0) upward; each slab may carry
an absorbing aperture-array mask on its top face. The hole lattice of every mask is the
lattice of used pixels (one hole above each used pixel, paper section 3), shifted by the
mask's optional misregistration.

Invalid input raises :class:`DesignError` whose message names every offending field and
the rule it breaks; nothing is traced for an invalid design.
"""

from __future__ import annotations

import hashlib
import json
import math
from typing import Annotated, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    model_validator,
)

from ..validate import InputError
from .electronics import Electronics, electronics_field
from .materials import CATALOGUE, WAVELENGTH_RANGE_UM, refractive_index

A4_WIDTH_UM = 210_000.0

#: Physically sensible ranges of a design's numbers (um unless named), stated in
#: docs/design-files.md. Wider values are refused at validation: they are typing errors,
#: not designs (a 1e9 um gap would make a scan allocate petabytes).
MAX_LENGTH_UM = 100_000.0  # slab, gap, pitch: 100 mm
#: The shortest slab, hole side or diameter, sensitive area side and non-zero reference
#: gap: thinner than a mask's chrome film, far below every wavelength the model takes.
#: Shorter lengths are no design the ray model can honour (a slab of 1e-300 um, a hole
#: that passes no light) and are refused at validation.
MIN_LENGTH_UM = 0.1
MIN_PITCH_UM = 1.0  # pixel pitch (25,400 dpi)
MAX_OFFSET_UM = 10_000.0  # misregistration and row offsets: 10 mm
INDEX_RANGE = (1.0, 4.0)
MAX_LINES = 64
MAX_PIXELS_PER_ROW = 1_000_000
MAX_DESIGN_FILE_BYTES = 1 << 20


def _number(value: object) -> object:
    """Accept int or float, refuse booleans and strings (TOML's `true`, `"42.0"`); -0.0 is
    0.0 (no "-0 um" in a table)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"expected a number (got {type(value).__name__} {value!r})")
    return value + 0.0 if isinstance(value, float) else value


def _at_least_min_length(value: float) -> float:
    if value < MIN_LENGTH_UM:
        raise ValueError(
            f"must be at least {MIN_LENGTH_UM:g} um (got {value!r}): shorter lengths are "
            "far below the wavelength, where the ray model does not hold"
        )
    return value


def _gap_length(value: float) -> float:
    if 0 < value < MIN_LENGTH_UM or value < 0:
        raise ValueError(
            f"must be 0 (the document on the top mask) or at least {MIN_LENGTH_UM:g} um "
            f"(got {value!r})"
        )
    return value


def _integer(value: object) -> object:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"expected an integer (got {type(value).__name__} {value!r})")
    return value


Rows = Annotated[Literal[1, 2], BeforeValidator(_integer)]
Number = Annotated[float, BeforeValidator(_number), Field(allow_inf_nan=False)]
#: A length of the stack (slab, hole, sensitive area, pitch): MIN_LENGTH_UM to MAX_LENGTH_UM.
PositiveUm = Annotated[Number, AfterValidator(_at_least_min_length), Field(le=MAX_LENGTH_UM)]
GapUm = Annotated[Number, AfterValidator(_gap_length), Field(le=MAX_LENGTH_UM)]
OffsetUm = Annotated[Number, Field(ge=-MAX_OFFSET_UM, le=MAX_OFFSET_UM)]


class DesignError(InputError):
    """A design that cannot be used, with a message naming the field and the rule."""


class FrozenModel(BaseModel):
    """Base of every design model: immutable, unknown keys refused."""

    model_config = ConfigDict(frozen=True, extra="forbid")


def _check_medium(value: object) -> float | str:
    """A refractive index in INDEX_RANGE or the name of a catalogued material."""
    if isinstance(value, str):
        names = {k.lower() for k in CATALOGUE}
        if value.lower() not in names:
            raise ValueError(
                f"unknown medium {value!r}; use a refractive index or one of "
                f"{', '.join(sorted(CATALOGUE))}"
            )
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(
            f"expected a refractive index or a material name (got {type(value).__name__})"
        )
    lo, hi = INDEX_RANGE
    if not math.isfinite(value) or not lo <= value <= hi:
        raise ValueError(f"refractive index must be a finite number in [{lo:g}, {hi:g}]")
    return float(value)


Medium = Annotated[float | str, BeforeValidator(_check_medium)]


class Mask(FrozenModel):
    """An absorbing mask with one hole above each used pixel."""

    name: str | None = None
    shape: Literal["square", "rectangle", "circle"] = "square"
    size_um: PositiveUm | None = Field(None, description="side (square) or diameter (circle)")
    width_um: PositiveUm | None = Field(None, description="x size of a rectangular hole")
    height_um: PositiveUm | None = Field(None, description="y size of a rectangular hole")
    offset_x_um: OffsetUm = 0.0
    offset_y_um: OffsetUm = 0.0

    @model_validator(mode="after")
    def _sizes(self) -> Mask:
        if self.shape == "rectangle":
            if self.width_um is None or self.height_um is None:
                raise ValueError("a rectangular hole needs width_um and height_um")
            if self.size_um is not None:
                raise ValueError("a rectangular hole takes width_um and height_um, not size_um")
        else:
            if self.size_um is None:
                raise ValueError(f"a {self.shape} hole needs size_um")
            if self.width_um is not None or self.height_um is not None:
                raise ValueError(f"a {self.shape} hole takes size_um, not width_um/height_um")
        return self

    @property
    def hole_width_um(self) -> float:
        return self.width_um if self.shape == "rectangle" else self.size_um

    @property
    def hole_height_um(self) -> float:
        return self.height_um if self.shape == "rectangle" else self.size_um

    @property
    def hole_area_um2(self) -> float:
        if self.shape == "circle":
            return math.pi * self.size_um**2 / 4
        return self.hole_width_um * self.hole_height_um


class Slab(FrozenModel):
    """A homogeneous layer of the stack, optionally masked on its top face."""

    medium: Medium
    thickness_um: PositiveUm
    mask_top: Mask | None = None


class Gap(FrozenModel):
    """The reference gap between the top mask and the reference plane (Z = 0)."""

    medium: Medium = "air"
    thickness_um: GapUm = 1000.0


class Sensor(FrozenModel):
    """Line sensor and the staggered lattice of used pixels (paper Fig. 3).

    ``acceptance_half_angle_deg`` is the pixel's angular response, a hard cut-off on the
    angle of incidence in the medium above the sensor (90: every ray counts, the paper's
    unstated default).
    """

    pixel_pitch_um: Annotated[Number, Field(ge=MIN_PITCH_UM, le=MAX_LENGTH_UM)] = 42.3
    sensitive_width_um: PositiveUm = 42.3
    sensitive_height_um: PositiveUm = 42.3
    lines: Annotated[int, BeforeValidator(_integer), Field(ge=1, le=MAX_LINES)] = 3
    rows: Rows = 2
    row_pitch_um: PositiveUm = 169.2
    row_b_offset_x_um: OffsetUm = 84.6
    row_b_offset_y_um: OffsetUm = 84.6
    pixels_per_row: (
        Annotated[int, BeforeValidator(_integer), Field(ge=1, le=MAX_PIXELS_PER_ROW)] | None
    ) = None
    acceptance_half_angle_deg: Annotated[Number, Field(gt=0, le=90)] = 90.0

    @model_validator(mode="after")
    def _rules(self) -> Sensor:
        if self.sensitive_width_um > self.pixel_pitch_um + 1e-9:
            raise ValueError(
                f"sensitive_width_um ({self.sensitive_width_um}) must not exceed "
                f"pixel_pitch_um ({self.pixel_pitch_um})"
            )
        if self.sensitive_height_um > self.pixel_pitch_um + 1e-9:
            raise ValueError(
                f"sensitive_height_um ({self.sensitive_height_um}) must not exceed "
                f"pixel_pitch_um ({self.pixel_pitch_um})"
            )
        if self.row_pitch_um < self.pixel_pitch_um - 1e-9:
            raise ValueError(
                f"row_pitch_um ({self.row_pitch_um}) must be at least pixel_pitch_um "
                f"({self.pixel_pitch_um})"
            )
        return self

    @property
    def n_per_row(self) -> int:
        """Used pixels per row (default: one A4 line, 210 mm)."""
        if self.pixels_per_row is not None:
            return self.pixels_per_row
        return max(1, round(A4_WIDTH_UM / self.row_pitch_um))


class Design(FrozenModel):
    """A complete scanner design (paper Figs. 2-4)."""

    name: str = "unnamed"
    description: str = ""
    wavelength_um: Annotated[
        Number, Field(ge=WAVELENGTH_RANGE_UM[0], le=WAVELENGTH_RANGE_UM[1])
    ] = 0.55
    sensor: Sensor = Sensor()
    slabs: Annotated[tuple[Slab, ...], Field(min_length=1)]
    reference_gap: Gap = Gap()
    object_medium: Medium = "air"
    electronics: Electronics = electronics_field()  # illumination, exposure, sensor electronics

    @model_validator(mode="after")
    def _holes(self) -> Design:
        s = self.sensor
        if self.reference_plane_um > MAX_LENGTH_UM:
            raise ValueError(
                f"slabs + reference_gap: the stack is {self.reference_plane_um:g} um thick, "
                f"more than {MAX_LENGTH_UM:g} um"
            )
        masks = [(i, sl.mask_top) for i, sl in enumerate(self.slabs) if sl.mask_top is not None]
        if not masks:
            raise ValueError("slabs: at least one slab needs a mask_top")
        for i, m in masks:
            where = f"slabs.{i}.mask_top"
            w, h = m.hole_width_um, m.hole_height_um
            if w >= s.row_pitch_um:
                raise ValueError(
                    f"{where}: hole width {w} um must be smaller than the hole "
                    f"pitch sensor.row_pitch_um = {s.row_pitch_um} um (holes overlap)"
                )
            if s.rows == 2:
                dx = s.row_b_offset_x_um % s.row_pitch_um
                dx = min(dx, s.row_pitch_um - dx)
                dy = abs(s.row_b_offset_y_um)
                if m.shape == "circle":
                    overlap = math.hypot(dx, dy) <= w
                else:
                    overlap = dx < w and dy < h
                if overlap:
                    raise ValueError(
                        f"{where}: holes of {w} x {h} um overlap between the two "
                        f"staggered rows (offset {dx:.1f}, {dy:.1f} um)"
                    )
        return self

    # -- derived quantities -------------------------------------------------------------
    def index(self, medium: float | str) -> float:
        return refractive_index(medium, self.wavelength_um)

    @property
    def mask_heights_um(self) -> list[float]:
        """z of each mask, from the sensor upward."""
        z, out = 0.0, []
        for sl in self.slabs:
            z += sl.thickness_um
            if sl.mask_top is not None:
                out.append(z)
        return out

    @property
    def reference_plane_um(self) -> float:
        """z of the reference plane (Z = 0)."""
        return sum(sl.thickness_um for sl in self.slabs) + self.reference_gap.thickness_um

    @property
    def masks(self) -> list[Mask]:
        return [sl.mask_top for sl in self.slabs if sl.mask_top is not None]

    def fingerprint(self) -> str:
        """Short hash of the design's content (for result provenance)."""
        return content_hash(self)


def content_hash(model: BaseModel) -> str:
    """Short SHA-256 of a model's JSON content (a design's fingerprint)."""
    blob = json.dumps(model.model_dump(mode="json"), sort_keys=True).encode()
    return hashlib.sha256(blob).hexdigest()[:12]
