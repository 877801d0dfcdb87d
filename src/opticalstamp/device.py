"""Which device traces the rays: ``cpu`` (numba, always there) or ``cuda`` (numba.cuda,
with the optional ``opticalstamp[cuda]`` and a GPU).

The device is a value: a name (``auto``, ``cpu`` or ``cuda``) resolved once by
:func:`resolve_device` to ``cpu`` or ``cuda`` and then carried by what traces rays (the
:class:`~opticalstamp.raytrace.pixel.PixelTracer`, ``launch(device=)``, a study's task
payloads, a result's provenance). ``auto``: CUDA where the optional numba-cuda package is
installed and a GPU answers, else the CPU. On the CPU path nothing of numba.cuda is
imported: ``auto`` looks for the numba-cuda package without importing it. numba's own
``NUMBA_ENABLE_CUDASIM=1`` makes ``cuda`` run numba's CUDA simulator (slow; the tests' way
to check the kernels).

Where a caller names no device, rays are traced on the device of the run in progress:
:func:`using_device` scopes one (the command line does, for the command it runs, from
``--device``); outside such a scope, the CPU. Nothing here reads or writes the process
environment.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

from .validate import InputError

DEVICES = ("auto", "cpu", "cuda")

#: the resolved device of the run in progress (:func:`using_device`); None outside one.
#: A context variable, not process state: it is local to a thread or task, undone on
#: leaving the scope, and not inherited by worker processes (their payloads carry it).
_RUN: ContextVar[str | None] = ContextVar("opticalstamp_device", default=None)


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


def simulated() -> bool:
    """Whether numba runs CUDA kernels in its simulator (numba's ``NUMBA_ENABLE_CUDASIM``,
    as numba read it)."""
    import numba

    return bool(numba.config.ENABLE_CUDASIM)


def _cuda_ready() -> tuple[bool, str]:
    """Whether numba.cuda can run kernels here (a GPU, or the simulator), and why not."""
    if simulated():
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


def device_name(name: str = "auto") -> str:
    """``auto``, ``cpu`` or ``cuda``: ``name`` checked (case and spaces aside) but not
    looked for; InputError naming ``device`` for another name, the empty one included."""
    if not isinstance(name, str) or name.strip().lower() not in DEVICES:
        raise InputError(f"device: must be one of {', '.join(DEVICES)} (got {name!r})")
    return name.strip().lower()


def resolve_device(name: str = "auto") -> str:
    """``cpu`` or ``cuda`` for ``name`` (:func:`device_name`). ``auto`` is ``cuda`` only
    with the numba-cuda package and a real GPU (never the simulator). Raises
    :class:`DeviceUnavailable` for ``cuda`` where it cannot run, saying why."""
    name = device_name(name)
    if name == "cpu":
        return "cpu"
    if name == "auto":
        if importlib.util.find_spec("numba_cuda") is None or not _driver_found():
            return "cpu"
        if simulated():
            return "cpu"
        return "cuda" if _cuda_ready()[0] else "cpu"
    ok, why = _cuda_ready()
    if not ok:
        raise DeviceUnavailable(f"device cuda cannot run here: {why}; choose cpu or auto")
    return "cuda"


def run_device(name: str | None = None) -> str:
    """``cpu`` or ``cuda``: ``name`` resolved (:func:`resolve_device`); None: the device of
    the run in progress (:func:`using_device`), the CPU outside one."""
    if name is not None:
        return resolve_device(name)
    return _RUN.get() or "cpu"


@contextmanager
def using_device(name: str) -> Iterator[str]:
    """Trace the rays of what runs inside on ``name`` (resolved once, here), where a
    caller names no device; undone on leaving. Yields the resolved device."""
    token = _RUN.set(resolve_device(name))
    try:
        yield _RUN.get()
    finally:
        _RUN.reset(token)


def usable_cores() -> int:
    """The CPU cores this process may run on: its CPU affinity where the system says (a
    container's limit), else every core of the machine."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on every system
        return os.cpu_count() or 1
