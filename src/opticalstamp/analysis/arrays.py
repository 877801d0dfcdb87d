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
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from types import ModuleType

import numba as nb
import numpy as np
from scipy import fft as sfft

from ..device import DeviceUnavailable, run_device

__all__ = ["Backend", "backend", "fft_threads", "fft_workers", "gram_rows", "wave_backend"]

#: Threads of the CPU's FFTs in the work in progress (-1: every core). A context
#: variable, local to a thread and undone on leaving :func:`fft_threads`: work run side
#: by side in threads gives each its one.
_FFT_THREADS: ContextVar[int] = ContextVar("opticalstamp_fft_threads", default=-1)


def fft_workers() -> int:
    """The CPU's FFT threads (SciPy's ``workers``) in the work in progress."""
    return _FFT_THREADS.get()


@contextmanager
def fft_threads(n: int) -> Iterator[None]:
    """The CPU backend's FFTs on ``n`` threads for what runs inside (-1: every core)."""
    token = _FFT_THREADS.set(int(n))
    try:
        yield
    finally:
        _FFT_THREADS.reset(token)


@dataclass(frozen=True)
class Backend:
    """An array module and its FFTs: ``xp`` (numpy or cupy), ``name`` ("cpu" or "cuda"),
    ``batch``: how many 2-D fields an operator pushes through at once (0: all it is
    given; on the CPU a few: the work arrays that its transforms run in place in are
    then a few fields' size whatever the block, and as fast: 2.0-2.1 s a block of 16
    through the circular prototype's stack at 4, 8 or 16 at a time, 2.7 s at 2)."""

    name: str
    xp: ModuleType
    _fft: ModuleType
    batch: int = 0

    def _kw(self) -> dict:
        return {"workers": fft_workers()} if self.name == "cpu" else {}

    def fft(self, a, axis: int = -1, norm: str | None = None, overwrite: bool = False):
        """The FFT along ``axis``; ``overwrite``: ``a`` may hold the result (in place)."""
        return self._fft.fft(a, axis=axis, norm=norm, overwrite_x=overwrite, **self._kw())

    def ifft(self, a, axis: int = -1, norm: str | None = None, overwrite: bool = False):
        """The inverse FFT along ``axis``; ``overwrite`` as :meth:`fft`'s."""
        return self._fft.ifft(a, axis=axis, norm=norm, overwrite_x=overwrite, **self._kw())

    def fft2(self, a, norm: str | None = None):
        return self._fft.fft2(a, norm=norm, **self._kw())

    def ifft2(self, a, norm: str | None = None):
        return self._fft.ifft2(a, norm=norm, **self._kw())

    def gram_t(self, a):
        """a^T conj(a) of a 2-D complex array (Hermitian): on the CPU by BLAS's zherk
        (:func:`gram_rows`), half the products of a matrix product."""
        if self.name == "cuda":
            return a.T @ a.conj()
        return gram_rows(np.asarray(a).T)

    def add_abs2(self, acc, u) -> None:
        """acc += |u|^2 in place (``acc`` real, ``u`` complex, the same shape): on the CPU
        in one pass without temporaries (a kernel), on a GPU by CuPy."""
        if self.name == "cuda":
            acc += u.real * u.real + u.imag * u.imag
        else:
            _add_abs2(acc, u)

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


def gram_rows(a: np.ndarray) -> np.ndarray:
    """G = a a^H of a 2-D complex host array (its rows' Gram matrix) by BLAS's zherk: half
    the products of a matrix product, G Hermitian to the last bit, and no copy of a C- or
    Fortran-ordered ``a``."""
    from scipy.linalg import blas

    a = np.asarray(a, dtype=np.complex128)
    if a.flags.f_contiguous:
        g = blas.zherk(1.0, a)  # a a^H, its upper triangle
    else:  # a^T is Fortran-ordered: (a^T)^H a^T = conj(a a^H)
        g = blas.zherk(1.0, np.ascontiguousarray(a).T, trans=2).conj()
    lower = np.tril_indices(g.shape[0], -1)
    g[lower] = g.T[lower].conj()
    return g


@nb.njit(cache=True, nogil=True)
def _add_abs2(acc, u):  # pragma: no cover - compiled
    for i in range(u.shape[0]):
        for j in range(u.shape[1]):
            v = u[i, j]
            acc[i, j] += v.real * v.real + v.imag * v.imag


CPU = Backend("cpu", np, sfft, batch=4)


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
