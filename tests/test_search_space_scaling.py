"""The search space at another resolution (docs/search.md, "The space at any resolution"):
the paper's 300-dpi space carried by the two similarities of the stack, geometric
(every length times k: the aspect ratios, so the ray optics) and paraxial Fresnel
(lateral lengths times k, slabs times k^2: the Fresnel numbers, so the diffraction)."""

from __future__ import annotations

import math

import pytest

from opticalstamp.analysis.wavebase import fresnel_numbers
from opticalstamp.design import load_design, stack_params, with_stack
from opticalstamp.studies.search import search_base
from opticalstamp.studies.searchspace import (
    default_space,
    lateral_scale,
    scaled_slab_bounds,
)

BUDGET_UM = 2500.0


def paper():
    return load_design("paper2016")


def extremes(space, design):
    """The largest Fresnel number (a/2)^2 / (lambda d) and the largest and smallest aspect
    ratio d / a that the space's holes and slabs allow (d: the slab's thickness reduced
    to air, t / n, as :func:`fresnel_numbers` reduces it)."""
    lam = design.wavelength_um
    a_lo, a_hi = space.hole_bounds_um
    out = {"fresnel_max": 0.0, "aspect_max": 0.0, "aspect_min": math.inf}
    for (t_lo, t_hi), sl in zip(space.thickness_bounds_um, design.slabs, strict=True):
        n = float(design.index(sl.medium))
        out["fresnel_max"] = max(out["fresnel_max"], (a_hi / 2) ** 2 / (lam * t_lo / n))
        out["aspect_max"] = max(out["aspect_max"], t_hi / n / a_lo)
        out["aspect_min"] = min(out["aspect_min"], t_lo / n / a_hi)
    return out


def in_space(space, design) -> bool:
    p = stack_params(design)
    lo, hi = space.hole_bounds_um
    holes = all(lo <= h <= hi for h in p["holes_um"])
    slabs = all(
        b[0] - 1e-9 <= t <= b[1] + 1e-9
        for t, b in zip(p["thicknesses_um"], space.thickness_bounds_um, strict=True)
    )
    return holes and slabs


def test_at_300_dpi_the_space_is_the_papers():
    sp = default_space(paper(), BUDGET_UM)
    assert lateral_scale(paper()) == 1.0
    assert sp.hole_bounds_um == (10.0, 74.0)  # 84.6 um stagger - 10 um of wall
    assert sp.thickness_bounds_um == [(100.0, 2000.0)] * 3
    assert sp.thickness_step_um == 50.0
    d = paper()
    assert search_base(d, 300) is d  # searched as it is


@pytest.mark.parametrize("dpi", [600, 1200])
def test_at_high_dpi_no_slab_is_thinner_in_fresnel_number_nor_thicker_in_aspect(dpi):
    ref = default_space(paper(), BUDGET_UM)
    base = search_base(paper(), dpi)
    k = lateral_scale(base)
    assert k == pytest.approx(300 / dpi)
    sp = default_space(base, BUDGET_UM)
    got, was = extremes(sp, base), extremes(ref, paper())
    # the largest Fresnel number and aspect ratio stay within the paper's space
    assert got["fresnel_max"] <= was["fresnel_max"] * (1 + 1e-9)
    assert got["aspect_max"] <= was["aspect_max"] * (1 + 1e-9)
    # and reach them: the thin end is the Fresnel image of the paper's thinnest slab, the
    # thick end the geometric image of its thickest (within the 1-um hole grid)
    assert got["fresnel_max"] == pytest.approx(was["fresnel_max"], rel=0.1)
    assert got["aspect_max"] == pytest.approx(was["aspect_max"], rel=0.25)
    # the smallest aspect ratio is k times the paper's: the range spans both images
    assert got["aspect_min"] == pytest.approx(k * was["aspect_min"], rel=0.1)
    assert sp.thickness_bounds_um[0] == pytest.approx((100 * k * k, 2000 * k))
    assert sp.thickness_step_um == pytest.approx(50 * k * k)


@pytest.mark.parametrize("dpi", [600, 1200])
def test_the_space_admits_both_images_of_the_prototype(dpi):
    """The prototype with every length scaled (the search's base: its ray optics as at
    300 dpi) and with its slabs scaled by k^2 (its Fresnel numbers as at 300 dpi) are both
    in the space at ``dpi``; the prototype's plates kept (the space before this rule) are
    not at 1200 dpi, where its 1-mm plate is thicker in aspect than any slab of the
    paper's space."""
    base = search_base(paper(), dpi)
    k = lateral_scale(base)
    sp = default_space(base, BUDGET_UM)
    assert in_space(sp, base)
    p0 = stack_params(paper())
    assert stack_params(base)["thicknesses_um"] == pytest.approx(
        [t * k for t in p0["thicknesses_um"]]
    )
    assert base.reference_gap.thickness_um == pytest.approx(1000.0 * k)
    fresnel = with_stack(base, thicknesses_um=[t * k * k for t in p0["thicknesses_um"]])
    assert in_space(sp, fresnel)
    # the Fresnel image has the prototype's Fresnel numbers between its layers
    got = [f["fresnel_number"] for f in fresnel_numbers(fresnel)][:3]
    want = [f["fresnel_number"] for f in fresnel_numbers(paper())][:3]
    assert got == pytest.approx(want, rel=0.02)  # the holes on the 0.1-um grid
    # and the geometric image the prototype's aspect ratios everywhere
    ratios = [f["distance_um"] / f["hole_um"] for f in fresnel_numbers(base)]
    assert ratios == pytest.approx(
        [f["distance_um"] / f["hole_um"] for f in fresnel_numbers(paper())], rel=0.01
    )
    if dpi == 1200:
        plates = with_stack(base, thicknesses_um=p0["thicknesses_um"])
        assert not in_space(sp, plates)


def test_scaled_slab_bounds_both_ways_and_refuses_a_bad_scale():
    assert scaled_slab_bounds(1.0) == (100.0, 2000.0, 50.0)
    lo, hi, step = scaled_slab_bounds(0.25)
    assert (lo, hi, step) == pytest.approx((6.25, 500.0, 3.125))
    # towards lower resolution the geometric image is the thinner one
    assert scaled_slab_bounds(1.5) == pytest.approx((150.0, 4500.0, 75.0))
    for bad in (0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="k"):
            scaled_slab_bounds(bad)
