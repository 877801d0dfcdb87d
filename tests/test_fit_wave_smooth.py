"""The wave fit's model has no steps (issue 24): the wave engine's grids are FFT lengths
that grow by a step as a design's lengths move the band's reach, which moves the figures
by ~1e-6 of the light, tens of chi2 at the charts' noise. The fit holds every grid at its
nominal design's sizes (``held_sampling``) and each height's spread on one table
(``WaveModel.held``)."""

from __future__ import annotations

import numpy as np

from opticalstamp.analysis.responsivity import resolve_optics
from opticalstamp.analysis.wavebase import grid_points
from opticalstamp.design import load_design
from opticalstamp.design.variants import replace
from opticalstamp.studies.fitmodel import smear_of
from opticalstamp.studies.fitwave import WaveModel, held_sampling

PAPER = load_design("paper2016")
Z = [0.5]


def _slab2(t: float):
    return replace(PAPER, {"slabs.1.thickness_um": float(t)})


def _step_in_grids(smp) -> float:
    """A slab-2 thickness (um) where the unheld grids change size, to 0.01 um."""
    base = grid_points(PAPER, Z[0], smp)
    for t in np.arange(400.0, 300.0, -1.0):
        if grid_points(_slab2(t), Z[0], smp) != base:
            lo, hi = t, t + 1.0
            while hi - lo > 0.01:
                mid = (lo + hi) / 2
                lo, hi = (mid, hi) if grid_points(_slab2(mid), Z[0], smp) != base else (lo, mid)
            return (lo + hi) / 2
    raise AssertionError("no grid step within 100 um of slab 2")


def _second_differences(model: WaveModel, ts) -> np.ndarray:
    """max |second difference| of the x and y cumulatives over the thicknesses ``ts``."""
    smear = smear_of(PAPER)
    sp = [model(_slab2(t), Z, smear)[Z[0]] for t in ts]
    n = min((s.u.size - 1) // 2 for s in sp)
    cut = [
        np.concatenate(
            [
                s.cx[(s.u.size - 1) // 2 - n :][: 2 * n + 1],
                s.cy[(s.u.size - 1) // 2 - n :][: 2 * n + 1],
            ]
        )
        for s in sp
    ]
    return np.abs(np.diff(np.array(cut), 2, axis=0)).max(axis=1)


def test_held_grids_do_not_change_size_and_the_model_has_no_step():
    smp = resolve_optics(PAPER, "wave").sampling
    t0 = _step_in_grids(smp)
    ts = t0 + np.array([-0.15, -0.05, 0.05, 0.15])  # the step between the middle two
    held = held_sampling(PAPER, smp, Z[0])
    sizes = {grid_points(_slab2(t), Z[0], held) for t in ts}
    assert len(sizes) == 1  # held: one size on both sides of the step
    assert len({grid_points(_slab2(t), Z[0], smp) for t in ts}) == 2  # unheld: two
    smooth = _second_differences(WaveModel(held).held(PAPER, Z, smear_of(PAPER)), ts)
    steppy = _second_differences(WaveModel(smp), ts)
    # a change of 0.1 um of a slab moves the spreads by ~1e-6 and their second
    # differences by ~1e-9; the unheld grids' step is far larger
    assert smooth.max() < 0.1 * steppy.max(), (smooth, steppy)  # 6e-9 against 3e-7
    assert smooth.max() < 5e-8, smooth
