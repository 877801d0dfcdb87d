"""Files: atomic writes, JSON with provenance. The only place results meet the disk."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from . import __version__
from .validate import InputError


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


class ImageError(InputError):
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
    return arr, _round_dpi(dpi)  # PNG stores pixels per metre: 600 dpi reads as 599.9988


#: Bytes per document pixel and channel while scanning (float32 reflectance, the y pass,
#: decoding buffers).
SCAN_BYTES_PER_SAMPLE = 10


def available_memory_bytes() -> int:
    """MemAvailable from /proc/meminfo (or 4 GiB where it cannot be read)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 4 << 30


def read_document(
    path: str | Path, *, color: bool = False, memory_limit_bytes: int | None = None
) -> tuple[np.ndarray, float | None]:
    """A document image as linear reflectance (float32, [y, x] or [y, x, 3]) and its dpi.

    8- and 16-bit sRGB values are decoded through a lookup table. The memory the scan
    will need is estimated from the header first, and a file that would not fit in
    ``memory_limit_bytes`` (default: 80 % of the available memory) is refused with the
    numbers, before it is decoded.
    """
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    if not path.is_file():
        raise ImageError(f"document {path}: no such file")
    Image.MAX_IMAGE_PIXELS = None  # the memory check below replaces Pillow's bomb guard
    try:
        with Image.open(path) as im:
            w, h = im.size
            n_ch = 3 if color and im.mode not in ("L", "I;16", "I;16B", "I;16L", "I", "F") else 1
            need = w * h * n_ch * SCAN_BYTES_PER_SAMPLE
            limit = memory_limit_bytes or int(0.8 * available_memory_bytes())
            if need > limit:
                raise ImageError(
                    f"document {path}: {w} x {h} pixels x {n_ch} channel(s) needs about "
                    f"{need / 2**30:.1f} GiB to scan, more than the {limit / 2**30:.1f} GiB "
                    "available; crop it or lower its resolution"
                )
            dpi = float(im.info["dpi"][0]) if "dpi" in im.info else None
            im.load()
            if im.mode in ("I;16", "I;16B", "I;16L", "I"):
                arr = (
                    np.asarray(im, dtype=np.uint16)
                    if im.mode != "I"
                    else np.clip(np.asarray(im), 0, 65535).astype(np.uint16)
                )
                lut = srgb_to_linear(np.arange(65536) / 65535.0).astype(np.float32)
                return _apply_lut(lut, arr), _round_dpi(dpi)
            if im.mode == "F":
                return np.clip(np.asarray(im, np.float32), 0, 1), _round_dpi(dpi)
            im = im.convert("RGB" if n_ch == 3 else "L")
            arr = np.asarray(im)
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError) as err:
        if isinstance(err, ImageError):
            raise
        raise ImageError(f"document {path}: cannot read it ({err})") from None
    lut = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
    return _apply_lut(lut, arr), _round_dpi(dpi)


def _apply_lut(lut: np.ndarray, arr: np.ndarray, rows: int = 512) -> np.ndarray:
    """lut[arr] in strips of rows (a whole-page fancy index would need an 8-byte index
    per pixel: 1.1 GB for an A4 page at 1200 dpi)."""
    out = np.empty(arr.shape, np.float32)
    for i in range(0, arr.shape[0], rows):
        out[i : i + rows] = lut[arr[i : i + rows]]
    return out


def _round_dpi(dpi: float | None) -> float | None:
    return round(float(dpi), 2) if dpi is not None and dpi > 1 else None


def linear_to_srgb(v: np.ndarray) -> np.ndarray:
    v = np.clip(np.asarray(v, dtype=np.float64), 0, 1)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def write_png(path: str | Path, linear: np.ndarray, dpi: float, *, srgb: bool = True) -> Path:
    """8-bit PNG (sRGB-encoded unless ``srgb`` is False) with its resolution, atomically."""
    import io as _io

    from PIL import Image

    v = linear_to_srgb(linear) if srgb else np.clip(linear, 0, 1)
    im = Image.fromarray(np.round(v * 255).astype(np.uint8))
    buf = _io.BytesIO()
    im.save(buf, format="PNG", dpi=(dpi, dpi))
    return write_atomic(path, buf.getvalue())


def write_tiff16(path: str | Path, linear: np.ndarray, dpi: float, description: str = ""):
    """16-bit TIFF of linear values (0..65535) with its resolution in dpi, atomically."""
    import io as _io

    import tifffile

    buf = _io.BytesIO()
    data = np.round(np.clip(linear, 0, 1) * 65535).astype(np.uint16)
    tifffile.imwrite(
        buf,
        data,
        resolution=(dpi, dpi),
        resolutionunit="INCH",
        description=description or None,
        photometric="rgb" if data.ndim == 3 else "minisblack",
    )
    return write_atomic(path, buf.getvalue())


def save_dataset(ds, path: str | Path) -> Path:
    """An xarray Dataset as netCDF (scipy engine: NETCDF3, no extra library), atomically.

    Attributes that are not numbers or strings are stored as JSON strings.
    """
    ds = ds.copy()
    ds.attrs = {
        k: v if isinstance(v, int | float | str) else json.dumps(v, default=_default)
        for k, v in ds.attrs.items()
        if v is not None
    }
    return write_atomic(path, ds.to_netcdf(engine="scipy"))
