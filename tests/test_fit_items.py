"""The fit's nuisance parameters item by item (issue 24's speed): each bar block's and edge
region's four parameters move its own data only, so the image's nuisance least squares
is block-diagonal. Checked against the image-wide problem it replaced: the same minimum,
and the Jacobian's nuisance columns the same bits as image-wide forward differences.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy.optimize import least_squares

from opticalstamp.design import load_design
from opticalstamp.imaging.charts import bar_chart, edge_chart
from opticalstamp.imaging.scan import prepare_kernels, simulate_scan
from opticalstamp.studies.fitdata import observation
from opticalstamp.studies.fitproblem import Problem, fit_items, layout_for, nuisance_start

DESIGN = load_design("paper2016")


@functools.cache
def _problem() -> tuple[Problem, np.ndarray]:
    """Bars at 1.5 mm and an edge at 2 mm, scanned with the nominal design (ray kernels,
    no ghost light), the fast model's problem at nominal with each image's starting
    nuisance."""
    kc = prepare_kernels(DESIGN, z_mm=[1.5, 2.0], ghosts=False, seed=3)
    obs = []
    for name, doc, dpi, z in (
        ("bars", bar_chart(2400.0, supersample=16), 2400.0, 1.5),
        ("edge", edge_chart(2400.0), 2400.0, 2.0),
    ):
        r = simulate_scan(doc, dpi, DESIGN, z_mm=z, seed=3, kernels=kc, ghosts=False)
        obs.append(observation(r.image, r.dpi, z, name=name))
    lay = layout_for(DESIGN, obs)
    prob = Problem(DESIGN, obs, lay)
    n_nu = sum(sl.stop - sl.start for sl, _ in lay.nuis)
    theta = np.concatenate([lay.fixed[list(lay.free)], np.zeros(n_nu)])
    for o, (sl, _) in zip(obs, lay.nuis, strict=True):
        theta[sl] = nuisance_start(o)
    return prob, theta


@pytest.mark.parametrize("i", [0, 1], ids=["bars", "edge"])
def test_items_reach_the_image_wide_minimum(i):
    """Per item (exact level columns, forward differences for the rest) the image's
    nuisance reaches the minimum of the image-wide least squares (scipy's 2-point
    differences over all its parameters at once), to 1e-6 of its sum of squares."""
    prob, theta = _problem()
    sl, _ = prob.lay.nuis[i]
    lo, hi = prob.bounds()
    sp = prob.spreads(prob.lay.physical(theta))[i]

    def res(nu):
        t = theta.copy()
        t[sl] = nu
        return prob.residual_of(i, sp, t)

    nu0 = np.clip(theta[sl], lo[sl] + 1e-9, hi[sl] - 1e-9)
    joint = least_squares(res, nu0, bounds=(lo[sl], hi[sl]), x_scale="jac", ftol=1e-12).x
    items = fit_items(prob.obs[i], sp, theta[sl], lo[sl], hi[sl], prob.steps(theta)[sl])
    start, want, got = (float(np.sum(res(v) ** 2)) for v in (nu0, joint, items))
    assert got < start
    assert got == pytest.approx(want, rel=1e-6)
    level = [n.rsplit(".", 1)[1] for n in prob.lay.nuis[i][1]]
    for k, name in enumerate(level):  # the levels, well determined, agree closely
        if name in ("black", "white"):
            assert items[k] == pytest.approx(joint[k], abs=1e-4)


def test_nuisance_columns_are_the_image_wide_differences_bit_for_bit():
    """The Jacobian's phase/pos and period/slope columns, now computed on their own
    item's rows, are the bits of the image-wide forward difference (the other items'
    rows exactly 0); the level columns exact as before."""
    prob, theta = _problem()
    theta = prob.fit_nuisance(theta)
    jac = prob.jacobian(theta)
    r0 = prob.residuals(theta)
    sps = prob.spreads(prob.lay.physical(theta))
    h = prob.steps(theta)
    start = 0
    checked = 0
    for i, (sl, names) in enumerate(prob.lay.nuis):
        size = prob.data[i][0].size
        for k, name in zip(range(sl.start, sl.stop), names, strict=True):
            if name.endswith("black") or name.endswith("white"):
                continue
            t = theta.copy()
            t[k] += h[k]
            want = (prob.residual_of(i, sps[i], t) - r0[start : start + size]) / h[k]
            assert np.array_equal(jac[start : start + size, k], want), name
            assert not np.any(jac[:start, k]) and not np.any(jac[start + size :, k])
            checked += 1
        start += size
    assert checked >= 4
