"""Design files: presets, derived geometry, validation messages, glass catalogue."""

from __future__ import annotations

from importlib import resources

import pytest
from pydantic import ValidationError

from helpers import preset_dict
from opticalstamp.design import DesignError, design_from_dict, load_design, preset_names
from opticalstamp.design.materials import refractive_index

PRESETS = ["paper2016", "fig1b", "fig1c", "fig1d", "three-layer-single-row"]


@pytest.mark.parametrize("name", PRESETS)
def test_presets_load(name):
    assert name in preset_names()
    d = load_design(name)
    assert d.name == name
    assert len(d.masks) >= 1
    assert d.reference_plane_um > max(d.mask_heights_um)


def test_paper2016_geometry():
    # paper section 3 / Fig. 4: gaps L3 = 0.45, L2 = 0.4, L1 = 1.0 mm from the sensor up;
    # holes 40, 40, 48 um from the sensor up; reference plane 1 mm above layer 1.
    d = load_design("paper2016")
    assert d.mask_heights_um == pytest.approx([450.0, 850.0, 1850.0])
    assert d.reference_plane_um == pytest.approx(2850.0)
    assert [m.hole_width_um for m in d.masks] == [40.0, 40.0, 48.0]
    s = d.sensor
    assert (s.row_pitch_um, s.row_b_offset_x_um, s.row_b_offset_y_um) == (169.2, 84.6, 84.6)
    assert s.rows == 2


def test_preset_file_path_round_trip(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(
        (resources.files("opticalstamp.design") / "presets" / "paper2016.toml").read_text()
    )
    d = load_design(path)
    assert d == load_design("paper2016")
    assert d.fingerprint() == load_design("paper2016").fingerprint()


def test_design_is_frozen():
    d = load_design("paper2016")
    with pytest.raises(ValidationError):
        d.name = "other"


def _error(mutate, preset: str = "paper2016") -> str:
    data = preset_dict(preset)
    mutate(data)
    with pytest.raises(DesignError) as info:
        design_from_dict(data)
    return str(info.value)


@pytest.mark.parametrize("value", [0.0, -10.0])
def test_thickness_must_be_positive(value):
    msg = _error(lambda d: d["slabs"][1].__setitem__("thickness_um", value))
    assert "slabs.1.thickness_um" in msg
    assert "must be at least 0.1 um" in msg  # MIN_LENGTH_UM: positive and then some


def test_negative_reference_gap():
    msg = _error(lambda d: d["reference_gap"].__setitem__("thickness_um", -1.0))
    assert "reference_gap.thickness_um" in msg


def test_hole_larger_than_pitch():
    # one row at 84.6 um pitch: a 90 um hole would merge with its neighbours
    msg = _error(lambda d: d["slabs"][2]["mask_top"].__setitem__("size_um", 90.0), "fig1b")
    assert "slabs.2.mask_top" in msg
    assert "row_pitch_um" in msg


def test_holes_overlap_between_staggered_rows():
    # 90 um holes are below the 169.2 um row pitch but overlap the other row (84.6, 84.6)
    msg = _error(lambda d: d["slabs"][0]["mask_top"].__setitem__("size_um", 90.0))
    assert "slabs.0.mask_top" in msg
    assert "staggered rows" in msg


def test_index_below_one():
    msg = _error(lambda d: d["slabs"][1].__setitem__("medium", 0.9))
    assert "slabs.1.medium" in msg
    assert "in [1, 4]" in msg


def test_unknown_medium():
    msg = _error(lambda d: d["slabs"][1].__setitem__("medium", "unobtainium"))
    assert "slabs.1.medium" in msg
    assert "unobtainium" in msg


def test_sensitive_area_larger_than_pitch():
    msg = _error(lambda d: d["sensor"].__setitem__("sensitive_width_um", 50.0))
    assert "sensor" in msg
    assert "sensitive_width_um" in msg
    assert "pixel_pitch_um" in msg
    msg = _error(lambda d: d["sensor"].__setitem__("sensitive_height_um", 43.0))
    assert "sensitive_height_um" in msg


@pytest.mark.parametrize(
    ("where", "field"),
    [
        ((), "colour"),
        (("sensor",), "sensor.colour"),
        (("slabs", 0, "mask_top"), "slabs.0.mask_top.colour"),
    ],
)
def test_unknown_key(where, field):
    def mutate(d):
        for key in where:
            d = d[key]
        d["colour"] = "red"

    msg = _error(mutate)
    assert field in msg
    assert "unknown key" in msg


@pytest.mark.parametrize(
    ("where", "typo", "meant"),
    [
        ((), "sensr", "sensor"),
        (("sensor",), "row", "rows"),
        (("slabs", 0), "thickness", "thickness_um"),
        (("slabs", 0, "mask_top"), "offset_x", "offset_x_um"),
        (("reference_gap",), "thicknes_um", "thickness_um"),
    ],
)
def test_a_misspelt_key_names_the_field_it_is_closest_to(where, typo, meant):
    """An unknown key close to a field of its own table (a slab's, a mask's, the
    sensor's) says which: "did you mean 'sensor'?"; one close to none says nothing more."""

    def mutate(d):
        for key in where:
            d = d[key]
        d[typo] = 1

    msg = _error(mutate)
    line = next(x for x in msg.splitlines() if f"{typo}: unknown key" in x)
    assert line.count("did you mean") == 1 and f"did you mean {meant!r}?" in line

    def far(d):
        d["zzz_unrelated"] = 1

    assert "did you mean" not in _error(far)


@pytest.mark.parametrize(("where", "typo", "meant"), [((), "aray", "array"),
                                                      (("array",), "row", "rows")])  # fmt: skip
def test_a_rod_lens_arrays_misspelt_key_names_its_field(where, typo, meant):
    """The same hint in a rod-lens array's file, from its own model's tables."""

    def mutate(d):
        for key in where:
            d = d[key]
        d[typo] = 1

    msg = _error(mutate, "sla-1row-12deg")
    assert f"{typo}: unknown key" in msg and f"did you mean {meant!r}?" in msg


def test_every_offending_field_is_named():
    def mutate(d):
        d["slabs"][0]["thickness_um"] = -1.0
        d["slabs"][2]["medium"] = 0.5

    msg = _error(mutate)
    assert "slabs.0.thickness_um" in msg
    assert "slabs.2.medium" in msg


def test_design_needs_a_mask():
    def mutate(d):
        for s in d["slabs"]:
            s.pop("mask_top", None)

    assert "mask_top" in _error(mutate)


def test_malformed_toml(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text('name = "broken"\n[[slabs]\nmedium = "air"\n')
    with pytest.raises(DesignError) as info:
        load_design(path)
    msg = str(info.value)
    assert "malformed TOML" in msg
    assert str(path) in msg


def test_invalid_file_names_the_field(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(
        'name = "bad"\n[[slabs]]\nmedium = "air"\nthickness_um = 0.0\n'
        "[slabs.mask_top]\nsize_um = 40.0\n"
    )
    with pytest.raises(DesignError) as info:
        load_design(path)
    assert "slabs.0.thickness_um" in str(info.value)
    assert str(path) in str(info.value)


def test_missing_design_file(tmp_path):
    with pytest.raises(DesignError, match="neither a preset"):
        load_design(tmp_path / "absent.toml")


@pytest.mark.parametrize(
    ("medium", "wavelength", "expected"),
    [
        ("N-BK7", 0.5876, 1.5168),  # Schott data sheet, n_d
        ("n-bk7", 0.5876, 1.5168),  # names are case-insensitive
        ("fused-silica", 0.5876, 1.4585),  # Malitson (1965), n_d
        ("air", 0.55, 1.0),
        (1.52, 0.55, 1.52),
    ],
)
def test_glass_catalogue(medium, wavelength, expected):
    assert refractive_index(medium, wavelength) == pytest.approx(expected, abs=1e-4)


def test_glass_dispersion_is_normal():
    # index falls with wavelength across the visible for every catalogue glass
    for name in ("N-BK7", "fused-silica", "PMMA", "soda-lime"):
        blue, red = refractive_index(name, 0.45), refractive_index(name, 0.65)
        assert blue > red > 1.3, name


def test_design_index_uses_its_wavelength():
    data = preset_dict("paper2016")
    data["slabs"][1]["medium"] = "N-BK7"
    data["wavelength_um"] = 0.5876
    d = design_from_dict(data)
    assert d.index(d.slabs[1].medium) == pytest.approx(1.5168, abs=1e-4)
