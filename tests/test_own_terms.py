"""Every analysis on its design's own terms: nothing of the paper's 300-dpi prototype is
baked into generic code.

The check is geometric similarity. Scaling every length of a design by k (pitches, holes,
slabs, the gap) and the object distance Z by k maps each traced ray onto a ray of the
original with the same direction, so the counter-based generator makes the same rays:
etendues scale by k^2 exactly, distances by k, fractions stay. Anything left on the
prototype's 84.6 um grid (spot cell, ghost landing bins, efficiency reference pixel,
diffraction slit) breaks the similarity and fails here.
"""

from __future__ import annotations

import numpy as np
import pytest

from opticalstamp.analysis.diffraction import design_slit_case
from opticalstamp.analysis.efficiency import efficiency, reference_etendue
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.spots import spots
from opticalstamp.design import load_design, replace, scale_to_dpi, with_stack
from opticalstamp.raytrace.stack import output_pitch
from opticalstamp.units import dpi_of_pitch

K = (0.5, 1.5)  # 600 dpi and 200 dpi
RAYS = 1 << 20


def scaled(design, k: float):
    """Every length of ``design`` times k."""
    s = design.sensor
    changes = {
        f"sensor.{f}": getattr(s, f) * k
        for f in (
            "pixel_pitch_um",
            "sensitive_width_um",
            "sensitive_height_um",
            "row_pitch_um",
            "row_b_offset_x_um",
            "row_b_offset_y_um",
        )
    }
    for i, sl in enumerate(design.slabs):
        changes[f"slabs.{i}.thickness_um"] = sl.thickness_um * k
        if sl.mask_top is not None:
            changes[f"slabs.{i}.mask_top.size_um"] = sl.mask_top.size_um * k
    changes["reference_gap.thickness_um"] = design.reference_gap.thickness_um * k
    changes["sensor.pixels_per_row"] = s.n_per_row  # the same lattice, k times smaller
    return replace(design, changes)


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


@pytest.mark.parametrize("k", K)
def test_ghosts_scale_with_the_design(paper, k):
    d = scaled(paper, k)
    assert output_pitch(d) == pytest.approx(84.6 * k)
    a = analyse_ghosts(paper, z_mm=(0.0, 2.0), n_rays=RAYS)
    b = analyse_ghosts(d, z_mm=(0.0, 2.0 * k), n_rays=RAYS)
    assert b.etendue_own_um2sr == pytest.approx(a.etendue_own_um2sr * k * k, rel=1e-9)
    assert b.ghost_fraction == pytest.approx(a.ghost_fraction, rel=1e-9)
    for za, zb in (("0", "0"), ("2", f"{2.0 * k:g}")):
        la, lb = a.landing[za], b.landing[zb]
        assert lb["bin_um"] == pytest.approx(output_pitch(d))
        # the same histogram: landing distances counted in the design's own pixels
        ha = np.asarray(la["etendue_by_distance_um2sr"]) * k * k
        np.testing.assert_allclose(lb["etendue_by_distance_um2sr"], ha, rtol=1e-6, atol=1e-12)
        assert lb["nearest_um"] == pytest.approx(la["nearest_um"] * k, rel=1e-9)


@pytest.mark.parametrize("k", K)
def test_spots_use_the_designs_cell(paper, k):
    d = scaled(paper, k)
    a = spots(paper, z_mm=(1.0,), n_rays=RAYS, bin_um=4.0)
    b = spots(d, z_mm=(1.0 * k,), n_rays=RAYS, bin_um=4.0 * k)
    assert b.meta["cell_um"] == pytest.approx(84.6 * k)
    sa, sb = a.spots[0], b.spots[0]
    assert sb.center_cell_fraction == pytest.approx(sa.center_cell_fraction, rel=1e-9)
    assert sb.extent_x_um == pytest.approx(sa.extent_x_um * k, rel=1e-9)


@pytest.mark.parametrize("k", K)
def test_efficiency_reference_pixel_is_the_output_pixel(paper, k):
    d = scaled(paper, k)
    a = efficiency(paper, area_scales=(1.0,))
    b = efficiency(d, area_scales=(1.0,))
    assert b.meta["reference_lens"]["pixel_um"] == pytest.approx(84.6 * k)
    assert b.reference_etendue_um2sr == pytest.approx(reference_etendue(84.6 * k))
    # a similar stack against a lens pixel of its own size: the same light efficiency
    # (the lens's projected solid angle is nearly uniform over a pixel this small)
    assert b.ratio == pytest.approx(a.ratio, rel=0.01)


def test_diffraction_slit_is_the_designs_object_side_hole(paper):
    d = with_stack(paper, holes_um=(52.0, 40.0, 36.0))  # object side first
    r = design_slit_case(d, z_mm=1.0)
    assert r.slit_um == 52.0
    assert r.r1_um == pytest.approx(1000.0 + 1000.0)
    assert r.r2_um == pytest.approx(1000.0 / 1.52)
    half = design_slit_case(scaled(paper, 0.5), z_mm=0.5)
    assert half.slit_um == pytest.approx(24.0) and half.r1_um == pytest.approx(1000.0)


def test_search_resolution_follows_the_design(paper):
    d600 = scale_to_dpi(paper, 600)
    # 25.4 mm / 600 on the artwork's 1-nm grid (scale_to_dpi): 600.0047 dpi
    assert dpi_of_pitch(output_pitch(d600)) == pytest.approx(600.0, rel=1e-4)
    assert output_pitch(d600) == 42.333


def test_the_study_row_that_is_the_design_shows_the_headline_numbers(paper):
    from opticalstamp.analysis.paper_study import parameter_study
    from opticalstamp.analysis.rmtf import rmtf

    own = {
        "hole_shape": ("square",),
        "sensitive_um": (42.3,),
        "gap_medium": ("air",),
        "fresnel": (False,),
        "glass_index": (1.52,),
    }
    g = analyse_ghosts(paper, n_rays=RAYS)
    r = rmtf(paper, dpi=(200.0,), n_rays=RAYS)
    st = parameter_study(
        paper, factors=own, n_rays=1 << 16, known={(paper.fingerprint(), False): (g, r)}
    )
    (row,) = st.rows
    assert row["source"] == "headline"
    assert row["dof_mm"] == r.dof_mm["200"] and row["ghost_fraction"] == g.ghost_fraction
    (fresh,) = parameter_study(paper, factors=own, n_rays=1 << 16).rows
    assert fresh["source"] == "study" and fresh["dof_mm"] != row["dof_mm"]


def test_with_headline_replaces_only_the_designs_own_row(paper):
    from opticalstamp.analysis.paper_study import parameter_study, with_headline
    from opticalstamp.analysis.rmtf import rmtf

    factors = {
        "hole_shape": ("square",),
        "sensitive_um": (42.3, 32.0),
        "gap_medium": ("air",),
        "fresnel": (False,),
        "glass_index": (1.52,),
    }
    st = parameter_study(paper, factors=factors, n_rays=1 << 16)
    g = analyse_ghosts(paper, n_rays=RAYS)
    r = rmtf(paper, dpi=(200.0,), n_rays=RAYS)
    new = with_headline(st, paper, g, r, fresnel=False)
    own, other = new.rows
    assert own["source"] == "headline" and own["dof_mm"] == r.dof_mm["200"]
    assert other == st.rows[1]  # 32 um sensitive area: another design, left as it was
    assert with_headline(st, paper, g, r, fresnel=True).rows == st.rows
