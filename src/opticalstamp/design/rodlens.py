"""A gradient-index rod-lens array (SELFOC-type) contact image sensor: the second kind of
design (``kind = "rod-lens-array"``), the scanner the optical stamp is meant to replace.

Geometry (z up from the sensor, x along the array): the sensor line lies at y = 0; one
row of touching rods of radius R has its axes at (2Rk, 0); two rows in hexagonal close
packing at (2Rk, +sqrt(3) R / 2) and (2Rk + R, -sqrt(3) R / 2). Each rod has a graded
core of radius r0 <= R (outside it the skin and the black resin absorb) and flat end
faces; its index profile is

    n(r)^2 = n0^2 [1 - (g r)^2 + h4 (g r)^4 + h6 (g r)^6 + h8 (g r)^8].

Imaging condition (erect 1:1 image, each rod a relay; NSG's rules, docs/rodlens.md):
g = NA / (n0 r0), pitch P = 2 pi / g, view radius X0 = 2 R m, rod length
Z0 = (P / pi) acos(-r0 / X0), working distance L0 = -tan(pi Z0 / P) / (n0 g) on both sides,
conjugate length TC = Z0 + 2 L0. A design may give Z0 (instead of the overlap m) and L0.

An optional cover (document) glass lies on the object side with its top face at the
nominal object plane: the document reference of a rod-lens scanner. Lengths in um.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from ..units import pitch_of_dpi
from .electronics import Electronics, electronics_field
from .materials import WAVELENGTH_RANGE_UM, refractive_index
from .model import INDEX_RANGE, FrozenModel, Medium, Number, PositiveUm, Rows, content_hash

KIND = "rod-lens-array"

#: A 300-dpi pixel (the paper's comparison: 84.67 um square, fill factor 1).
DEFAULT_PIXEL_UM = pitch_of_dpi(300)
#: Radii at which the index profile is checked (n(r)^2 >= 1 inside the core).
_PROFILE_SAMPLES = 257


class RodSensor(FrozenModel):
    """The line sensor behind the array: one row of square-ish pixels at ``pixel_pitch_um``."""

    pixel_pitch_um: Annotated[Number, Field(ge=1.0, le=10_000.0)] = DEFAULT_PIXEL_UM
    sensitive_width_um: PositiveUm | None = None
    sensitive_height_um: PositiveUm | None = None

    @property
    def width_um(self) -> float:
        return self.sensitive_width_um or self.pixel_pitch_um

    @property
    def height_um(self) -> float:
        return self.sensitive_height_um or self.pixel_pitch_um

    @model_validator(mode="after")
    def _fits(self) -> RodSensor:
        if self.width_um > self.pixel_pitch_um + 1e-9:
            raise ValueError(
                f"sensitive_width_um ({self.width_um}) must not exceed pixel_pitch_um "
                f"({self.pixel_pitch_um})"
            )
        return self


class CoverGlass(FrozenModel):
    """The document glass between the rods and the document (its top face is the reference)."""

    medium: Medium = 1.52
    thickness_um: Annotated[Number, Field(gt=0, le=20_000.0)]


class RodArray(FrozenModel):
    """The rods: rows, radius, graded core, profile and the overlap (or explicit lengths)."""

    rows: Rows = 1  # 1, or 2 in hexagonal close packing
    rod_radius_um: Annotated[Number, Field(gt=0, le=5_000.0)]
    core_radius_um: Annotated[Number, Field(gt=0, le=5_000.0)]
    n0: Annotated[Number, Field(gt=INDEX_RANGE[0], le=INDEX_RANGE[1])]
    view_angle_deg: Annotated[Number, Field(gt=0, lt=90)] | None = None
    numerical_aperture: Annotated[Number, Field(gt=0, lt=1)] | None = None
    overlap: Annotated[Number, Field(gt=0, le=20)] | None = None
    h4: Annotated[Number, Field(ge=-1e4, le=1e4)] = 0.0
    h6: Annotated[Number, Field(ge=-1e4, le=1e4)] = 0.0
    h8: Annotated[Number, Field(ge=-1e4, le=1e4)] = 0.0
    rod_length_um: Annotated[Number, Field(gt=0, le=100_000.0)] | None = None
    working_distance_um: Annotated[Number, Field(gt=0, le=100_000.0)] | None = None

    @model_validator(mode="after")
    def _rules(self) -> RodArray:
        if (self.view_angle_deg is None) == (self.numerical_aperture is None):
            raise ValueError("give exactly one of view_angle_deg and numerical_aperture")
        if self.core_radius_um > self.rod_radius_um + 1e-9:
            raise ValueError(
                f"core_radius_um ({self.core_radius_um}) must not exceed rod_radius_um "
                f"({self.rod_radius_um})"
            )
        if self.na >= self.n0:
            raise ValueError(
                f"numerical aperture {self.na:.4g} must be below n0 = {self.n0:g} "
                "(n0 g r0 >= n0 leaves no index at the core's edge)"
            )
        if (self.overlap is None) == (self.rod_length_um is None):
            raise ValueError("give exactly one of overlap (m) and rod_length_um (Z0)")
        m_min = self.core_radius_um / (2 * self.rod_radius_um)
        if self.overlap is not None and self.view_radius_um <= self.core_radius_um:
            raise ValueError(
                f"overlap: m = {self.overlap:g} gives a view radius X0 = 2 R m = "
                f"{self.view_radius_um:g} um not larger than the core radius r0 = "
                f"{self.core_radius_um:g} um; the imaging condition acos(-r0 / X0) has no "
                f"solution (need m > r0 / 2R = {m_min:.4g})"
            )
        if self.working_distance_um is None and self.working_distance_paraxial_um <= 0:
            raise ValueError(
                f"rod_length_um: Z0 = {self.rod_length_um:g} um gives no real erect image "
                f"(working distance -tan(pi Z0 / P) / (n0 g) <= 0 with P = "
                f"{self.pitch_length_um:.1f} um); use Z0 between P/2 and P"
            )
        r = np.linspace(0.0, self.core_radius_um, _PROFILE_SAMPLES)
        n2 = self.index_squared(r)
        if n2.min() < 1.0:
            bad = float(r[np.argmax(n2 < 1.0)])
            raise ValueError(
                f"index profile: n(r)^2 falls below 1 at r = {bad:.1f} um inside the core "
                "(check h4, h6, h8 and the numerical aperture)"
            )
        return self

    # -- derived by the imaging condition ---------------------------------------------
    @property
    def na(self) -> float:
        """Numerical aperture NA = sin(theta) = n0 g r0."""
        if self.numerical_aperture is not None:
            return self.numerical_aperture
        return math.sin(math.radians(self.view_angle_deg))

    @property
    def g_per_um(self) -> float:
        """Gradient constant g = NA / (n0 r0) (1/um)."""
        return self.na / (self.n0 * self.core_radius_um)

    @property
    def pitch_length_um(self) -> float:
        """One-pitch length P = 2 pi / g."""
        return 2 * math.pi / self.g_per_um

    @property
    def view_radius_um(self) -> float:
        """X0 = 2 R m (given), or -r0 / cos(pi Z0 / P) for a given Z0."""
        if self.overlap is not None:
            return 2 * self.rod_radius_um * self.overlap
        c = math.cos(math.pi * self.rod_length_um / self.pitch_length_um)
        return -self.core_radius_um / c if c < 0 else math.inf

    @property
    def overlap_degree(self) -> float:
        """m = X0 / 2R."""
        return self.view_radius_um / (2 * self.rod_radius_um)

    @property
    def length_um(self) -> float:
        """Rod length Z0 = (P / pi) acos(-r0 / X0), or as given."""
        if self.rod_length_um is not None:
            return self.rod_length_um
        return (
            self.pitch_length_um / math.pi * math.acos(-self.core_radius_um / self.view_radius_um)
        )

    @property
    def working_distance_paraxial_um(self) -> float:
        """L0 = -tan(pi Z0 / P) / (n0 g) (imaging condition)."""
        return -math.tan(math.pi * self.length_um / self.pitch_length_um) / (
            self.n0 * self.g_per_um
        )

    @property
    def working_um(self) -> float:
        """Working distance used on both sides: as given, else the imaging condition's."""
        return self.working_distance_um or self.working_distance_paraxial_um

    @property
    def conjugate_um(self) -> float:
        """Total conjugate length TC = Z0 + 2 L0."""
        return self.length_um + 2 * self.working_um

    def index_squared(self, r_um) -> np.ndarray:
        gr2 = (self.g_per_um * np.asarray(r_um, dtype=np.float64)) ** 2
        poly = 1 - gr2 + self.h4 * gr2**2 + self.h6 * gr2**3 + self.h8 * gr2**4
        return self.n0**2 * poly

    def axes(self) -> list[tuple[float, float]]:
        """(x offset, y) of each row's rod axes (rod k of a row at x offset + 2 R k)."""
        r = self.rod_radius_um
        if self.rows == 1:
            return [(0.0, 0.0)]
        h = math.sqrt(3) * r / 2
        return [(0.0, h), (r, -h)]


class RodLensDesign(FrozenModel):
    """A complete rod-lens-array scanner: rods, sensor, optional cover glass."""

    kind: Literal["rod-lens-array"] = KIND
    name: str = "unnamed"
    description: str = ""
    wavelength_um: Annotated[Number, Field(ge=WAVELENGTH_RANGE_UM[0], le=WAVELENGTH_RANGE_UM[1])]
    array: RodArray
    sensor: RodSensor = RodSensor()
    cover_glass: CoverGlass | None = None
    electronics: Electronics = electronics_field()  # illumination, exposure, sensor electronics

    @model_validator(mode="after")
    def _glass_fits(self) -> RodLensDesign:
        if self.cover_glass is not None and self.air_gap_um < 0:
            g = self.cover_glass
            raise ValueError(
                f"cover_glass: {g.thickness_um:g} um of index {self.glass_index:.4g} needs an "
                f"optical thickness t / n = {g.thickness_um / self.glass_index:.1f} um, more "
                f"than the working distance L0 = {self.array.working_um:.1f} um"
            )
        return self

    @property
    def glass_index(self) -> float:
        g = self.cover_glass
        return 1.0 if g is None else refractive_index(g.medium, self.wavelength_um)

    @property
    def air_gap_um(self) -> float:
        """Air between the rods' top faces and the cover glass (the object in focus on it)."""
        g = self.cover_glass
        if g is None:
            return self.array.working_um
        return self.array.working_um - g.thickness_um / self.glass_index

    @property
    def reference_plane_um(self) -> float:
        """z of the document reference: the cover glass's top, else the nominal object plane."""
        a = self.array
        glass = 0.0 if self.cover_glass is None else self.cover_glass.thickness_um
        return a.working_um + a.length_um + self.air_gap_um + glass

    @property
    def output_pitch_um(self) -> float:
        return self.sensor.pixel_pitch_um

    def fingerprint(self) -> str:
        return content_hash(self)
