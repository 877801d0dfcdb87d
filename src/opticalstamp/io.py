"""Files: atomic writes, JSON with provenance. The only place results meet the disk."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from . import __version__


def _default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def _clean(obj):
    """Replace non-finite floats by None (JSON has no NaN/inf)."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, float | np.floating) and not np.isfinite(obj):
        return None
    return obj


def to_json(data: dict) -> str:
    return json.dumps(
        _clean(json.loads(json.dumps(data, default=_default, allow_nan=True))), indent=2
    )


def provenance(design, seed: int | None) -> dict:
    return {
        "design": design.name,
        "design_fingerprint": design.fingerprint(),
        "seed": seed,
        "opticalstamp_version": __version__,
    }


def write_atomic(path: str | Path, data: str | bytes) -> Path:
    """Write a file so that readers never see it half-written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the usual mode
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def save_figure(fig, path: str | Path, dpi: int = 110) -> Path:
    """Save a matplotlib figure atomically as PNG."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return write_atomic(path, buf.getvalue())


class ImageError(ValueError):
    """An image file that cannot be used (unreadable, truncated, wrong kind)."""


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding of values in [0, 1]."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def read_image(path: str | Path, *, linear: bool = False) -> tuple[np.ndarray, float | None]:
    """Read a PNG, TIFF or JPEG as a grey float image in [0, 1] and its dpi (or None).

    RGB is reduced to luminance (Rec. 709 weights); 16-bit files keep their precision;
    ``linear`` decodes sRGB to linear values.
    """
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise ImageError(f"image {path}: no such file")
    dpi = None
    try:
        if path.suffix.lower() in (".tif", ".tiff"):
            import tifffile

            with tifffile.TiffFile(path) as tf:
                arr = tf.asarray()
                tags = tf.pages[0].tags
                if "XResolution" in tags:
                    num, den = tags["XResolution"].value
                    unit = tags["ResolutionUnit"].value if "ResolutionUnit" in tags else 2
                    dpi = num / den * (2.54 if int(unit) == 3 else 1.0)
        else:
            with Image.open(path) as im:
                im.load()
                if "dpi" in im.info:
                    dpi = float(im.info["dpi"][0])
                keep = ("L", "RGB", "I;16", "I;16B", "I;16L", "I", "F")
                arr = np.asarray(im if im.mode in keep else im.convert("RGB"))
    except (OSError, UnidentifiedImageError, ValueError, KeyError) as err:
        raise ImageError(f"image {path}: cannot read it ({err})") from None
    if np.issubdtype(arr.dtype, np.integer):
        scale = float(np.iinfo(arr.dtype).max) if arr.dtype != np.int32 else 65535.0
        arr = arr.astype(np.float64) / scale
    else:
        arr = arr.astype(np.float64)
    if arr.ndim == 3:
        arr = arr[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    if arr.ndim != 2 or min(arr.shape) < 2:
        raise ImageError(f"image {path}: expected a 2-D image (got shape {arr.shape})")
    if linear:
        arr = srgb_to_linear(np.clip(arr, 0, 1))
    if dpi is not None:  # PNG stores pixels per metre: 600 dpi reads back as 599.9988
        dpi = round(float(dpi), 2) if dpi > 1 else None
    return arr, dpi
