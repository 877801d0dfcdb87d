"""Derived designs (design/variants.py): the validated primitive ``replace`` and each named
variant against an explicit expected design; designs immutable and hashable."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from opticalstamp.design import (
    DesignError,
    design_from_dict,
    drop_mask,
    load_design,
    one_row,
    replace,
    scale_to_dpi,
    square_holes,
    stack_params,
    structural_variants,
    with_glass_index,
    with_hole_shape,
    with_layers,
    with_sensitive_area,
    with_stack,
    with_unstated,
)

#: The fingerprint of the paper2016 preset (a list of slabs before they became a tuple).
PAPER_FINGERPRINT = "bc4f1a6ca8a9"


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def paper_data(description: str) -> dict:
    """The paper2016 preset written out (a fresh dict each call, for the test to edit)."""
    return {
        "name": "paper2016",
        "description": description,
        "wavelength_um": 0.55,
        "object_medium": "air",
        "sensor": {
            "pixel_pitch_um": 42.3,
            "sensitive_width_um": 42.3,
            "sensitive_height_um": 42.3,
            "lines": 3,
            "rows": 2,
            "row_pitch_um": 169.2,
            "row_b_offset_x_um": 84.6,
            "row_b_offset_y_um": 84.6,
        },
        "slabs": [
            {
                "medium": "air",
                "thickness_um": 450.0,
                "mask_top": {"name": "layer 3", "shape": "square", "size_um": 40.0},
            },
            {
                "medium": 1.52,
                "thickness_um": 400.0,
                "mask_top": {"name": "layer 2", "shape": "square", "size_um": 40.0},
            },
            {
                "medium": 1.52,
                "thickness_um": 1000.0,
                "mask_top": {"name": "layer 1", "shape": "square", "size_um": 48.0},
            },
        ],
        "reference_gap": {"medium": "air", "thickness_um": 1000.0},
    }


@pytest.fixture
def data(paper):
    return paper_data(paper.description)


def same(variant, expected_data: dict) -> None:
    """The variant equals the expected design, field by field."""
    expected = design_from_dict(expected_data)
    assert variant.model_dump() == expected.model_dump()
    assert variant == expected and variant.fingerprint() == expected.fingerprint()


# -- the design itself ------------------------------------------------------------------
def test_preset_fingerprint_unchanged(paper, data):
    assert paper.fingerprint() == PAPER_FINGERPRINT
    same(paper, data)
    dumped = paper.model_dump(mode="json")
    assert isinstance(dumped["slabs"], list)  # tuples are written as JSON lists
    assert design_from_dict(dumped) == paper


def test_design_is_immutable_and_hashable(paper, data):
    assert isinstance(paper.slabs, tuple)
    assert hash(paper) == hash(design_from_dict(data))
    assert len({paper, design_from_dict(data), with_layers(paper, 2)}) == 2
    with pytest.raises(ValidationError, match="frozen"):
        paper.slabs = paper.slabs[:1]
    with pytest.raises(ValidationError, match="frozen"):
        paper.slabs[0].mask_top.size_um = 10.0
    with pytest.raises(AttributeError):
        paper.slabs.append(paper.slabs[0])
    with pytest.raises(TypeError):
        paper.slabs[0] = paper.slabs[1]
    with pytest.raises(DesignError, match="slabs"):
        design_from_dict(data | {"slabs": []})


# -- replace --------------------------------------------------------------------------------
def test_replace_by_path(paper, data):
    v = replace(paper, {"sensor.sensitive_width_um": 30, "slabs.2.mask_top.size_um": 52})
    data["sensor"]["sensitive_width_um"] = 30.0
    data["slabs"][2]["mask_top"]["size_um"] = 52.0
    same(v, data)
    assert paper.sensor.sensitive_width_um == 42.3  # the base is untouched
    assert replace(paper) == paper


def test_replace_merges_tables_removes_none_and_takes_keywords(paper, data):
    v = replace(
        paper,
        {
            "sensor": {"lines": 1},
            "slabs.-1.mask_top": {"offset_x_um": 2.5},
            "slabs.0.mask_top": None,
        },
        name="variant",
    )
    data["sensor"]["lines"] = 1
    data["slabs"][2]["mask_top"]["offset_x_um"] = 2.5
    del data["slabs"][0]["mask_top"]
    data["name"] = "variant"
    same(v, data)
    # a removed field takes its default; a model is accepted as a value
    same(replace(paper, {"sensor.row_b_offset_y_um": None}), paper_data(paper.description))
    two = replace(paper, slabs=paper.slabs[1:])
    assert two.slabs == paper.slabs[1:]


def test_replace_refuses_an_invalid_change_naming_the_field(paper):
    with pytest.raises(DesignError, match=r"sensor: sensitive_width_um \(50"):
        replace(paper, {"sensor.sensitive_width_um": 50})
    with pytest.raises(DesignError, match=r"slabs\.1\.mask_top\.size_um"):
        replace(paper, {"slabs.1.mask_top.size_um": -1})
    with pytest.raises(DesignError, match=r"sensor\.colour: unknown key"):
        replace(paper, {"sensor.colour": "red"})
    with pytest.raises(DesignError, match=r"slabs\.7\.medium: no item '7'"):
        replace(paper, {"slabs.7.medium": 1.5})
    with pytest.raises(DesignError, match=r"name\.x: 'x' is inside a value"):
        replace(paper, {"name.x": 1})
    with pytest.raises(DesignError, match="not a field path"):
        replace(paper, {"sensor..lines": 1})
    with pytest.raises(DesignError, match=r"slabs\.0\.thickness_um: Field required"):
        replace(paper, {"slabs.0.thickness_um": None})


# -- the stack ------------------------------------------------------------------------------
def test_stack_params(paper):
    assert stack_params(paper) == {
        "holes_um": [48.0, 40.0, 40.0],
        "thicknesses_um": [1000.0, 400.0, 450.0],  # object side first
        "offsets_um": [(0.0, 0.0), (0.0, 0.0), (0.0, 0.0)],
        "reference_gap_um": 1000.0,
    }


def test_with_stack(paper, data):
    v = with_stack(
        paper,
        holes_um=[50, 41, 39],
        thicknesses_um=[900, 300, 500],  # object side first
        offsets_um=[(1.5, -2.0), (0, 0), (3, 0)],
        reference_gap_um=800,
        name="stack",
    )
    for i, (h, t, off) in enumerate(
        [(39.0, 500.0, (3.0, 0.0)), (41.0, 300.0, (0.0, 0.0)), (50.0, 900.0, (1.5, -2.0))]
    ):
        data["slabs"][i]["thickness_um"] = t
        data["slabs"][i]["mask_top"] |= {"size_um": h, "offset_x_um": off[0], "offset_y_um": off[1]}
    data["reference_gap"]["thickness_um"] = 800.0
    data["name"] = "stack"
    same(v, data)
    assert stack_params(v)["offsets_um"] == [(1.5, -2.0), (0.0, 0.0), (3.0, 0.0)]


def test_with_stack_round_trip_and_revalidation(paper):
    assert with_stack(paper, **stack_params(paper)) == paper
    shifted = with_stack(paper, offsets_um=[(1.0, 2.0), (0, 0), (0, -1.0)])
    assert with_stack(shifted, **stack_params(shifted)) == shifted
    circ = with_hole_shape(paper, "circle")
    assert with_stack(circ, **stack_params(circ)) == circ
    # a hole bigger than the pitch, and holes that overlap between the staggered rows
    with pytest.raises(DesignError, match=r"slabs\.2\.mask_top: hole width 170"):
        with_stack(paper, holes_um=[170, 40, 40])
    with pytest.raises(DesignError, match=r"slabs\.0\.mask_top: holes of 90"):
        with_stack(paper, holes_um=[48, 40, 90])
    with pytest.raises(DesignError, match="holes_um: 2 values given, the design has 3"):
        with_stack(paper, holes_um=[48, 40])
    with pytest.raises(DesignError, match="thicknesses_um: 4 values"):
        with_stack(paper, thicknesses_um=[1, 2, 3, 4])


# -- resolution and structure ---------------------------------------------------------------
def test_scale_to_dpi(paper, data):
    # the merged pitch 25.4 mm / 600 on the artwork's 1-nm grid: 42.333 um, not 42.3333...
    k = 2 * 42.333 / 169.2
    for key in data["sensor"]:
        if key.endswith("_um"):
            data["sensor"][key] = round(data["sensor"][key] * k, 3)
    for sl, hole in zip(data["slabs"], (20.0, 20.0, 24.0), strict=True):
        sl["mask_top"]["size_um"] = hole  # rounded to 0.1 um
    data["name"] = "paper2016 at 600 dpi"
    same(scale_to_dpi(paper, 600.0), data)


def test_drop_mask(paper, data):
    del data["slabs"][1]["mask_top"]
    same(drop_mask(paper, 1), data)
    same(with_layers(paper, 2), data)
    with pytest.raises(DesignError, match=r"slabs\.1\.mask_top: this slab carries no mask"):
        drop_mask(drop_mask(paper, 1), 1)
    with pytest.raises(DesignError, match=r"slabs\.3: the design has 3 slabs"):
        drop_mask(paper, 3)


def test_with_layers(paper, data):
    same(with_layers(paper, 3), data)
    del data["slabs"][0]["mask_top"]
    del data["slabs"][1]["mask_top"]
    same(with_layers(paper, 1), data)  # one layer: the object-side mask
    with pytest.raises(DesignError, match=r"layers: between 1 and 3 \(got 4\)"):
        with_layers(paper, 4)


def test_one_row(paper, data):
    data["sensor"] |= {"rows": 1, "row_pitch_um": 84.6}
    same(one_row(paper), data)
    same(one_row(one_row(paper)), data)
    # the row-B offsets return to their defaults
    shifted = replace(paper, {"sensor.row_b_offset_y_um": 100.0})
    same(one_row(shifted), data)


def test_structural_variants(paper, data):
    v = structural_variants(paper, layers=(2, 3), stagger=("yes", "no"))
    assert list(v) == [
        "paper2016, 2 layers, staggered",
        "paper2016, 2 layers, one row",
        "paper2016, 3 layers, staggered",
        "paper2016, 3 layers, one row",
    ]
    del data["slabs"][1]["mask_top"]
    data["sensor"] |= {"rows": 1, "row_pitch_um": 84.6}
    data["name"] = "paper2016, 2 layers, one row"
    same(v["paper2016, 2 layers, one row"], data)
    assert v["paper2016, 3 layers, staggered"] == replace(
        paper, name="paper2016, 3 layers, staggered"
    )
    with pytest.raises(DesignError, match="stagger: yes or no"):
        structural_variants(paper, stagger=("maybe",))


# -- the pixel and the paper's unstated parameters ----------------------------------------
def test_with_sensitive_area(paper, data):
    data["sensor"] |= {
        "pixel_pitch_um": 84.6,
        "sensitive_width_um": 84.6,
        "sensitive_height_um": 84.6,
    }
    data["name"] = "paper2016 (sensitive 84.6 x 84.6 um)"
    same(with_sensitive_area(paper, 84.6, 84.6), data)
    small = with_sensitive_area(paper, 10.0, 20.0)
    assert small.sensor.pixel_pitch_um == 42.3
    assert (small.sensor.sensitive_width_um, small.sensor.sensitive_height_um) == (10.0, 20.0)


def test_hole_shapes(paper, data):
    for sl in data["slabs"]:
        sl["mask_top"]["shape"] = "circle"
    circ = with_hole_shape(paper, "circle")
    same(circ, data)
    assert square_holes(circ) == paper
    assert square_holes(paper) is paper  # nothing to change
    rect_hole = {"shape": "rectangle", "size_um": None, "width_um": 30.0, "height_um": 44.0}
    rect = replace(paper, {"slabs.1.mask_top": rect_hole})
    data["slabs"][1]["mask_top"]["size_um"] = 30.0  # a rectangle's width
    same(with_hole_shape(rect, "circle"), data)
    with pytest.raises(DesignError, match="a rectangular hole needs width_um"):
        with_stack(rect, holes_um=[48, 40, 40])


def test_with_glass_index(paper, data):
    data["slabs"][1]["medium"] = data["slabs"][2]["medium"] = "N-BK7"
    same(with_glass_index(paper, "N-BK7"), data)


def test_with_unstated(paper, data):
    assert with_unstated(paper) == paper
    v = with_unstated(
        paper, hole_shape="circle", sensitive_um=32.0, gap_medium=1.49, glass_index=1.46
    )
    for sl in data["slabs"]:
        sl["mask_top"]["shape"] = "circle"
    data["slabs"][1]["medium"] = data["slabs"][2]["medium"] = 1.46
    data["reference_gap"]["medium"] = 1.49
    data["sensor"] |= {"sensitive_width_um": 32.0, "sensitive_height_um": 32.0}
    same(v, data)
    with pytest.raises(DesignError, match="sensitive_width_um"):
        with_unstated(paper, sensitive_um=50.0)
