"""The ghost analysis where no ray carries ghost light: it stops on a stated bound.

Issue 21: the prototype with a 70-degree pixel acceptance has no ghost light (its ghost
paths leave the pixel at 73.7 degrees and more), and the ghost analysis ran to its ray
cap (2^27 rays) waiting for a relative standard error that a zero cannot have.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import preset_dict
from opticalstamp.analysis.ghosts import analyse_ghosts, ghost_ratio_bound
from opticalstamp.design import design_from_dict, load_design
from opticalstamp.raytrace.launch import launch
from opticalstamp.raytrace.pixel import PixelTracer
from opticalstamp.raytrace.sampling import Source, weight_bound


def _paper(acceptance: float | None = None, circle: bool = False, offset: float = 0.0):
    d = preset_dict("paper2016")
    if acceptance is not None:
        d["sensor"]["acceptance_half_angle_deg"] = acceptance
    for slab in d["slabs"]:
        if circle:
            slab["mask_top"]["shape"] = "circle"
        slab["mask_top"]["offset_x_um"] = offset
        offset = -offset / 2  # a different misregistration per mask
    return design_from_dict(d)


def test_rule_of_three():
    # none of n rays a ghost: p < 1 - 0.05^(1/n), about 3/n
    assert ghost_ratio_bound(1.0, 1000, 1.0) == pytest.approx(1 - 0.05**0.001, rel=1e-12)
    assert ghost_ratio_bound(2.0, 10**6, 4.0) == pytest.approx(-math.log(0.05) / 2e6, rel=1e-5)
    assert ghost_ratio_bound(1.0, 0, 1.0) == math.inf
    assert ghost_ratio_bound(1.0, 10, 0.0) == math.inf


@pytest.mark.parametrize(
    "design",
    [
        load_design("paper2016"),
        load_design("fig1b"),
        _paper(70.0),
        _paper(circle=True, offset=6.0),
    ],
    ids=["paper2016", "fig1b", "acceptance70", "circles-offset"],
)
def test_weight_bound_bounds_every_ray(design):
    """No traced ray, own or ghost, weighs more than :func:`weight_bound` (the premise of
    the rule-of-three bound), and the bound is not loose where rays reach it."""
    tr = PixelTracer(design)
    src = tr.source((0, 0))
    w_max = weight_bound(tr.path, src, tr.hole_weights((0, 0)), tr.s2_max)
    seen = max(pb.w.max(initial=0.0) for pb in tr.trace((0, 0), 1 << 20, stream=5))
    assert 0 < seen <= w_max
    if design.sensor.acceptance_half_angle_deg >= 90:  # every hole's rays are accepted
        assert seen > 0.5 * w_max


def test_weight_bound_geometric_table_and_point_source():
    d = load_design("paper2016")
    tr = PixelTracer(d)
    src = tr.source((0, 0))
    w_max = weight_bound(tr.path, src)
    seen = max(b.w.max(initial=0.0) for b in launch(tr.path, src, 1 << 19, 2))
    assert 0.5 * w_max < seen <= w_max
    pt = Source(src.x, src.y)  # a point: weights are fractions of its power
    w_pt = weight_bound(tr.path, pt)
    seen = max(b.w.max(initial=0.0) for b in launch(tr.path, pt, 1 << 18, 2))
    assert 0 < seen <= w_pt
    # a tiny acceptance cone: only the own hole's rays count
    assert 0 < weight_bound(tr.path, src, None, 1e-12) <= w_max


def test_no_ghost_light_stops_on_the_bound():
    """Issue 21's design: a few seconds (2^23 rays, set by the own path's precision, not
    2^27), a stated bound, no rows of zeros."""
    d = _paper(70.0)
    r = analyse_ghosts(d)
    assert r.n_rays == 1 << 23
    assert r.etendue_ghost_um2sr == 0.0 and r.ghost_fraction == 0.0
    assert r.etendue_own_se / r.etendue_own_um2sr <= 1e-3
    assert r.ghost_ratio_bound is not None and 0 < r.ghost_ratio_bound <= 1e-3
    assert r.paths == []  # hole sequences only unaccepted rays follow carry no light
    ds = r.to_dataset()
    assert ds.attrs["ghost_ratio_bound"] == r.ghost_ratio_bound
    # the bound at a fixed ray count is stated too, and shrinks as 1/n
    small = analyse_ghosts(d, n_rays=1 << 18)
    assert small.ghost_ratio_bound == pytest.approx(
        r.ghost_ratio_bound * 32 * r.etendue_own_um2sr / small.etendue_own_um2sr, rel=1e-3
    )


def test_bound_holds_where_ghost_light_is_faint():
    """At 73.8 degrees a little ghost light gets in (about 6e-5 of the own path's); a
    short run that sees none of it states a bound above it."""
    d = _paper(73.8)
    short = analyse_ghosts(d, n_rays=1 << 16)
    assert short.etendue_ghost_um2sr == 0.0
    long = analyse_ghosts(d, n_rays=1 << 23)
    assert long.etendue_ghost_um2sr > 0 and long.ghost_ratio_bound is None
    ratio = long.etendue_ghost_um2sr / long.etendue_own_um2sr
    assert short.ghost_ratio_bound > ratio + 3 * long.etendue_ghost_se / long.etendue_own_um2sr


def test_prototype_ghost_figures_unchanged():
    """Where ghost light is found the stopping rule is the one before issue 21: the
    prototype stops at 2^23 rays with the same figures (pinned from before the change)."""
    r = analyse_ghosts(load_design("paper2016"), z_mm=(0.0, 2.0))
    assert r.ghost_ratio_bound is None
    assert r.n_rays == 1 << 23
    assert len(r.paths) == 130
    np.testing.assert_allclose(
        [r.etendue_own_um2sr, r.etendue_ghost_um2sr, r.ghost_fraction],
        [2.126115126996726, 0.29866109674543534, 0.12317058119470965],
        rtol=1e-9,
    )


def test_command_prints_the_bound_not_rows_of_zeros(tmp_path):
    from typer.testing import CliRunner

    from opticalstamp.cli.common import app
    from opticalstamp.design.files import design_toml

    f = tmp_path / "a70.toml"
    f.write_text(design_toml(_paper(70.0)))
    res = CliRunner().invoke(app, ["ghosts", "-d", str(f), "--rays", "1048576"])
    assert res.exit_code == 0, res.output
    assert "no ghost light found: ghost/own < 0.0019 (95 % bound)" in res.stdout
    assert "ghost etendue" not in res.stdout and "sr  " not in res.stdout
