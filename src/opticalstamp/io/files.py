"""Files: atomic writes, JSON with provenance. The only place results meet the disk."""

from __future__ import annotations

import contextlib
import json
import re
import unicodedata
from pathlib import Path

import numpy as np

from .. import __version__
from ..design.electronics import LUMA
from ..validate import InputError
from .atomic import replace_folder, verify_set, write_atomic, write_set  # noqa: F401


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


#: Longest file stem :func:`file_stem` returns (characters).
MAX_STEM = 80
_UNIT_AFTER_NUMBER = re.compile(r"(?<![A-Za-z0-9.])(?:at\s+)?(\d+(?:\.\d+)?)\s+(dpi|um|mm|nm)\b")
_UNSAFE = re.compile(r"[^A-Za-z0-9._]+")


def file_stem(name: str) -> str:
    """A design's name as a file stem: no spaces, nothing a shell or a file system treats
    specially, the same stem for the same name on every run.

    Parameters
    ----------
    name : str
        A design's name, as readable as it likes (``"paper2016 at 600 dpi"``).

    Returns
    -------
    str
        ASCII letters, digits, ``.``, ``_`` and ``-`` only: accents dropped
        (``é`` -> ``e``), a number and the unit after it joined, an ``at`` before them
        dropped (``"at 600 dpi"`` -> ``600dpi``), every other run of characters one
        ``-``; no leading or trailing ``-`` or ``.`` (never an option, never hidden); at
        most :data:`MAX_STEM` characters; ``"design"`` where nothing is left.
        ``"paper2016 at 600 dpi"`` -> ``"paper2016-600dpi"``; ``"paper2016"`` stays.
    """
    text = unicodedata.normalize("NFKD", name).encode("ascii", "ignore").decode("ascii")
    text = _UNIT_AFTER_NUMBER.sub(r"\1\2", text)
    stem = _UNSAFE.sub("-", text).strip("-.")[:MAX_STEM].rstrip("-.")
    return stem or "design"


def provenance(design, seed: int | None, traced: bool = True, device: str | None = None) -> dict:
    """What a result was made from: the design, the seed, the version and the device that
    traced its rays: ``device`` (:func:`~opticalstamp.device.run_device`; None: the device
    of the run in progress, the CPU outside one), or None where ``traced`` is False
    (nothing was traced)."""
    from ..design.rodlens import RodLensDesign
    from ..device import run_device

    # a rod-lens array's GRIN tracer has no GPU kernel: its rays are traced on the CPU
    # whatever the device
    where = None
    if traced:
        where = "cpu" if isinstance(design, RodLensDesign) else run_device(device)
    return {
        "design": design.name,
        "design_fingerprint": design.fingerprint(),
        "seed": seed,
        "opticalstamp_version": __version__,
        "device": where,
    }


def figure_png(fig, dpi: int = 110) -> bytes:
    """A matplotlib figure as PNG bytes."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def save_figure(fig, path: str | Path, dpi: int = 110) -> Path:
    """Save a matplotlib figure atomically as PNG."""
    return write_atomic(path, figure_png(fig, dpi))


class ImageError(InputError):
    """An image file that cannot be used (unreadable, truncated, wrong kind)."""


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding of values in [0, 1]."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


#: Bytes per image pixel and channel while reading and measuring an image (the float64
#: image, a working copy, decoding buffers).
IMAGE_BYTES_PER_SAMPLE = 24

#: Bytes per document pixel and channel while scanning (float32 reflectance, the y pass,
#: decoding buffers).
SCAN_BYTES_PER_SAMPLE = 10

_TIFF_MAGIC = (b"II*\0", b"MM\0*", b"II+\0", b"MM\0+")
_GREY_MODES = ("L", "I;16", "I;16B", "I;16L", "I", "F")


@contextlib.contextmanager
def _guarded(path: Path, what: str):
    """Turn any failure of the decoders into an ImageError naming the file.

    Pillow's decompression-bomb limit is lifted inside (the header checks of
    :func:`_checked_header` replace it with a memory estimate) and restored on leaving.
    """
    from PIL import Image

    old = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None
    try:
        yield
    except InputError:
        raise
    except Exception as err:  # truncated, corrupt or unsupported files fail in many ways
        detail = str(err) or type(err).__name__
        raise ImageError(f"{what} {path}: cannot read it ({detail})") from None
    finally:
        Image.MAX_IMAGE_PIXELS = old


def _ratio(value) -> float:
    """A TIFF RATIONAL (numerator, denominator) as a float; NaN for a zero denominator."""
    num, den = value
    return num / den if den else float("nan")


def _header(path: Path, what: str) -> tuple[int, int, int, tuple[float, float] | None, bool]:
    """Width, height, samples per pixel, the stored (x, y) resolution in dpi (None when
    absent) and whether the file is a TIFF, from the header alone (first TIFF page)."""
    with open(path, "rb") as fh:
        tiff = fh.read(4) in _TIFF_MAGIC
    if tiff:
        import tifffile

        with tifffile.TiffFile(path) as tf:
            if not tf.pages:
                raise ImageError(f"{what} {path}: a TIFF header with no readable image after it")
            page = tf.pages[0]
            tags, res = page.tags, None
            if "XResolution" in tags:
                cm = "ResolutionUnit" in tags and tags["ResolutionUnit"].value == 3
                scale = 2.54 if cm else 1.0
                x = _ratio(tags["XResolution"].value)
                y = _ratio(tags["YResolution"].value) if "YResolution" in tags else x
                res = (x * scale, y * scale)
            return page.imagewidth, page.imagelength, page.samplesperpixel, res, True
    from PIL import Image

    with Image.open(path) as im:
        dpi = im.info.get("dpi")
        res = (float(dpi[0]), float(dpi[1])) if dpi else None
        return im.size[0], im.size[1], len(im.getbands()), res, False


def _checked_header(
    path: Path,
    what: str,
    *,
    dpi: float | None,
    min_px: int,
    channels: int | None,
    bytes_per_sample: int,
    memory_limit_bytes: int | None,
) -> tuple[float | None, bool]:
    """Check an image from its header before decoding it: at least ``min_px`` pixels each
    way, memory for ``bytes_per_sample`` per pixel and channel (``channels``, default:
    the file's) within ``memory_limit_bytes`` (default: 80 % of the available memory),
    and, unless ``dpi`` is given, a usable resolution with square pixels.

    Returns the resolution to use (``dpi`` if given, else the file's; None if it stores
    none) and whether the file is a TIFF.
    """
    w, h, bands, res, tiff = _header(path, what)
    if min(w, h) < min_px:
        raise ImageError(
            f"{what} {path}: {w} x {h} pixels is too small (this command needs at least "
            f"{min_px} x {min_px})"
        )
    n_ch = channels or bands
    need = w * h * n_ch * bytes_per_sample
    limit = memory_limit_bytes or int(0.8 * available_memory_bytes())
    if need > limit:
        raise ImageError(
            f"{what} {path}: {w} x {h} pixels x {n_ch} channel(s) needs about "
            f"{need / 2**30:.1f} GiB to {'scan' if what == 'document' else 'measure'}, more "
            f"than the {limit / 2**30:.1f} GiB available; crop it or lower its resolution"
        )
    if dpi is not None or res is None:
        return dpi, tiff
    x, y = res
    if not (np.isfinite(x) and np.isfinite(y)):
        raise ImageError(
            f"{what} {path}: its stored resolution is not a number (a zero denominator); give --dpi"
        )
    if max(x, y) > 1 and abs(x - y) > 1e-3 * max(x, y):
        raise ImageError(
            f"{what} {path}: its pixels are not square ({round(x, 2):g} dpi along x, "
            f"{round(y, 2):g} dpi along y) and the analyses assume square pixels; resample "
            "it, or give --dpi to override the file's resolution"
        )
    return _round_dpi(x), tiff


def _finite(arr: np.ndarray, path: Path, what: str) -> None:
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise ImageError(f"{what} {path}: holds NaN or infinite pixel values; replace them")


def read_image(
    path: str | Path,
    *,
    linear: bool = False,
    dpi: float | None = None,
    min_px: int = 2,
    memory_limit_bytes: int | None = None,
) -> tuple[np.ndarray, float | None]:
    """Read a PNG, TIFF or JPEG as a grey float image in [0, 1] and its dpi (or None).

    Parameters
    ----------
    path : str or Path
        The image file. TIFFs are read with tifffile (first page), others with Pillow.
    linear : bool
        Decode sRGB values to linear ones.
    dpi : float, optional
        The resolution to use instead of the file's (which is then not checked).
    min_px : int
        The fewest pixels the image may have along each side.
    memory_limit_bytes : int, optional
        Refuse, from the header, an image that needs more memory (default: 80 % of the
        available memory).

    Returns
    -------
    image : ndarray
        [y, x] float64; RGB is reduced to luminance (Rec. 709 weights), grey + alpha to
        grey; 16-bit files keep their precision.
    dpi : float or None

    Raises
    ------
    ImageError
        Whatever makes the file unusable, naming it: unreadable, too small or too large,
        non-square pixels or a broken resolution (unless ``dpi`` is given), NaN or
        infinite values in a float image.
    """
    from PIL import Image

    path = Path(path)
    if not path.is_file():
        raise ImageError(f"image {path}: no such file")
    with _guarded(path, "image"):
        use, tiff = _checked_header(
            path,
            "image",
            dpi=dpi,
            min_px=min_px,
            channels=None,
            bytes_per_sample=IMAGE_BYTES_PER_SAMPLE,
            memory_limit_bytes=memory_limit_bytes,
        )
        if tiff:
            import tifffile

            with tifffile.TiffFile(path) as tf:
                page = tf.pages[0]
                arr = page.asarray()
                if arr.ndim == 3 and page.planarconfig == 2:  # separate planes: [c, y, x]
                    arr = np.moveaxis(arr, 0, -1)
        else:
            with Image.open(path) as im:
                im.load()
                keep = ("L", "RGB", "I;16", "I;16B", "I;16L", "I", "F")
                arr = np.asarray(im if im.mode in keep else im.convert("RGB"))
    if arr.dtype.kind not in "biuf":
        raise ImageError(f"image {path}: pixel type {arr.dtype} is not supported")
    _finite(arr, path, "image")
    if arr.dtype.kind in "iu":
        scale = float(np.iinfo(arr.dtype).max) if arr.dtype != np.int32 else 65535.0
        arr = arr.astype(np.float64) / scale
    else:
        arr = arr.astype(np.float64)
    if arr.ndim == 3:  # grey (+ alpha): the first channel; colour: luminance
        arr = arr[..., 0] if arr.shape[2] < 3 else arr[..., :3] @ list(LUMA)
    if arr.ndim != 2 or min(arr.shape) < min_px:
        raise ImageError(f"image {path}: expected a 2-D image (got shape {arr.shape})")
    if linear:
        arr = srgb_to_linear(np.clip(arr, 0, 1))
    return arr, use  # PNG stores pixels per metre: 600 dpi reads as 599.9988 (rounded)


#: Largest illumination profile read (bytes): a CSV of x_mm,relative pairs, thousands of
#: rows at most; a device, a folder or a stray huge file is refused before it is read.
MAX_PROFILE_BYTES = 1 << 20


def read_illumination_profile(path: str | Path) -> tuple[tuple[float, float], ...]:
    """The (x_mm, relative) rows of an illumination profile CSV, read as numbers.

    The file must be a regular file of at most :data:`MAX_PROFILE_BYTES`, UTF-8 text of
    two comma-separated columns (``#`` starts a comment). The values' rules (increasing x,
    finite, >= 0, positive somewhere) are
    :class:`~opticalstamp.imaging.scan.ScanSettings`'s, checked where the settings are made.

    Raises
    ------
    InputError
        Naming the file and the rule: not a regular file (a folder, ``/dev/zero``, a
        pipe), too large, not text, or not two columns of numbers.
    """
    path = Path(path)
    where = f"illumination profile {path}"
    if not path.exists():
        raise InputError(f"{where}: no such file (use uniform, ripple or a CSV of x_mm,relative)")
    if not path.is_file():
        raise InputError(f"{where}: not a regular file (a CSV of x_mm,relative)")
    try:
        if path.stat().st_size > MAX_PROFILE_BYTES:
            raise InputError(
                f"{where}: larger than {MAX_PROFILE_BYTES >> 10} KiB; a profile is a short "
                "CSV of x_mm,relative"
            )
        lines = [
            ln
            for ln in path.read_text(encoding="utf-8-sig").splitlines()
            if ln.split("#")[0].strip()
        ]
        if not lines:
            raise InputError(f"{where}: no rows (a CSV of x_mm,relative, one point a row)")
        arr = np.loadtxt(lines, delimiter=",", ndmin=2, comments="#")
    except (OSError, UnicodeDecodeError, ValueError) as err:
        if isinstance(err, InputError):
            raise
        raise InputError(f"{where}: cannot read it as a CSV of x_mm,relative ({err})") from None
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise InputError(f"{where}: needs two columns, x_mm,relative (got {arr.shape[-1]})")
    return tuple((float(a), float(b)) for a, b in arr)


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
    path: str | Path,
    *,
    color: bool = False,
    memory_limit_bytes: int | None = None,
    dpi: float | None = None,
    min_px: int = 2,
) -> tuple[np.ndarray, float | None]:
    """A document image as linear reflectance (float32, [y, x] or [y, x, 3]) and its dpi.

    8- and 16-bit sRGB values are decoded through a lookup table. The file is checked
    from its header before it is decoded, as in :func:`read_image` (``dpi``, ``min_px``),
    and a file whose scan would not fit in ``memory_limit_bytes`` (default: 80 % of the
    available memory) is refused with the numbers.

    Raises
    ------
    ImageError
        Whatever makes the file unusable, naming it (see :func:`read_image`).
    """
    from PIL import Image

    path = Path(path)
    if not path.is_file():
        raise ImageError(f"document {path}: no such file")
    with _guarded(path, "document"):
        with Image.open(path) as im:
            n_ch = 3 if color and im.mode not in _GREY_MODES else 1
            use, _ = _checked_header(
                path,
                "document",
                dpi=dpi,
                min_px=min_px,
                channels=n_ch,
                bytes_per_sample=SCAN_BYTES_PER_SAMPLE,
                memory_limit_bytes=memory_limit_bytes,
            )
            im.load()
            if im.mode in ("I;16", "I;16B", "I;16L", "I"):
                arr = (
                    np.asarray(im, dtype=np.uint16)
                    if im.mode != "I"
                    else np.clip(np.asarray(im), 0, 65535).astype(np.uint16)
                )
                lut = srgb_to_linear(np.arange(65536) / 65535.0).astype(np.float32)
                return _apply_lut(lut, arr), use
            if im.mode == "F":
                arr = np.asarray(im, np.float32)
                _finite(arr, path, "document")
                return np.clip(arr, 0, 1), use
            arr = np.asarray(im.convert("RGB" if n_ch == 3 else "L"))
    lut = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)
    return _apply_lut(lut, arr), use


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


#: PNG gAMA values (1/gamma x 100000): sRGB's nominal 1/2.2, and linear values.
_GAMA_SRGB, _GAMA_LINEAR = 45455, 100000


def encode_png(linear: np.ndarray, dpi: float, *, srgb: bool = True) -> bytes:
    """8-bit PNG bytes (sRGB-encoded unless ``srgb`` is False) with the resolution, and
    the encoding stated in the file: an sRGB chunk (with gAMA 1/2.2), or gAMA 1 for
    linear values, so that readers (:func:`image_encoding`) decode it right."""
    import io as _io

    from PIL import Image, PngImagePlugin

    v = linear_to_srgb(linear) if srgb else np.clip(linear, 0, 1)
    im = Image.fromarray(np.round(v * 255).astype(np.uint8))
    info = PngImagePlugin.PngInfo()
    if srgb:
        info.add(b"sRGB", b"\x00")  # rendering intent: perceptual
    gama = _GAMA_SRGB if srgb else _GAMA_LINEAR
    info.add(b"gAMA", gama.to_bytes(4, "big"))
    buf = _io.BytesIO()
    im.save(buf, format="PNG", dpi=(dpi, dpi), pnginfo=info)
    return buf.getvalue()


def image_encoding(path: str | Path) -> str:
    """How an image file's values are encoded, from its header: "srgb" (an sRGB chunk,
    an ICC profile, or a gamma near 1/2.2), "linear" (gamma 1, 16-bit or float samples,
    TIFF), or "untagged" (8-bit with no colour information: sRGB is likely, not stated).
    """
    from PIL import Image

    path = Path(path)
    if path.suffix.lower() in (".tif", ".tiff"):
        return "linear"
    with _guarded(path, "image"), Image.open(path) as im:
        info, mode = im.info, im.mode
    if mode not in ("L", "LA", "P", "RGB", "RGBA"):
        return "linear"  # 16-bit or float samples: opticalstamp and instruments store linear
    if "srgb" in info or "icc_profile" in info:
        return "srgb"
    gamma = info.get("gamma")
    if gamma is not None:
        return "linear" if abs(gamma - 1.0) < 0.01 else "srgb"
    return "untagged"


def write_png(path: str | Path, linear: np.ndarray, dpi: float, *, srgb: bool = True) -> Path:
    """8-bit PNG (sRGB-encoded unless ``srgb`` is False) with its resolution, atomically."""
    return write_atomic(path, encode_png(linear, dpi, srgb=srgb))


def encode_tiff16(linear: np.ndarray, dpi: float, description: str = "") -> bytes:
    """16-bit TIFF bytes of linear values (0..65535) with the resolution in dpi."""
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
    return buf.getvalue()


def write_tiff16(path: str | Path, linear: np.ndarray, dpi: float, description: str = ""):
    """16-bit TIFF of linear values (0..65535) with its resolution in dpi, atomically."""
    return write_atomic(path, encode_tiff16(linear, dpi, description))


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
