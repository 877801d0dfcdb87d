"""A scan's JSON sidecar (``NAME.json`` beside ``NAME.png``): read back with its fields
checked, matched against the image by the hashes it records, paths kept relative to it.

``scan`` writes the sidecar with its PNG and TIFF as one set
(:func:`~opticalstamp.io.atomic.write_set`); ``restore`` reads it for the height, the
design, the seed and the settings of the scan. Relative paths in a sidecar (the design
file, a height-map file, the input) are relative to the sidecar's folder, so that a scan
moved with its design file, or restored from another folder, still finds it.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from ..design import preset_names
from ..validate import InputError, check_number, check_seed

#: Largest sidecar read (bytes); a scan's is a few KiB.
MAX_SIDECAR_BYTES = 1 << 20

#: fields that are text where present (null allowed)
_TEXT = ("design", "design_source", "design_fingerprint", "height_map_spec", "input")
#: fields that are true or false where present (null allowed)
_FLAGS = ("color", "height_map", "noiseless", "ghosts")


class SidecarError(InputError):
    """A sidecar that cannot be used: the message names the file, the field and the rule."""


def sidecar_of(image: str | Path) -> Path:
    """The sidecar of an image: ``NAME.json`` beside it."""
    return Path(image).with_suffix(".json")


def read_sidecar(image: str | Path, *, z_range_mm: tuple[float, float]) -> dict | None:
    """The sidecar beside ``image``, its fields checked and its paths resolved.

    Parameters
    ----------
    image : path
        The scan; its sidecar is :func:`sidecar_of` it.
    z_range_mm : (float, float)
        The heights a scan may have been made at (mm): ``z_mm`` must lie in it.

    Returns
    -------
    dict or None
        The sidecar's fields (None: there is no sidecar). ``design_source`` that is not a
        preset and ``height_map_spec`` that names a file beside the sidecar are returned
        as paths joined to the sidecar's folder (relative paths are the sidecar's).

    Raises
    ------
    SidecarError
        Naming the sidecar and the field: not a regular file or too large, not a JSON
        object, ``z_mm`` not a finite number in ``z_range_mm`` (``true`` is not a
        number), ``seed`` not an integer in [0, 2^63 - 1], a text field that is not
        text, a flag that is not true or false, ``settings``/``restoration`` not objects,
        ``files`` not an object of names and SHA-256 digests.
    """
    path = sidecar_of(image)
    if not path.exists():
        return None
    if not path.is_file():
        raise SidecarError(f"sidecar {path}: not a regular file")
    try:
        if path.stat().st_size > MAX_SIDECAR_BYTES:
            raise SidecarError(
                f"sidecar {path}: larger than {MAX_SIDECAR_BYTES >> 10} KiB; a scan's sidecar "
                "is a short JSON file"
            )
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as err:  # JSON and UTF-8 errors included
        if isinstance(err, SidecarError):
            raise
        raise SidecarError(f"sidecar {path}: cannot read the scan's sidecar ({err})") from None
    if not isinstance(data, dict):
        raise SidecarError(f"sidecar {path}: not a JSON object (got {type(data).__name__})")
    _check_fields(data, path, z_range_mm)
    out = dict(data)
    src = out.get("design_source")
    if src is not None and src not in preset_names() and not Path(src).is_absolute():
        out["design_source"] = str(path.parent / src)
    spec = out.get("height_map_spec")
    if spec is not None and not Path(spec).is_absolute() and (path.parent / spec).is_file():
        out["height_map_spec"] = str(path.parent / spec)  # else a shape (tilt, gutter, ...)
    return out


def _check_fields(data: dict, path: Path, z_range_mm: tuple[float, float]) -> None:
    """SidecarError for the first field of ``data`` that breaks its rule."""
    where = f"sidecar {path}"
    try:
        if data.get("z_mm") is not None:
            check_number(data["z_mm"], f"{where}: z_mm (mm)", *z_range_mm)
        if data.get("seed") is not None:
            check_seed(data["seed"], f"{where}: seed")
    except InputError as err:
        raise SidecarError(str(err)) from None
    for key in _TEXT:
        if data.get(key) is not None and not isinstance(data[key], str):
            raise SidecarError(f"{where}: {key}: expected text (got {data[key]!r})")
    for key in _FLAGS:
        if data.get(key) is not None and not isinstance(data[key], bool):
            raise SidecarError(f"{where}: {key}: expected true or false (got {data[key]!r})")
    for key in ("settings", "restoration"):
        if data.get(key) is not None and not isinstance(data[key], dict):
            raise SidecarError(f"{where}: {key}: expected a JSON object (got {data[key]!r})")
    files = data.get("files")
    if files is not None and not (
        isinstance(files, dict)
        and all(isinstance(k, str) and isinstance(v, str) for k, v in files.items())
    ):
        raise SidecarError(
            f"{where}: files: expected an object of file names and SHA-256 digests (got {files!r})"
        )


def sidecar_matches(image: str | Path, data: dict) -> bool | None:
    """Whether ``image`` is one of the files its sidecar ``data`` records (SHA-256 of its
    bytes among the ``files`` digests, whatever its name now); None where the sidecar
    records no files (written by hand, or by an older version)."""
    files = data.get("files")
    if not files or not Path(image).is_file():  # a missing image is its reader's to name
        return None
    h = hashlib.sha256()
    with open(image, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest() in files.values()


def relative_to_sidecar(value: str | None, sidecar: str | Path) -> str | None:
    """What a sidecar records for a path given on the command line: an existing file as
    a path relative to the sidecar's folder (absolute where there is none, as between
    drives); anything else (None, a preset name, a height-map shape) as it is."""
    if value is None or value in preset_names() or not Path(value).is_file():
        return value
    target = Path(value).resolve()
    try:
        return os.path.relpath(target, Path(sidecar).resolve().parent)
    except ValueError:  # pragma: no cover - another drive (Windows)
        return str(target)
