"""Where the wave engine's 2-D arrays live: NumPy on the CPU, CuPy on a CUDA GPU.

The 2-D path of the wave engine (:mod:`.wave2d`) is written once against an array
module ``xp`` and an FFT module; :func:`backend` picks them from the device, a value
(``cpu`` or ``cuda``, :mod:`opticalstamp.device`), as the ray tracer does: no
environment is read. CuPy is optional (``pip install cupy-cuda12x``, or the build that
matches the driver); ``cuda`` without it is refused with the reason, and a run whose
device is ``cuda`` (``--device cuda``) but has no CuPy keeps the 2-D wave path on the CPU
and says so (:func:`wave_backend`).
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from scipy import fft as sfft

from ..device import DeviceUnavailable, run_device

__all__ = ["Backend", "backend", "wave_backend"]


@dataclass(frozen=True)
class Backend:
    """An array module and its FFTs: ``xp`` (numpy or cupy), ``name`` ("cpu" or "cuda")."""

    name: str
    xp: ModuleType
    _fft: ModuleType

    def _kw(self) -> dict:
        return {"workers": -1} if self.name == "cpu" else {}

    def fft(self, a, axis: int = -1, norm: str | None = None):
        return self._fft.fft(a, axis=axis, norm=norm, **self._kw())

    def ifft(self, a, axis: int = -1, norm: str | None = None):
        return self._fft.ifft(a, axis=axis, norm=norm, **self._kw())

    def fft2(self, a, norm: str | None = None):
        return self._fft.fft2(a, norm=norm, **self._kw())

    def ifft2(self, a, norm: str | None = None):
        return self._fft.ifft2(a, norm=norm, **self._kw())

    def j1(self, a):
        """The Bessel function J1 on this backend's arrays."""
        if self.name == "cuda":
            from cupyx.scipy import special as cspecial

            return cspecial.j1(a)
        from scipy import special

        return special.j1(a)

    def put(self, a):
        """A host array on this backend's device."""
        return self.xp.asarray(a)

    def host(self, a) -> np.ndarray:
        """An array of this backend back on the host (NumPy)."""
        return a.get() if self.name == "cuda" else np.asarray(a)

    def sync(self) -> None:
        """Wait for the device's queued work (for timings)."""
        if self.name == "cuda":
            self.xp.cuda.Device().synchronize()


CPU = Backend("cpu", np, sfft)


def cupy_found() -> bool:
    """Whether CuPy is installed (not imported)."""
    return importlib.util.find_spec("cupy") is not None


def backend(device: str = "cpu") -> Backend:
    """The backend of ``device``: "cpu" (NumPy, SciPy's FFTs on every core) or "cuda"
    (CuPy; :class:`~opticalstamp.device.DeviceUnavailable` where CuPy or a GPU is
    missing, naming which)."""
    if device == "cpu":
        return CPU
    if device != "cuda":
        raise ValueError(f"device: 'cpu' or 'cuda' (got {device!r})")
    if not cupy_found():
        raise DeviceUnavailable(
            "device cuda: the 2-D wave path on a GPU needs CuPy (pip install cupy-cuda12x, "
            "or the cupy build matching the driver); choose cpu"
        )
    import cupy
    import cupyx.scipy.fft as cfft

    try:
        cupy.cuda.runtime.getDeviceCount()
    except Exception as err:  # noqa: BLE001 - CuPy raises its own runtime errors
        raise DeviceUnavailable(f"device cuda: no GPU answers CuPy ({err}); choose cpu") from err
    return Backend("cuda", cupy, cfft)


def wave_backend(device: str | None = None) -> tuple[Backend, str]:
    """The 2-D wave path's backend for ``device`` (None: the run's device,
    :func:`~opticalstamp.device.run_device`), and a note: a ``cuda`` run without CuPy
    stays on the CPU (the note says so); a ``cuda`` named here is refused without it."""
    if device is not None:
        return backend(device), ""
    dev = run_device()
    if dev == "cuda" and not cupy_found():
        return CPU, "the run's device is cuda but CuPy is not installed: 2-D wave path on the CPU"
    return backend(dev), ""
