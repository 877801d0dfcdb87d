"""Line-spread functions from the 2-D path of the wave engine (any hole shape).

:func:`~.wave2d.stack_modes` gives a pixel's in-band light above the object-side mask as
coherent modes u_m(x, y) (2-D fields: circular holes make it non-separable). A chart
varying along x needs only the x marginal of the responsivity,

    LSF_x(x; Z) = sum_m integral |u_m(x, y; Z)|^2 dy
                = step sum_m sum_{f_y} |IFFT_x[g_m(f_y, .) H_x(.; Z)](x)|^2,

(Parseval along y; g_m the mode's in-band spectrum, ortho-normalised). Above the stack
the paraxial transfer function is separable, H = H_x(f_x) H_y(f_y) with |H_y| = 1, so
H_y drops out: the 1-D spectra g_m(f_y, .) over every mode and every in-band f_y are an
incoherent set along x whose mutual intensity does not depend on Z. Its eigenvectors
(the coherent modes of the x marginal, all but ``mode_tol`` of the power) are
propagated to each Z as 1-D fields, by the separable path's object side
(:mod:`.waveobject`): the same grids, the same paraxial propagator, the same
:class:`~.wave.LSFSource`. The y marginal likewise. The product of the two marginals
is *not* the 2-D responsivity (a circle is not separable): the source gives marginals
and the light only; 2-D maps and the central cell's share come from
:func:`~.wave2d.wave_response_2d`.
"""

from __future__ import annotations

import numpy as np

from ..design import Design
from .arrays import fft_workers
from .wave import LSFSource, one_blas_thread
from .wave2d import RANGE_TOL, StackModes, stack_modes
from .wavebase import WaveSampling, stack_axes, wave_sampling
from .waveobject import object_side

__all__ = ["lsf_source_2d", "marginal_modes"]


def marginal_modes(sm: StackModes, axis: int, tol: float):
    """The coherent modes of the ``axis`` marginal (0: x, 1: y) of the modes ``sm`` as
    fields on that axis's stack grid (n, q), on the host: sum_k |u_k|^2 is the marginal
    (um sr per um), all but ``tol`` of its power; and the marginal's power (um^2 sr)."""
    st, bk, xp = sm.stack, sm.bk, sm.bk.xp
    ny_in, nx_in = st.ky.size, st.kx.size
    g = sm.modes.reshape(-1, ny_in, nx_in)
    a = g.reshape(-1, nx_in) if axis == 0 else xp.swapaxes(g, 1, 2).reshape(-1, ny_in)
    # mutual intensity of the incoherent 1-D spectra (rows): J = a^T conj(a) = sum p v v^H
    p, v = xp.linalg.eigh(bk.gram_t(a))
    p, v = bk.host(p)[::-1].clip(0.0, None), bk.host(v)[:, ::-1]
    keep = max(1, min(int(np.searchsorted(np.cumsum(p), (1 - tol) * p.sum())) + 1, p.size))
    grid = st.x if axis == 0 else st.y
    step = float(grid[1] - grid[0])
    bins = bk.host(st.kx if axis == 0 else st.ky)  # the axis's in-band FFT bins
    full = np.zeros((keep, grid.size), dtype=np.complex128)
    full[:, bins] = (v[:, :keep] * np.sqrt(p[:keep] * step)).T
    from scipy import fft as sfft

    u = sfft.ifft(full, axis=-1, norm="ortho", workers=fft_workers()).T  # (n, q)
    return np.ascontiguousarray(u), float(p.sum()) * step * step


def lsf_source_2d(
    design: Design,
    z_max_mm: float,
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    tol: float = RANGE_TOL,
    seed: int = 0,
    device: str | None = None,
    fresnel: bool = False,
    propagator: str = "exact",
    precision: str = "single",
) -> LSFSource:
    """An :class:`~.wave.LSFSource` of a used pixel by the 2-D path (any hole shape):
    x line-spread functions at any Z up to ``z_max_mm`` from the stack traversed once.
    ``tol``, ``seed``: the range finder's (:func:`~.wave2d.coherent_modes`); ``device``:
    "cpu" or "cuda" (None: the run's, :mod:`.arrays`). The object side is paraxial, as
    the separable path's; the stack's slabs are exact (angular spectrum; ``propagator``
    "paraxial" for checks against the separable path). ``fresnel``: the interfaces'
    Fresnel transmission (:func:`~.wave2dgrid.angular_filters`, which also apply the pixel's
    acceptance cone); ``precision``: the stack operator's (:func:`~.wave2d.stack_modes`)."""
    smp = wave_sampling(design) if sampling is None else sampling
    with one_blas_thread():
        sm = stack_modes(
            design,
            pixel=pixel,
            sampling=smp,
            tol=tol,
            seed=seed,
            device=device,
            fresnel=fresnel,
            propagator=propagator,
            precision=precision,
        )
        ux, light = marginal_modes(sm, 0, smp.mode_tol)
        uy, light_y = marginal_modes(sm, 1, smp.mode_tol)
        uy = uy / np.sqrt(max(light_y, 1e-300))  # unit power: R = X(x) Y(y) / light
        planes = stack_axes(design, pixel, reach_um=0.0, bounds=True)
        side = object_side(
            [()], {(): (ux, uy)}, planes, [sm.stack.x, sm.stack.y], smp, float(z_max_mm)
        )
        # ux are the x marginal's coherent modes already (orthogonal, all but mode_tol of
        # its power): propagated as they are, where x_modes would compress them again
        # (and drop up to mode_tol more); the one term's y weight is uy's power, 1
        modes = side.spectra[0][0] * np.sqrt(side.gram(1)[0, 0].real)
    meta = {"path": "2d", "device": sm.bk.name} | sm.info
    if sm.note:
        meta["note"] = sm.note
    return LSFSource(side, float(z_max_mm), ["2-D"], modes, light, meta, sm.bk.name)
