"""Float-height maps of a document (mm above the reference plane), arrays [y, x].

Built-in shapes (``SHAPE:arg:arg``, lengths in mm):

- ``flat:Z`` constant height;
- ``tilt:Z0:Z1`` linear from Z0 at the top edge (y = 0) to Z1 at the bottom;
- ``gutter:DEPTH:RADIUS`` a book's gutter: a cylinder of radius RADIUS along y at the
  page's centre line, the page rising to DEPTH there (height = DEPTH - sagitta of the
  distance from the centre, floored at 0);
- ``crumple:AMPLITUDE:SCALE`` a smooth random crumple (Gaussian-filtered white noise of
  correlation length SCALE, scaled to peak AMPLITUDE, shifted to start at 0), seeded.

Files: ``.npy`` (float, mm) or a float TIFF (mm). A map must have the document's aspect
ratio (within 2 %); it is resampled onto the scan's sample positions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

from ..validate import InputError

#: Heights the scan model covers (mm).
Z_RANGE_MM = (0.0, 10.0)
SHAPES = ("flat", "tilt", "gutter", "crumple")
#: Largest gutter radius (mm).
MAX_RADIUS_MM = 1e6
#: Largest crumple correlation length (mm): the filter's cost grows with it, and a crumple
#: longer than a metre is a plane on any page.
MAX_SCALE_MM = 1000.0
#: Most samples a height-map file may hold (a page at 0.05 mm holds about 3.5e7).
MAX_MAP_SAMPLES = 100_000_000


class HeightMapError(InputError):
    """A height map (file or shape) that cannot be used; the message names it and the rule."""


def _args(spec: str, n: int, defaults: tuple[float, ...]) -> tuple[float, ...]:
    parts = spec.split(":")[1:]
    if len(parts) > n:
        raise HeightMapError(f"height map {spec!r}: at most {n} numbers after the shape")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise HeightMapError(f"height map {spec!r}: arguments must be numbers") from None
    return tuple(vals) + defaults[len(vals) :]


def _height(spec: str, name: str, v: float) -> float:
    """``v`` if it lies in the modelled range :data:`Z_RANGE_MM` (NaN does not)."""
    lo, hi = Z_RANGE_MM
    if not lo <= v <= hi:
        raise HeightMapError(
            f"height map {spec!r}: {name} = {v:g} mm lies outside the modelled range "
            f"[{lo:g}, {hi:g}] mm"
        )
    return v


def _length(spec: str, name: str, v: float, hi: float) -> float:
    """``v`` if it lies in (0, hi] mm (NaN and infinity do not)."""
    if not 0 < v <= hi:
        raise HeightMapError(f"height map {spec!r}: {name} must lie in (0, {hi:g}] mm (got {v:g})")
    return v


def shape_map(
    spec: str, height_mm: float, width_mm: float, seed: int = 0, step_mm: float = 0.5
) -> np.ndarray:
    """A built-in height map on a grid of ``step_mm`` covering the page."""
    kind = spec.split(":")[0]
    ny = max(2, int(np.ceil(height_mm / step_mm)) + 1)
    nx = max(2, int(np.ceil(width_mm / step_mm)) + 1)
    y = np.linspace(0, height_mm, ny)[:, None]
    x = np.linspace(0, width_mm, nx)[None, :]
    if kind == "flat":
        (z,) = _args(spec, 1, (1.0,))
        m = np.full((ny, nx), _height(spec, "Z", z))
    elif kind == "tilt":
        z0, z1 = _args(spec, 2, (0.0, 3.0))
        z0, z1 = _height(spec, "Z0", z0), _height(spec, "Z1", z1)
        m = np.broadcast_to(z0 + (z1 - z0) * y / height_mm, (ny, nx)).copy()
    elif kind == "gutter":
        depth, radius = _args(spec, 2, (3.0, 40.0))
        depth = _height(spec, "DEPTH", depth)
        radius = _length(spec, "RADIUS", radius, MAX_RADIUS_MM)
        d = np.minimum(np.abs(x - width_mm / 2), radius)
        sag = d**2 / (radius + np.sqrt(radius**2 - d**2))  # r - sqrt(r^2 - d^2), no cancelling
        m = np.broadcast_to(np.maximum(depth - sag, 0.0), (ny, nx)).copy()
    elif kind == "crumple":
        amp, scale = _args(spec, 2, (1.5, 15.0))
        amp = _height(spec, "AMPLITUDE", amp)
        scale = _length(spec, "SCALE", scale, MAX_SCALE_MM)
        rng = np.random.default_rng(seed)
        f = ndimage.gaussian_filter(rng.standard_normal((ny, nx)), scale / step_mm, mode="wrap")
        f -= f.min()
        m = amp * f / f.max() if f.max() > 0 else np.zeros((ny, nx))
    else:
        raise HeightMapError(
            f"height map {spec!r}: unknown shape (use {', '.join(SHAPES)}, or a .npy/.tif file)"
        )
    return m


def load_height_map(spec: str, height_mm: float, width_mm: float, seed: int = 0) -> np.ndarray:
    """A height map from a file or a built-in shape, checked against the page and range."""
    p = Path(spec)
    if spec.split(":")[0] in SHAPES and not p.exists():
        m = shape_map(spec, height_mm, width_mm, seed)
    else:
        if not p.is_file():
            raise HeightMapError(
                f"height map {spec!r}: neither a shape ({', '.join(SHAPES)}) nor a file"
            )
        m = _read_map(p)
        aspect, page = m.shape[0] / m.shape[1], height_mm / width_mm
        if abs(aspect / page - 1) > 0.02:
            raise HeightMapError(
                f"height map {p}: shape {m.shape[0]} x {m.shape[1]} (rows x cols) does not "
                f"match the document's {height_mm:.1f} x {width_mm:.1f} mm aspect ratio"
            )
    check_range(m, spec)
    return m


def _read_map(p: Path) -> np.ndarray:
    """The heights (float64) in a .npy or TIFF file, checked from its header first: a 2-D
    array of real numbers, at least 2 x 2, at most :data:`MAX_MAP_SAMPLES`."""
    suffix = p.suffix.lower()
    if suffix not in (".npy", ".tif", ".tiff"):
        raise HeightMapError(f"height map {p}: use .npy or a float TIFF, in mm")
    try:
        if suffix == ".npy":
            with open(p, "rb") as fh:
                if fh.read(4) == b"PK\x03\x04":
                    raise HeightMapError(
                        f"height map {p}: an .npz archive, not a .npy array; save one array "
                        "with numpy.save"
                    )
                fh.seek(0)
                version = np.lib.format.read_magic(fh)
                read = np.lib.format.read_array_header_1_0
                if version != (1, 0):
                    read = np.lib.format.read_array_header_2_0
                shape, _, dtype = read(fh)
        else:
            import tifffile

            with tifffile.TiffFile(p) as tf:
                if not tf.pages:
                    raise HeightMapError(f"height map {p}: a TIFF header with no image after it")
                shape, dtype = tf.pages[0].shape, tf.pages[0].dtype
        if dtype is None or dtype.kind not in "iuf":
            raise HeightMapError(f"height map {p}: heights must be real numbers (got {dtype})")
        if len(shape) != 2 or min(shape) < 2:
            raise HeightMapError(
                f"height map {p}: must be a 2-D array of at least 2 x 2 (got shape {shape})"
            )
        if shape[0] * shape[1] > MAX_MAP_SAMPLES:
            raise HeightMapError(
                f"height map {p}: {shape[0]} x {shape[1]} samples, more than the "
                f"{MAX_MAP_SAMPLES:.0e} allowed; resample it"
            )
        if suffix == ".npy":
            m = np.load(p, allow_pickle=False)
        else:
            m = tifffile.imread(p, key=0)
        return np.asarray(m, dtype=np.float64).reshape(shape)
    except HeightMapError:
        raise
    except Exception as err:  # truncated or corrupt files fail in many ways
        detail = str(err) or type(err).__name__
        raise HeightMapError(f"height map {p}: cannot read it ({detail})") from None


def check_heights(z_mm: float | None, height_map: np.ndarray | None) -> None:
    """The one check of a scan's heights: a float height ``z_mm`` (mm) in
    :data:`Z_RANGE_MM`, or where ``height_map`` is given, its heights (:func:`check_range`);
    ValueError naming ``z_mm`` or the height map."""
    if height_map is not None:
        check_range(np.asarray(height_map, dtype=np.float64), "height_map")
        return
    lo, hi = Z_RANGE_MM
    if z_mm is None or not np.isfinite(z_mm) or not lo <= z_mm <= hi:
        raise ValueError(f"z_mm: must lie in [{lo:g}, {hi:g}] mm, the kernels' range (got {z_mm})")


def check_range(m: np.ndarray, name: str) -> None:
    lo, hi = Z_RANGE_MM
    if not np.all(np.isfinite(m)):
        raise HeightMapError(
            f"height map {name}: contains NaN or infinite heights (each must be a finite mm value)"
        )
    if m.min() < lo or m.max() > hi:
        raise HeightMapError(
            f"height map {name}: heights {m.min():.3g} to {m.max():.3g} mm lie outside the "
            f"modelled range [{lo:g}, {hi:g}] mm"
        )


def sample(
    m: np.ndarray, height_mm: float, width_mm: float, y_um: np.ndarray, x_um: np.ndarray
) -> np.ndarray:
    """Bilinear values of a page-covering map at points (y_um[:, None], x_um[None, :])."""
    fy = np.clip(np.asarray(y_um) / 1000.0 / height_mm, 0, 1) * (m.shape[0] - 1)
    fx = np.clip(np.asarray(x_um) / 1000.0 / width_mm, 0, 1) * (m.shape[1] - 1)
    yy, xx = np.meshgrid(fy, fx, indexing="ij")
    return ndimage.map_coordinates(m, [yy, xx], order=1, mode="nearest")
