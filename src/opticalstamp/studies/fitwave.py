"""Wave optics in the fit (issue 24): the wave engine's responsivity as the forward model.

Where the other commands take wave optics for a design (``--optics auto``:
:func:`~opticalstamp.analysis.responsivity.resolve_optics`), the fit's spread of a pixel
at each height is the wave engine's (:func:`~opticalstamp.analysis.wavespectral.
spectral_marginals`, the design's light, at the nominal design's sampling for every
perturbed design, so that the grids and the band do not jump as the parameters move):
the light in its band, the own path with its diffraction and the near crosstalk, as the
x and y marginals (the y one smeared by the document's motion, as the fast model's), and
nothing else: no budget, no central-cell shares, each axis's line-spread function from
the leading coherent modes of its mutual intensity, to 1e-14 of the light.

One wave run (every height at once) costs about 0.3 s on the prototype, a hundred times
the fast model's; a multi-start search evaluates its model thousands of times. So the
search (starts and holds, :mod:`.fit`) runs on the fast model (:func:`~.fitmodel.spread`,
the paraxial own path) plus the wave model's difference from it about the nominal design,
to first order in the parameters (:class:`Corrected`: 1 + free wave runs), and the wave
model's own least squares takes its best minimum to the wave model's optimum
(:func:`~.fit._polish`), whose Jacobian gives the errors. (Repeating the correction about
each new point instead, a defect correction, converged poorly on the default free set: the
fast model's kinks, where two holes' shadow edges cross, make the difference nonlinear
over a step; the wave model itself is smooth.)

The model is smooth in the parameters only if nothing discrete moves with them: every
design is run at the nominal design's sampling with its grids held at one size
(:func:`held_sampling`; a grid that grew by one FFT length with a slab's thickness moved
the chi2 of the charts by ~50), and each height's spread is tabulated on one table
(:meth:`WaveModel.held`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..analysis.paraxial import OwnPath
from ..analysis.wavebase import WaveSampling, grid_points
from ..design import Design
from .fitmodel import SMEAR_SUBS, TABLE_UM, Param, Spread, spread, spreads, with_params

#: Light left beyond a wave spread's table on each side of each marginal: the table stops
#: where the cumulative reaches it, and is renormalised to 0..1 on its grid.
WAVE_TAIL = 1e-5
#: Step (assembly scales) of the forward differences of the wave model's correction.
STEP = 0.1
#: The fit's wave grids are held at this multiple of the nominal design's sizes ...
GRID_ROOM = 1.1
#: ... and its spreads' tables at this multiple of the nominal design's reach.
TABLE_ROOM = 1.25


def _cumulative(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Normalised cumulative trapezoid integral of the density ``p`` sampled on ``x``."""
    c = np.concatenate([[0.0], np.cumsum((p[1:] + p[:-1]) / 2)]) * (x[1] - x[0])
    if not c[-1] > 0:
        raise ValueError("no in-band light reaches the object plane")
    return c / c[-1]


def _reach(x: np.ndarray, c: np.ndarray, tail: float) -> float:
    """Half width about the axis beyond which at most ``tail`` of the light lies on each
    side."""
    lo = x[min(np.searchsorted(c, tail), x.size - 1)]
    hi = x[min(np.searchsorted(c, 1 - tail), x.size - 1)]
    return float(max(-lo, hi))


def wave_spread(
    x_um: np.ndarray,
    lsf_x: np.ndarray,
    y_um: np.ndarray,
    lsf_y: np.ndarray,
    smear_um: float,
    reach_um: float = 0.0,
) -> Spread:
    """A :class:`~.fitmodel.Spread` from the wave engine's marginals at one height: on the
    fast model's fixed grid (k ``TABLE_UM``) out to where all but ``WAVE_TAIL`` of the
    light lies on each side, or ``reach_um`` if wider; along y smeared over ``smear_um``
    (``SMEAR_SUBS`` sub-positions, as :func:`~.fitmodel.spread`)."""
    cxw, cyw = _cumulative(x_um, lsf_x), _cumulative(y_um, lsf_y)
    half = max(_reach(x_um, cxw, WAVE_TAIL), _reach(y_um, cyw, WAVE_TAIL) + smear_um / 2)
    n = max(math.ceil((half + 2 * TABLE_UM) / TABLE_UM), math.ceil(reach_um / TABLE_UM))
    u = np.arange(-n, n + 1) * TABLE_UM
    cx = np.interp(u, x_um, cxw)
    subs = ((np.arange(SMEAR_SUBS) + 0.5) / SMEAR_SUBS - 0.5) * smear_um
    cy = np.mean([np.interp(u + s, y_um, cyw) for s in subs], axis=0)
    cx = (cx - cx[0]) / (cx[-1] - cx[0])
    cy = (cy - cy[0]) / (cy[-1] - cy[0])
    return Spread(u, cx, cy, n * TABLE_UM)


def held_sampling(design: Design, sampling: WaveSampling, z_max_mm: float) -> WaveSampling:
    """``sampling`` with every grid of every wavelength of ``design``'s light held at
    GRID_ROOM x the largest size that ``design`` needs up to ``z_max_mm``
    (:meth:`~opticalstamp.analysis.wavebase.WaveSampling.held`): a grid that changed size
    as the fit's parameters move would make the model jump (by ~1e-6 of the light, tens
    of chi2 at the charts' noise)."""
    from ..analysis.spectrum import one_channel
    from ..analysis.wavespectral import at_wavelength, spectral_samplings

    spec = one_channel(design, None)
    sizes = [
        grid_points(at_wavelength(design, lam), z_max_mm, s)
        for lam, s in zip(
            spec.wavelengths_um, spectral_samplings(design, spec, sampling), strict=True
        )
    ]
    return sampling.held(*(math.ceil(GRID_ROOM * max(n)) for n in zip(*sizes, strict=True)))


@dataclass(frozen=True)
class WaveModel:
    """The wave engine as the fit's forward model: (design, heights, smear) -> {Z:
    spread}, every design at one ``sampling`` (the nominal design's, its grids held:
    :func:`held_sampling`) and, once :meth:`held` has fixed them, each height's spread on
    one table (``reach_um``: {Z: half width}) whatever the design: a table that followed
    each design's tails would renormalise the spread by a step as it grows."""

    sampling: WaveSampling
    reach_um: dict = field(default_factory=dict)

    def __call__(self, design: Design, zs, smear_um: float, phys=None) -> dict[float, Spread]:
        from ..analysis.wavespectral import spectral_marginals

        zs = [float(z) for z in zs]
        x, lx, y, ly, _ = spectral_marginals(design, zs, sampling=self.sampling)
        return {
            z: wave_spread(x, lx[i], y, ly[i], smear_um, self.reach_um.get(z, 0.0))
            for i, z in enumerate(zs)
        }

    def held(self, design: Design, zs, smear_um: float) -> WaveModel:
        """This model with each height's table fixed at TABLE_ROOM x the reach of
        ``design``'s spread there (one run)."""
        sp = self(design, zs, smear_um)
        return replace(self, reach_um={z: TABLE_ROOM * s.half_um for z, s in sp.items()})

    def points(self, params: list[Param], phys: np.ndarray, free) -> list[np.ndarray]:
        """The physical values at which :meth:`correction` runs the wave model: ``phys``
        and a step of ``STEP`` assembly scales in each parameter of ``free`` (down where up
        would leave its bounds)."""
        at = np.asarray(phys, dtype=np.float64)
        out = [at]
        for j in free:
            p = params[j]
            out.append(at.copy())
            out[-1][j] += STEP * p.scale if at[j] + STEP * p.scale <= p.hi else -STEP * p.scale
        return out

    def correction(
        self,
        design: Design,
        params: list[Param],
        phys: np.ndarray,
        free,
        zs,
        smear_um: float,
        wave_at=None,
    ) -> Corrected:
        """The wave model minus the fast one at the physical values ``phys`` of
        ``design``'s ``params``, and its derivative in each parameter of ``free`` (forward
        differences of ``STEP`` assembly scales): 1 + len(free) wave runs (``wave_at``:
        physical values -> the wave model's spreads there, e.g. a memo of the runs made
        already; default a run each)."""
        zs = [float(z) for z in zs]
        at = np.asarray(phys, dtype=np.float64)
        points = self.points(params, at, free)
        steps = [(v - at)[j] for v, j in zip(points[1:], free, strict=True)]
        waves, fasts = [], []
        for v in points:
            d = with_params(design, params, v)
            waves.append(self(d, zs, smear_um) if wave_at is None else wave_at(v))
            fasts.append(spreads(d, zs, smear_um))
        table = {}
        for z in zs:
            n = max((x[z].u.size - 1) // 2 for x in waves + fasts)
            w = [x[z].widened(n) for x in waves]
            f = [x[z].widened(n) for x in fasts]
            base = (w[0].cx - f[0].cx, w[0].cy - f[0].cy)
            size = base[0].size
            sx, sy = np.zeros((len(steps), size)), np.zeros((len(steps), size))
            for k, (wk, fk, h) in enumerate(zip(w[1:], f[1:], steps, strict=True)):
                sx[k] = (wk.cx - w[0].cx - fk.cx + f[0].cx) / h
                sy[k] = (wk.cy - w[0].cy - fk.cy + f[0].cy) / h
            table[z] = (base, (sx, sy))
        return Corrected(table, at, tuple(free))


@dataclass(frozen=True)
class Corrected:
    """The fast model plus the wave model's difference from it, to first order about the
    physical values ``at``: at each height Z, ``table[Z]`` = ((dcx, dcy), (sx, sy)), the
    wave spread's cumulatives minus the fast one's at ``at`` and their derivatives in the
    parameters ``free`` (indices into the physical values; rows of ``sx``, ``sy``), on
    k ``TABLE_UM``, |k| <= n (0 at both ends: the cumulatives agree there, 0 and 1). At
    ``at`` its spreads and their derivatives are the wave model's."""

    table: dict
    at: np.ndarray
    free: tuple[int, ...]

    def __call__(self, design: Design, zs, smear_um: float, phys=None) -> dict[float, Spread]:
        dv = np.zeros(len(self.free)) if phys is None else (phys - self.at)[list(self.free)]
        out = {}
        own = OwnPath(design)
        for z in zs:
            (dcx, dcy), slopes = self.table[float(z)]
            n = (dcx.size - 1) // 2
            f = spread(design, float(z), smear_um, reach_um=n * TABLE_UM, own=own)
            dx, dy = dcx + dv @ slopes[0], dcy + dv @ slopes[1]
            o = (f.u.size - 1) // 2 - n  # the fast grid may reach further: 0 there
            cx, cy = f.cx.copy(), f.cy.copy()
            cx[o : o + dx.size] += dx
            cy[o : o + dy.size] += dy
            out[float(z)] = Spread(f.u, cx, cy, f.half_um)
        return out
