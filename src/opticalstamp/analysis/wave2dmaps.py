"""A pixel's 2-D responsivity maps by the wave engine's 2-D path (any hole shape).

What the separable path (:func:`~.wave.wave_response`) gives for rectangular holes, for
holes it cannot separate (circles): the line-spread functions of x and y, the in-band
light, the central cell's share and maps on any square bins (:meth:`MapResponse.spot`),
from the stack traversed once (:func:`~.wave2d.stack_modes`: the pixel's light above the
object-side mask as coherent modes u_m, the slabs by the exact angular spectrum).

Above the stack, as in the separable path, the propagator is paraxial (one reduced
distance d through the reference gap and the object medium): each mode's in-band spectrum
on the object grid (the stack grid widened by the band's reach up to the highest Z,
:func:`~.wavebase.object_grid`) is multiplied by exp(-i pi lambda d |f|^2) and the
intensity sum_m |u_m(X, Y; Z)|^2 evaluated where the light is: a window per height that
holds all but ``MAP_TAIL`` of each line-spread function at each end (and the central
cell). The transforms are pruned: the forward transform once per mode (only the stack's
rows are non-zero, only the in-band columns are kept), at each height only the in-band
columns back along y and only the window's rows back along x.

* The line-spread functions and the light come from the marginals' coherent modes
  (:func:`~.wave2dlsf.marginal_modes`, the object side of the separable path): exact,
  all the light, on the fine object grids; the maps' own marginals agree with them to
  the window's tail (tests/test_wave_circle_maps.py).
* The central cell's share integrates the window's intensity with the exact weights of
  band-limited samples (the separable path's; the intensity's band 2B / lambda is below
  the fine grid's Nyquist rate, and what lies outside the window is below the tail);
  the maps integrate it over their bins (cumulative trapezoid on the fine grid, as the
  separable path's maps).

Cost: a mode costs two transforms of the object grid per height (pruned to about 2/3
of a full 2-D pair); the stack dominates on a GPU, the heights on a CPU (docs/wave.md,
"Circular holes": measured figures). :func:`expected_seconds` estimates both from the
grids before any work, so that a caller can say what a CPU run will take.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np

from ..design import Design
from ..device import run_device
from ..raytrace.stack import output_pitch
from ..validate import InputError
from .arrays import cupy_found
from .wave import half_width, one_blas_thread
from .wave2d import (
    PRECISIONS,
    RANGE_TOL,
    StackModes,
    binned_map,
    operator_grid,
    stack_modes,
)
from .wave2dlsf import marginal_modes
from .wave2dop import gather_bins, in_band_runs, scatter_bins
from .wavebase import (
    WaveSampling,
    object_grid,
    pixel_record,
    response_summary,
    stack_axes,
    stack_grid,
    wave_sampling,
)
from .waveobject import cell_weights, object_side, responses_at

__all__ = [
    "MAP_TAIL",
    "MapResponse",
    "checked_heights",
    "expected_seconds",
    "maps_on_gpu",
    "wave_maps_2d",
]

#: Share of each line-spread function left outside a height's window at each end.
MAP_TAIL = 1e-6

#: CPU-seconds of the circular-hole prototype (paper2016 with circles, its default band,
#: one wavelength, 86 modes, object grid 6750^2 for 4.5 mm) on the shared 2-core
#: development machine, by what they scale with: the stack (range finder, 37 CPU-s at
#: load 1 on 2026-11-27, on its operator grid of 1120^2 points,
#: :func:`~.wave2d.operator_grid`) per operator-grid point, and a height of maps (about
#: 28 CPU-s: one run at Z = 0 and 4.5 mm took 127 CPU-s, less the stack's 37 and the
#: marginals' 5, for the forward transforms and two heights, 2026-11-27) per mode and
#: object-grid point (docs/wave.md; :func:`expected_seconds`).
CPU_S_PER_STACK_POINT = 37.0 / 1120**2
CPU_S_PER_MODE_POINT = 28.0 / (86 * 6750**2)
PROTOTYPE_MODES = 86
PROTOTYPE_POINTS = 39  # its Gauss-Legendre source points per axis


def checked_heights(z_mm) -> np.ndarray:
    """The object distances ``z_mm`` (mm) as an array, each finite and >= 0 (InputError
    naming ``z_mm`` otherwise)."""
    zs = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    if zs.size == 0 or not np.all(np.isfinite(zs)) or zs.min() < 0:
        raise InputError("z_mm: object distances must be finite and >= 0")
    return zs


def maps_on_gpu() -> bool:
    """Whether the 2-D path's maps run on a GPU in this run: the run's device is cuda
    (:func:`~opticalstamp.device.run_device`; ``--device`` on the command line) and CuPy
    is installed (:mod:`.arrays`)."""
    return run_device() == "cuda" and cupy_found()


@dataclass(frozen=True)
class MapResponse:
    """A pixel's responsivity by the 2-D path, with the attributes of
    :class:`~.wave.WaveResponse` where they mean the same.

    Attributes
    ----------
    design, fingerprint, pixel, z_mm : as :class:`~.wave.WaveResponse`
    x_um, y_um : (nx,), (ny,) the fine object grids (um, from the pixel's axis)
    lsf_x, lsf_y : (nz, nx), (nz, ny) line-spread functions (um sr per um)
    etendue_um2sr : (nz,) in-band light (um^2 sr)
    center_cell_fraction : (nz,) share of it within the central cell
    budget : the object-side mask's record (``in_band``, ``lost_to_band`` and its
        standard error ``lost_to_band_se``, ``transmitted``; um^2 sr): the 2-D path
        estimates the light sent beyond the band there, not mask by mask
    sampling : the :class:`~.wavebase.WaveSampling`
    windows : per height (x (n,), y (m,), intensity (m, n), um^2 sr per um^2) where the
        light is (:data:`MAP_TAIL`); float32 at the default single precision (4 bytes a
        point: 130 MB a height for the circular prototype at 4.5 mm, whose window is
        most of its 6750^2 object grid)
    meta : how the stack was traversed (modes, range, device, grids)
    """

    design: str
    fingerprint: str
    pixel: dict
    z_mm: np.ndarray
    x_um: np.ndarray
    y_um: np.ndarray
    lsf_x: np.ndarray
    lsf_y: np.ndarray
    etendue_um2sr: np.ndarray
    center_cell_fraction: np.ndarray
    budget: list[dict]
    sampling: WaveSampling
    windows: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(repr=False)
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Summary as plain data (no fine arrays)."""
        return response_summary(self) | {
            "budget": self.budget,
            "sampling": asdict(self.sampling),
            "meta": self.meta,
        }

    def spot(self, iz: int, bin_um: float = 2.0, half_um: float | None = None):
        """The responsivity map at ``z_mm[iz]`` on square bins (sr): (edges, map[y, x]),
        as :meth:`~.wave.WaveResponse.spot` (default ``half_um``: where the line-spread
        functions hold all but 1e-4 of the light); bins beyond the window are 0."""
        if half_um is None:
            half_um = max(
                half_width(self.x_um, self.lsf_x[iz]), half_width(self.y_um, self.lsf_y[iz])
            )
        n = int(math.ceil(half_um / bin_um))
        edges = np.arange(-n, n + 1) * bin_um
        x, y, inten = self.windows[iz]
        return edges, binned_map(x, y, inten.astype(np.float64), edges) / (bin_um * bin_um)


def _window(x: np.ndarray, lsf: np.ndarray, cell: float, tail: float) -> slice:
    """The part of the grid ``x`` that holds all but ``tail`` of ``lsf`` at each end and
    the central cell |x| <= cell / 2."""
    c = np.cumsum(np.clip(lsf, 0.0, None))
    step = x[1] - x[0]
    lo, hi = -cell / 2 - step, cell / 2 + step
    if c[-1] > 0:
        c = c / c[-1]
        lo = min(lo, x[max(int(np.searchsorted(c, tail)) - 1, 0)])
        hi = max(hi, x[min(int(np.searchsorted(c, 1 - tail)) + 1, x.size - 1)])
    i0 = max(int(np.floor((lo - x[0]) / step)), 0)
    i1 = min(int(np.ceil((hi - x[0]) / step)) + 1, x.size)
    return slice(i0, i1)


def expected_seconds(design: Design, sampling: WaveSampling, z_max_mm: float, n_heights: int):
    """What a CPU run of :func:`wave_maps_2d` will take at one wavelength, from the grids
    alone: {"stack_s", "height_s", "total_s"} (CPU-seconds), scaled from the circular
    prototype's measured figures (:data:`CPU_S_PER_STACK_POINT`,
    :data:`CPU_S_PER_MODE_POINT`) by the operator grid's and the object grid's points and
    by the number of modes, which the range finder finds as it goes: estimated as the
    prototype's 86 times sqrt(source points / 39^2) (measured: 86 modes at 39 x 39
    points, 29 at 13 x 13, 35 at 14 x 14)."""
    px, py = stack_axes(design, reach_um=0.0, bounds=True)
    top = px.heights[-1]
    xs, ys = stack_grid(px.source, top, sampling), stack_grid(py.source, top, sampling)
    d_max = px.reduced(float(z_max_mm)) - top
    nx, ny = object_grid(xs, d_max, sampling)[0].size, object_grid(ys, d_max, sampling)[0].size
    lam, band = sampling.wavelength_um, sampling.band
    gx, gy = operator_grid(xs, lam, band), operator_grid(ys, lam, band)
    stack = CPU_S_PER_STACK_POINT * gx.size * gy.size
    modes = PROTOTYPE_MODES * math.sqrt(math.prod(sampling.source_points)) / PROTOTYPE_POINTS
    height = CPU_S_PER_MODE_POINT * modes * nx * ny
    return {"stack_s": stack, "height_s": height, "total_s": stack + (n_heights + 1) * height}


def wave_maps_2d(
    design: Design,
    z_mm=(0.0, 1.0),
    *,
    pixel: tuple[int, int] = (0, 0),
    sampling: WaveSampling | None = None,
    cell_um: float | None = None,
    fresnel: bool = False,
    propagator: str = "exact",
    tol: float = RANGE_TOL,
    seed: int = 0,
    device: str | None = None,
    precision: str = "single",
    tail: float = MAP_TAIL,
    bar=None,
) -> MapResponse:
    """Responsivity of a used pixel on the object plane at each Z by the 2-D path, with
    maps: :class:`MapResponse` (the separable :func:`~.wave.wave_response`'s figures for
    any hole shape).

    Parameters
    ----------
    design, z_mm, pixel, sampling, cell_um, fresnel : as :func:`~.wave.wave_response`
    propagator, tol, seed, device, precision : the stack's (:func:`~.wave2d.stack_modes`:
        "exact" angular spectrum or "paraxial" for checks; the range finder's tolerance
        and seed; "cpu" or "cuda", None the run's; "single" or "double" FFTs)
    tail : share of each line-spread function left outside a height's window at each end
    bar : a tqdm bar to advance by one per height (fractions as the modes go), or None
    """
    zs = checked_heights(z_mm)
    smp = wave_sampling(design) if sampling is None else sampling
    cell = output_pitch(design) if cell_um is None else float(cell_um)
    t0 = time.perf_counter()
    with one_blas_thread():
        if bar is not None:
            bar.set_postfix_str(f"stack at {smp.wavelength_um:.3f} µm")
        sm = stack_modes(
            design,
            pixel=pixel,
            sampling=smp,
            propagator=propagator,
            tol=tol,
            seed=seed,
            device=device,
            fresnel=fresnel,
            precision=precision,
        )
        sm.bk.sync()
        t1 = time.perf_counter()
        ux, light = marginal_modes(sm, 0, smp.mode_tol)
        uy, light_y = marginal_modes(sm, 1, smp.mode_tol)
        uy = uy / np.sqrt(max(light_y, 1e-300))  # unit power: LSF_y = light Y(y)
        planes = stack_axes(design, pixel, reach_um=0.0, bounds=True)
        st = sm.stack
        side = object_side([()], {(): (ux, uy)}, planes, [st.x, st.y], smp, float(zs.max()))
        lsf_x, lsf_y, etendue, _ = responses_at(side, zs, cell)  # its cells: a product
        gx, gy = side.grids
        wins = [
            (_window(gx, lsf_x[i], cell, tail), _window(gy, lsf_y[i], cell, tail))
            for i in range(zs.size)
        ]
        if bar is not None:
            bar.set_postfix_str(f"maps at {smp.wavelength_um:.3f} µm, {sm.modes.shape[0]} modes")
        t2 = time.perf_counter()
        inten = _intensities(sm, side, zs, wins, precision, bar)
        t3 = time.perf_counter()
    windows, cells = [], np.zeros(zs.size)
    cw = [cell_weights(g, cell) for g in (gx, gy)]  # exact: the band is below Nyquist
    for i, (wx, wy) in enumerate(wins):
        x, y = gx[wx], gy[wy]
        inside = float(cw[1][wy] @ inten[i].astype(np.float64) @ cw[0][wx])  # ~0 beyond
        cells[i] = inside / etendue[i] if etendue[i] > 0 else 0.0
        windows.append((x, y, inten[i]))
    info = sm.info
    budget = [
        {
            "mask": len(sm.layers) - 1,
            "transmitted": info["in_band"] + info["lost_to_band"],
            "in_band": info["in_band"],
            "lost_to_band": info["lost_to_band"],
            "lost_to_band_se": info["lost_to_band_se"],
        }
    ]
    meta = {"path": "2d", "propagator": propagator, "object_side": "paraxial", "cell_um": cell}
    meta |= {"device": sm.bk.name, "precision": precision, "tail": tail}
    meta |= {
        "grid": (st.y.size, st.x.size),
        "object_grid": (side.grids[1].size, side.grids[0].size),
    }
    meta |= {k: info[k] for k in ("range", "modes", "blocks", "missing_estimate")}
    meta["seconds"] = {"stack": t1 - t0, "marginals": t2 - t1, "maps": t3 - t2}
    if sm.note:
        meta["note"] = sm.note
    return MapResponse(
        design.name,
        design.fingerprint(),
        pixel_record(design, pixel),
        zs,
        side.grids[0],
        side.grids[1],
        lsf_x,
        lsf_y,
        etendue,
        cells,
        budget,
        smp,
        windows,
        meta,
    )


def _intensities(sm: StackModes, side, zs: np.ndarray, wins, precision: str, bar) -> list:
    """sum_m |u_m(X, Y; Z)|^2 on each height's window (host arrays, um^2 sr per um^2, in
    the precision's real type: float32 sums of 86 modes are good to ~1e-7):
    each mode's spectrum on the object grid once (pruned transforms), then at each Z the
    paraxial transfer function, back along y on the in-band columns and along x on the
    window's rows. The transforms run in place in work arrays made once (a fresh array
    of the largest window, up to 290 MB at 4.5 mm, was page-faulted in anew for each
    mode and height: 0.7 s against 0.1 s for its transform), and |u|^2 is added in one
    pass (:meth:`~.arrays.Backend.add_abs2`)."""
    st, bk, xp = sm.stack, sm.bk, sm.bk.xp
    cdt, rdt = PRECISIONS[precision]
    smp = sm.sampling
    (xf, yf), step = side.grids, smp.step_um
    ox = int(round((st.x[0] - xf[0]) / step))
    oy = int(round((st.y[0] - yf[0]) / step))
    kx, ky = side.bins[0] % xf.size, side.bins[1] % yf.size  # in-band bins
    runs = in_band_runs(kx, xf.size)  # the in-band columns (FFT order) as two runs
    hx = [bk.put(side.transfer(0, float(z)).astype(cdt)) for z in zs]
    hy = [bk.put(side.transfer(1, float(z)).astype(cdt)) for z in zs]
    ky_d = bk.put(ky)
    rows = xp.zeros((st.y.size, xf.size), dtype=cdt)  # the stack's rows on the object grid
    cols = xp.zeros((yf.size, kx.size), dtype=cdt)  # in-band columns: the stack's rows
    back = xp.zeros((yf.size, kx.size), dtype=cdt)  # in-band columns: the in-band rows
    n_wy = max(wy.stop - wy.start for _, wy in wins)
    work = xp.empty((n_wy, xf.size), dtype=cdt)  # a window's rows, transformed in place
    tall = xp.empty((yf.size, kx.size), dtype=cdt)  # back, transformed in place
    acc = [xp.zeros((wy.stop - wy.start, wx.stop - wx.start), dtype=rdt) for wx, wy in wins]
    n_modes = sm.modes.shape[0]
    for m in sm.modes:
        rows[:, :ox] = 0  # (the transform in place wrote there)
        rows[:, ox : ox + st.x.size] = st.field(m)
        rows[:, ox + st.x.size :] = 0
        r = bk.fft(rows, axis=-1, overwrite=True)
        gather_bins(xp, r, runs, -1, out=cols[oy : oy + st.y.size])
        tall[...] = cols
        spec = bk.fft(tall, axis=0, overwrite=True)[ky_d]  # (ny_in, nx_in)
        for i, (wx, wy) in enumerate(wins):
            back[ky_d] = spec * hy[i][:, None] * hx[i][None, :]
            tall[...] = back
            b = bk.ifft(tall, axis=0, overwrite=True)[wy]  # the window's rows, in band
            w = scatter_bins(xp, b, runs, xf.size, -1, out=work[: wy.stop - wy.start])
            bk.add_abs2(acc[i], bk.ifft(w, axis=-1, overwrite=True)[:, wx])
        if bar is not None:
            bar.update(zs.size / n_modes)
    return [bk.host(a) for a in acc]
