"""Reciprocity (DESIGN.md section 3): forward and reverse tracing give the same etendue.

The etendue between a pixel's sensitive area and a small object square at distance Z,
through the stack, is estimated twice: by reverse tracing from the pixel (paper Fig. 4's
virtual source) and counting rays that land in the square, and by forward tracing from the
square (paper Fig. 10's direction) and counting rays that land on the pixel.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from helpers import Tally, assert_agree, preset_dict
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.spots import spots
from opticalstamp.design import design_from_dict, load_design
from opticalstamp.raytrace.launch import launch
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.sampling import Source
from opticalstamp.raytrace.stack import forward_path, pixel_center, reverse_path
from opticalstamp.raytrace.tally import is_own_path, object_plane

Z_UM = 1000.0
SIDE_UM = 20.0


def reverse_estimate(design, pixel, x0, y0, z_um=Z_UM, n_rays=1 << 23, seed=21):
    """(all paths, own path) etendue from pixel to the square, by reverse tracing."""
    path = reverse_path(design)
    row, k = pixel
    every, own_t = Tally(), Tally()
    for b in launch(path, pixel_source(design, row, k), n_rays, seed):
        xo, yo = object_plane(b, z_um, design.index(design.object_medium))
        inside = (np.abs(xo - x0) <= SIDE_UM / 2) & (np.abs(yo - y0) <= SIDE_UM / 2)
        every.add(b.w[inside], b.n_samples)
        own_t.add(b.w[inside & (is_own_path(b, row, k))], b.n_samples)
    return every, own_t


def forward_estimate(design, pixel, x0, y0, importance, n_rays, z_um=Z_UM, seed=22):
    """(any holes, the pixel's own holes) etendue from the square to the pixel, forward."""
    path = forward_path(design, z_um)
    row, k = pixel
    cx, cy = pixel_center(design, row, k)
    s = design.sensor
    every, own_t = Tally(), Tally()
    for b in launch(path, Source(x0, y0, SIDE_UM, SIDE_UM), n_rays, seed, importance=importance):
        on = (np.abs(b.x - cx) <= s.sensitive_width_um / 2) & (
            np.abs(b.y - cy) <= s.sensitive_height_um / 2
        )
        own = np.all((b.hole_row == row) & (b.hole_k == k), axis=1)
        every.add(b.w[on], b.n_samples)
        own_t.add(b.w[on & own], b.n_samples)
    return every, own_t


def design_named(name: str):
    """A preset, or ``<preset>+pmma``: its reference gap filled by a PMMA light-guide plate."""
    if name.endswith("+pmma"):
        data = preset_dict(name.removesuffix("+pmma"))
        data["reference_gap"]["medium"] = "PMMA"
        return design_from_dict(data)
    return load_design(name)


@functools.cache
def reverse_for(name, pixel, x0, y0, z_um):
    """Reverse estimates, shared by the importance and plain forward runs of one case."""
    return reverse_estimate(design_named(name), pixel, x0, y0, z_um)


CASES = [
    ("paper2016", (0, 0), 0.0, 0.0, Z_UM),  # on the pixel's axis
    ("paper2016", (0, 0), 60.0, 0.0, Z_UM),  # off axis, in the spot's shoulder
    ("paper2016", (0, 0), 30.0, -20.0, Z_UM),
    ("paper2016", (1, 0), 84.6 + 25.0, 84.6 + 10.0, Z_UM),  # a row-B pixel
    ("paper2016", (0, 0), 30.0, 10.0, 0.0),  # object on the reference plane (Z = 0)
    # the prototype's 1 mm reference gap is a light-guide plate (paper section 4): light
    # refracts at the reference plane
    ("paper2016+pmma", (0, 0), 60.0, 0.0, Z_UM),
    ("fig1b", (0, 0), 0.0, 0.0, Z_UM),
    ("fig1b", (0, 0), 60.0, 0.0, Z_UM),  # one layer (paper Fig. 1(b)), off axis
]


@pytest.mark.parametrize("importance", [True, False], ids=["importance", "plain"])
@pytest.mark.parametrize(("name", "pixel", "x0", "y0", "z_um"), CASES)
def test_forward_equals_reverse(name, pixel, x0, y0, z_um, importance):
    design = design_named(name)
    rev_all, rev_own = reverse_for(name, pixel, x0, y0, z_um)
    n_fwd = 1 << 21 if importance else 1 << 26
    fwd_all, fwd_own = forward_estimate(design, pixel, x0, y0, importance, n_fwd, z_um)
    assert rev_all.value > 0 and fwd_all.value > 0
    assert_agree(rev_all.value, rev_all.se, fwd_all.value, fwd_all.se)
    assert_agree(rev_own.value, rev_own.se, fwd_own.value, fwd_own.se)


def test_ghost_light_reaches_the_pixel_through_foreign_holes():
    # fig1b (one layer, paper Fig. 1(b)): an object square 127 um off axis reaches pixel A0
    # only through other pixels' holes; forward and reverse agree on that ghost light too.
    design = load_design("fig1b")
    rev_all, rev_own = reverse_estimate(design, (0, 0), 127.0, 0.0)
    fwd_all, fwd_own = forward_estimate(design, (0, 0), 127.0, 0.0, True, 1 << 21)
    assert rev_own.value == fwd_own.value == 0.0
    assert rev_all.value > 10 * rev_all.se
    assert_agree(rev_all.value, rev_all.se, fwd_all.value, fwd_all.se)


def test_spot_map_integrates_to_the_own_path_etendue():
    # the responsivity map (paper Fig. 5) is etendue per object area: its integral over the
    # object plane is the pixel's own-path etendue at every Z; spots and analyse_ghosts
    # trace the same rays for the same seed, so the two must match to rounding
    design = load_design("paper2016")
    sp = spots(design, z_mm=(0.0, 2.0), n_rays=1 << 20, seed=5, ghosts=False)
    g = analyse_ghosts(design, n_rays=1 << 20, seed=5)
    for s in sp.spots:
        cell = np.diff(s.x_edges_um)[0] * np.diff(s.y_edges_um)[0]
        assert s.map_sr.sum() * cell == pytest.approx(g.etendue_own_um2sr, rel=1e-9)
