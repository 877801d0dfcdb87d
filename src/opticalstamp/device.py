"""Which device traces the rays: ``cpu`` (numba, always there) or ``cuda`` (numba.cuda,
with the optional ``opticalstamp[cuda]`` and a GPU).

The choice is ``--device`` (the app's option) or the environment's ``OPTICALSTAMP_DEVICE``,
``auto`` by default: CUDA where the optional numba-cuda package is installed and a GPU
answers, else the CPU. On the CPU path nothing of numba.cuda is imported: ``auto`` looks
for the numba-cuda package without importing it. ``NUMBA_ENABLE_CUDASIM=1`` makes
``cuda`` run numba's CUDA simulator (slow; the tests' way to check the kernels).
"""

from __future__ import annotations

import importlib.util
import os
import sys

from .validate import InputError

DEVICES = ("auto", "cpu", "cuda")
ENV = "OPTICALSTAMP_DEVICE"


class DeviceUnavailable(InputError):
    """CUDA asked for where it cannot run."""


def _driver_found() -> bool:
    """Whether an NVIDIA driver library is installed (Linux: libcuda in the loader's cache,
    30 ms), so that ``auto`` on a machine without one does not import numba.cuda (0.3 s)
    to find no GPU; True elsewhere (numba.cuda is asked then)."""
    if not sys.platform.startswith("linux"):
        return True
    import ctypes.util

    return ctypes.util.find_library("cuda") is not None


def _compiler_found() -> bool:
    """Whether numba-cuda finds the CUDA compiler (libNVVM); True where it cannot tell."""
    try:
        from numba.cuda.cudadrv import nvvm

        return bool(nvvm.is_available())
    except Exception:  # noqa: BLE001 - an internal API of numba-cuda: assume it is there
        return True


def _cuda_ready() -> tuple[bool, str]:
    """Whether numba.cuda can run kernels here (a GPU, or the simulator), and why not."""
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return True, ""
    if importlib.util.find_spec("numba_cuda") is None:
        return False, (
            "numba-cuda is not installed: pip install 'opticalstamp[cuda]' (from a clone: "
            ".venv/bin/pip install -e '.[cuda]')"
        )
    try:
        from numba import cuda
    except ImportError as err:  # pragma: no cover - a broken numba-cuda
        return False, f"numba.cuda cannot be imported ({err})"
    if not cuda.is_available():
        return False, "no CUDA GPU answers (numba.cuda.is_available() is False)"
    if not _compiler_found():  # pragma: no cover - GPU machines only
        return False, (
            "no CUDA compiler (libNVVM) found: install the CUDA toolkit, or as wheels "
            "pip install 'numba-cuda[cu12]' (or [cu13] for a CUDA 13 driver)"
        )
    return True, ""


def device_name(name: str | None = None) -> str:
    """``auto``, ``cpu`` or ``cuda``: ``name`` (None: the environment's
    ``OPTICALSTAMP_DEVICE``, else ``auto``), checked but not looked for; InputError for
    another name, the empty one included (naming OPTICALSTAMP_DEVICE where the name came
    from it; an empty OPTICALSTAMP_DEVICE is unset, as in a shell's ``VAR= cmd``)."""
    where = "device"
    if name is None:
        if os.environ.get(ENV):
            where = ENV  # named where it came from: the environment
        name = os.environ.get(ENV) or "auto"
    name = name.strip().lower()
    if name not in DEVICES:
        raise InputError(f"{where}: must be one of {', '.join(DEVICES)} (got {name!r})")
    return name


def resolve_device(name: str | None = None) -> str:
    """``cpu`` or ``cuda`` for ``name`` (:func:`device_name`). ``auto`` is ``cuda`` only
    with the numba-cuda package and a real GPU (never the simulator). Raises
    :class:`DeviceUnavailable` for ``cuda`` where it cannot run, saying why and naming
    both ways to choose (``--device`` sets OPTICALSTAMP_DEVICE for the whole run)."""
    name = device_name(name)
    if name == "cpu":
        return "cpu"
    if name == "auto":
        simulated = os.environ.get("NUMBA_ENABLE_CUDASIM") == "1"
        if simulated or importlib.util.find_spec("numba_cuda") is None or not _driver_found():
            return "cpu"
        return "cuda" if _cuda_ready()[0] else "cpu"
    ok, why = _cuda_ready()
    if not ok:
        raise DeviceUnavailable(
            f"device cuda (--device or {ENV}) cannot run here: {why}; choose cpu or auto"
        )
    return "cuda"
