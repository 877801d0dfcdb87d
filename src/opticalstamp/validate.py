"""Checks of user input shared by the library and the command line.

Every check raises :class:`InputError` (or a subclass: ``DesignError``, ``ImageError``,
``HeightMapError``) whose message names the field or option and the rule it breaks. The
command line turns any ``InputError`` into ``error: <message>`` and exit code 2, before
any work is done.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np


class InputError(ValueError):
    """Input that cannot be used; the message names the field or option and the rule."""


#: Seeds: non-negative integers below 2^63 (the counter-based generator hashes them into
#: 64 bits; numpy's generators take them as they are). One rule for every command.
MAX_SEED = 2**63 - 1

#: The most memory one option may make an analysis allocate in one array (bytes).
MAX_WORK_BYTES = 2 << 30


def check_number(
    value: object,
    name: str,
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    hi_open: bool = False,
    integer: bool = False,
) -> float:
    """``value`` as a finite number in the interval; InputError naming ``name`` otherwise.

    Booleans and strings are not numbers. ``lo_open``/``hi_open`` exclude the bounds.
    """
    kind = "an integer" if integer else "a number"
    ok_type = isinstance(value, int) if integer else isinstance(value, int | float)
    if isinstance(value, bool) or not ok_type:
        raise InputError(f"{name}: expected {kind} (got {value!r})")
    if not integer and not math.isfinite(value):
        raise InputError(f"{name}: must be a finite number (got {value!r})")
    below = lo is not None and (value <= lo if lo_open else value < lo)
    above = hi is not None and (value >= hi if hi_open else value > hi)
    if below or above:
        raise InputError(f"{name}: must be {_interval(lo, hi, lo_open, hi_open)} (got {value!r})")
    return value


def _interval(lo, hi, lo_open, hi_open) -> str:
    if hi is None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if lo is None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def check_seed(seed: object, name: str = "seed") -> int:
    """A seed: an integer in [0, 2^63 - 1]."""
    ok = isinstance(seed, int | np.integer) and not isinstance(seed, bool | np.bool_)
    if not ok or not 0 <= seed <= MAX_SEED:
        raise InputError(f"{name}: must be an integer in [0, 2^63 - 1] (got {seed!r})")
    return seed


def parse_numbers(
    text: str, name: str, lo: float, hi: float, *, max_count: int = 10_000
) -> tuple[float, ...]:
    """Comma-separated finite numbers in [lo, hi] (at least one)."""
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise InputError(f"{name}: expected comma-separated numbers (got {text!r})") from None
    if not vals:
        raise InputError(f"{name}: expected at least one number (got {text!r})")
    if len(vals) > max_count:
        raise InputError(f"{name}: at most {max_count} values (got {len(vals)})")
    for v in vals:
        check_number(v, name, lo, hi)
    return vals


def parse_grid(text: str, name: str, lo: float, hi: float, max_steps: int = 1000):
    """START:STOP:STEP (inclusive of STOP) or comma-separated numbers, within [lo, hi]."""
    if ":" not in text:
        return parse_numbers(text, name, lo, hi)
    try:
        a, b, c = (float(v) for v in text.split(":"))
    except ValueError:
        raise InputError(f"{name}: expected START:STOP:STEP (got {text!r})") from None
    check_number(a, f"{name} START", lo, hi)
    check_number(b, f"{name} STOP", a, hi)
    check_number(c, f"{name} STEP", 0.0, None, lo_open=True)
    if (b - a) / c > max_steps:
        raise InputError(f"{name}: at most {max_steps} steps (got {text!r})")
    return tuple(float(v) for v in np.round(np.arange(a, b + c / 2, c), 6))


def check_memory(n_bytes: float, what: str, limit: float = MAX_WORK_BYTES) -> None:
    """Refuse work whose largest array would exceed ``limit`` bytes, naming ``what``."""
    if n_bytes > limit:
        raise InputError(
            f"{what}: would need about {n_bytes / 2**30:.3g} GiB in one array, more than the "
            f"{limit / 2**30:.3g} GiB allowed"
        )


def check_output_path(
    path: str | Path,
    name: str,
    *,
    suffixes: tuple[str, ...] = (),
    directory: bool = False,
    marker: str | None = None,
) -> Path:
    """An output path that can be written, checked before any work is done.

    Missing parent folders are allowed (they are created when writing); the nearest
    existing ancestor must be a writable folder. A file output must not name an existing
    folder, a folder output (``directory``) not an existing file. ``suffixes`` (lower
    case, compared case-insensitively) restricts the file type; the user's spelling of
    the suffix is kept. A folder output is replaced as a whole: an existing, non-empty
    folder must hold ``marker`` (the file that shows a previous run wrote it), so that a
    user's own folder is never replaced.
    """
    p = Path(path)
    if str(p) in ("", "."):
        raise InputError(f"{name}: an output path is needed")
    if suffixes and p.suffix.lower() not in suffixes:
        raise InputError(f"{name}: must end in {' or '.join(suffixes)} (got {p.name!r})")
    for part in p.parts:
        if len(os.fsencode(part)) > 255:
            raise InputError(f"{name}: the name {part[:40]!r}... is longer than 255 bytes")
    if directory and p.exists() and not p.is_dir():
        raise InputError(f"{name}: {p} exists and is not a folder")
    if directory and marker and p.is_dir() and any(p.iterdir()) and not (p / marker).is_file():
        raise InputError(
            f"{name}: {p} is a folder with other content (no {marker}); it would be replaced "
            "as a whole: choose a new or empty folder"
        )
    if not directory and p.is_dir():
        raise InputError(f"{name}: {p} is an existing folder, not a file")
    parent = p.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(f"{name}: {p} lies under {parent}, which is a file, not a folder")
    try:  # a real probe: permissions, read-only or special file systems, quotas
        fd, probe = tempfile.mkstemp(dir=parent, prefix=".opticalstamp-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        raise InputError(f"{name}: cannot write in {parent} ({err.strerror})") from None
    return p
