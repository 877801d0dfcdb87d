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

from .validate import InputError

DEVICES = ("auto", "cpu", "cuda")
ENV = "OPTICALSTAMP_DEVICE"


class DeviceUnavailable(InputError):
    """CUDA asked for where it cannot run."""


def _cuda_ready() -> tuple[bool, str]:
    """Whether numba.cuda can run kernels here (a GPU, or the simulator), and why not."""
    if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
        return True, ""
    try:
        from numba import cuda
    except ImportError as err:  # pragma: no cover - numba without its CUDA target
        return False, f"numba.cuda cannot be imported ({err}); pip install 'opticalstamp[cuda]'"
    if cuda.is_available():
        return True, ""
    return False, "no CUDA GPU answers (numba.cuda.is_available() is False)"


def resolve_device(name: str | None = None) -> str:
    """``cpu`` or ``cuda`` for ``name`` (None: the environment's ``OPTICALSTAMP_DEVICE``,
    else ``auto``). ``auto`` is ``cuda`` only with the numba-cuda package and a real GPU
    (never the simulator). Raises :class:`DeviceUnavailable` for ``cuda`` where it cannot
    run and :class:`~opticalstamp.validate.InputError` for a name not in :data:`DEVICES`
    (naming OPTICALSTAMP_DEVICE where the name came from it)."""
    where = "device"
    if name is None and os.environ.get(ENV):
        where = ENV  # named where it came from: the environment
    name = (name or os.environ.get(ENV) or "auto").strip().lower()
    if name not in DEVICES:
        raise InputError(f"{where}: must be one of {', '.join(DEVICES)} (got {name!r})")
    if name == "cpu":
        return "cpu"
    if name == "auto":
        simulated = os.environ.get("NUMBA_ENABLE_CUDASIM") == "1"
        if simulated or importlib.util.find_spec("numba_cuda") is None:
            return "cpu"
        return "cuda" if _cuda_ready()[0] else "cpu"
    ok, why = _cuda_ready()
    if not ok:
        raise DeviceUnavailable(f"{where} cuda: {why}")
    return "cuda"
