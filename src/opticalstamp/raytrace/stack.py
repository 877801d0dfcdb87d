"""Compile a :class:`~opticalstamp.design.Design` into flat arrays for the ray kernel.

A *path* is the stack seen in one direction of travel: a list of homogeneous slabs
crossed in order, each with its thickness, refractive index and the mask (if any) on
the plane where the ray leaves it. Reverse tracing (paper Fig. 4) goes from the sensor
(z = 0) up to the reference plane; forward tracing (paper Fig. 10) from an object point
Z above the reference plane down to the sensor.

Hole lattice (paper Fig. 3): row A holes at (k p, 0), row B at (b_x + k p, b_y), for
k = k_lo ... k_hi, where p is the pitch within a row and the used pixel k = 0 of row A
sits at the origin in the middle of the array. Every mask uses this lattice shifted by
its own misregistration (offset_x_um, offset_y_um).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from ..design import Design
from ..design.resolution import output_pitch_um

#: margin (um) beyond the array ends and either side of the rows where the plates end;
#: a ray that leaves this region inside the stack is counted as escaped.
PLATE_MARGIN_UM = 5000.0

SHAPE_CODE = MappingProxyType({"square": 0, "rectangle": 0, "circle": 1})


@dataclass(frozen=True)
class Lattice:
    """The staggered lattice of used pixels (and of holes)."""

    pitch: float
    k_lo: int
    k_hi: int
    row_x: np.ndarray  # (2,) x of k = 0 in each row
    row_y: np.ndarray  # (2,) y of each row
    n_rows: int

    def as_array(self) -> np.ndarray:
        """[pitch, k_lo, k_hi, n_rows, x_A, y_A, x_B, y_B] for the kernel."""
        return np.array(
            [
                self.pitch,
                self.k_lo,
                self.k_hi,
                self.n_rows,
                self.row_x[0],
                self.row_y[0],
                self.row_x[1],
                self.row_y[1],
            ]
        )

    def centers(self, row: int | np.ndarray, k: int | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x, y of lattice site (row, k)."""
        row = np.asarray(row)
        return self.row_x[row] + np.asarray(k) * self.pitch, self.row_y[row]

    def all_sites(self) -> tuple[np.ndarray, np.ndarray]:
        """(row, k) of every site, row-major: shape (n_rows * n_per_row,) each."""
        ks = np.arange(self.k_lo, self.k_hi + 1)
        rows = np.repeat(np.arange(self.n_rows), ks.size)
        return rows, np.tile(ks, self.n_rows)


@dataclass(frozen=True)
class Path:
    """The stack along one direction of travel, as kernel arrays.

    Attributes
    ----------
    slabs : (n_slabs, 3) float64
        thickness (um), refractive index, mask id on the exit plane (-1: none).
    index_out : float
        Index of the medium after the last exit plane.
    masks : (n_masks, 5) float64
        shape code (0 rectangle, 1 circle), half width (or radius), half height,
        x and y misregistration, for mask ids 0.. (ordered from the sensor upward).
    lattice : Lattice
    limits : (2,) float64
        |x| and |y| beyond which a ray has left the plates.
    z_exit : (n_slabs,) float64
        z (um, from the sensor) of each slab's exit plane.
    mask_names : tuple of str
    """

    slabs: np.ndarray
    index_out: float
    masks: np.ndarray
    lattice: Lattice
    limits: np.ndarray
    z_exit: np.ndarray
    mask_names: tuple[str, ...]

    @property
    def n_masks(self) -> int:
        return self.masks.shape[0]

    @property
    def first_mask_slab(self) -> int:
        """Index of the slab whose exit plane carries the first mask met."""
        return int(np.flatnonzero(self.slabs[:, 2] >= 0)[0])

    def hole_area(self, mask_id: int) -> float:
        shape, hw, hh = self.masks[mask_id, :3]
        return float(np.pi * hw * hw if shape == 1 else 4 * hw * hh)


def lattice_of(design: Design) -> Lattice:
    s = design.sensor
    n = s.n_per_row
    k_lo = -(n // 2)
    bx, by = (s.row_b_offset_x_um, s.row_b_offset_y_um) if s.rows == 2 else (0.0, 0.0)
    return Lattice(
        pitch=s.row_pitch_um,
        k_lo=k_lo,
        k_hi=k_lo + n - 1,
        row_x=np.array([0.0, bx]),
        row_y=np.array([0.0, by]),
        n_rows=s.rows,
    )


def _mask_table(design: Design) -> tuple[np.ndarray, tuple[str, ...]]:
    rows, names = [], []
    for i, m in enumerate(design.masks):
        if m.shape == "circle":
            hw = hh = m.size_um / 2
        else:
            hw, hh = m.hole_width_um / 2, m.hole_height_um / 2
        rows.append([SHAPE_CODE[m.shape], hw, hh, m.offset_x_um, m.offset_y_um])
        names.append(m.name or f"mask {i}")
    return np.array(rows, dtype=np.float64), tuple(names)


def _limits(lat: Lattice) -> np.ndarray:
    half_len = max(abs(lat.k_lo), abs(lat.k_hi)) * lat.pitch + abs(lat.row_x).max()
    return np.array([half_len + PLATE_MARGIN_UM, abs(lat.row_y).max() + PLATE_MARGIN_UM])


def reverse_path(design: Design) -> Path:
    """Sensor (z = 0) up to the reference plane; rays end in the object medium."""
    masks, names = _mask_table(design)
    slabs, mid, z, z_exit = [], 0, 0.0, []
    for sl in design.slabs:
        m = -1
        if sl.mask_top is not None:
            m, mid = mid, mid + 1
        slabs.append([sl.thickness_um, design.index(sl.medium), m])
        z += sl.thickness_um
        z_exit.append(z)
    gap = design.reference_gap
    if gap.thickness_um > 0:
        slabs.append([gap.thickness_um, design.index(gap.medium), -1])
        z_exit.append(z + gap.thickness_um)
    lat = lattice_of(design)
    return Path(
        np.array(slabs, dtype=np.float64),
        design.index(design.object_medium),
        masks,
        lat,
        _limits(lat),
        np.array(z_exit),
        names,
    )


def forward_path(design: Design, z_um: float) -> Path:
    """From an object plane ``z_um`` above the reference plane down to the sensor."""
    if not np.isfinite(z_um) or z_um < 0:
        raise ValueError(f"object distance must be >= 0 (got {z_um} um)")
    rev = reverse_path(design)
    # Slabs crossed downward: object medium (Z), then the reverse slabs in reverse order.
    # A mask on the exit (top) plane of reverse slab i is met on entering slab i going
    # down, i.e. on the exit plane of the slab above it.
    down = [[z_um, design.index(design.object_medium), -1]]
    z_exit = [rev.z_exit[-1]]
    for i in range(rev.slabs.shape[0] - 1, -1, -1):
        d, n, _ = rev.slabs[i]
        down[-1][2] = rev.slabs[i, 2]
        down.append([d, n, -1])
        z_exit.append(rev.z_exit[i] - d)
    # A zero-thickness first slab (Z = 0) is kept: it may carry the top mask.
    slabs = np.array(down, dtype=np.float64)
    return Path(
        slabs, slabs[-1, 1], rev.masks, rev.lattice, rev.limits, np.array(z_exit), rev.mask_names
    )


def pixel_center(design: Design, row: int = 0, k: int = 0) -> tuple[float, float]:
    """Centre (x, y) of used pixel ``k`` of ``row`` (0 = A, 1 = B)."""
    x, y = lattice_of(design).centers(row, k)
    return float(x), float(y)


def output_pitch(design: Design) -> float:
    """Pitch (um) of the merged output line and of its lines: the row pitch over the
    number of staggered rows (84.6 um for the paper's prototype, 300 dpi;
    :func:`~opticalstamp.design.resolution.output_pitch_um`)."""
    return output_pitch_um(design)
