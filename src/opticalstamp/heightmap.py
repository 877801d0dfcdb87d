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

from .validate import InputError

#: Heights the scan model covers (mm).
Z_RANGE_MM = (0.0, 10.0)
SHAPES = ("flat", "tilt", "gutter", "crumple")


class HeightMapError(InputError):
    pass


def _args(spec: str, n: int, defaults: tuple[float, ...]) -> tuple[float, ...]:
    parts = spec.split(":")[1:]
    if len(parts) > n:
        raise HeightMapError(f"height map {spec!r}: at most {n} numbers after the shape")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise HeightMapError(f"height map {spec!r}: arguments must be numbers") from None
    return tuple(vals) + defaults[len(vals) :]


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
        m = np.full((ny, nx), z)
    elif kind == "tilt":
        z0, z1 = _args(spec, 2, (0.0, 3.0))
        m = np.broadcast_to(z0 + (z1 - z0) * y / height_mm, (ny, nx)).copy()
    elif kind == "gutter":
        depth, radius = _args(spec, 2, (3.0, 40.0))
        if radius <= 0:
            raise HeightMapError("gutter: radius must be > 0")
        d = np.minimum(np.abs(x - width_mm / 2), radius)
        sag = radius - np.sqrt(radius**2 - d**2)
        m = np.broadcast_to(np.maximum(depth - sag, 0.0), (ny, nx)).copy()
    elif kind == "crumple":
        amp, scale = _args(spec, 2, (1.5, 15.0))
        if scale <= 0:
            raise HeightMapError("crumple: scale must be > 0")
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
        try:
            if p.suffix.lower() == ".npy":
                m = np.load(p, allow_pickle=False)
            elif p.suffix.lower() in (".tif", ".tiff"):
                import tifffile

                m = tifffile.imread(p)
            else:
                raise HeightMapError(f"height map {p}: use .npy or a float TIFF, in mm")
        except (OSError, ValueError) as err:
            if isinstance(err, HeightMapError):
                raise
            raise HeightMapError(f"height map {p}: cannot read it ({err})") from None
        m = np.asarray(m, dtype=np.float64)
        if m.ndim != 2 or min(m.shape) < 2:
            raise HeightMapError(f"height map {p}: must be a 2-D array (got shape {m.shape})")
        aspect, page = m.shape[0] / m.shape[1], height_mm / width_mm
        if abs(aspect / page - 1) > 0.02:
            raise HeightMapError(
                f"height map {p}: shape {m.shape[0]} x {m.shape[1]} (rows x cols) does not "
                f"match the document's {height_mm:.1f} x {width_mm:.1f} mm aspect ratio"
            )
    check_range(m, spec)
    return m


def check_range(m: np.ndarray, name: str) -> None:
    lo, hi = Z_RANGE_MM
    if not np.all(np.isfinite(m)):
        raise HeightMapError(f"height map {name}: contains NaN or infinite heights")
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
