"""Regression corpus of bad input found by testing as a careful user would: each case ends
with exit code 2, a message naming the field or option and the rule, no traceback and no
output file."""

from __future__ import annotations

import pytest

from edges import assert_clean_refusal, run, to_toml
from helpers import preset_dict
from opticalstamp.design import DesignError, design_from_dict, load_design
from opticalstamp.validate import InputError, check_seed, parse_grid

# -- designs -----------------------------------------------------------------------------
BAD_DESIGN_VALUES = [
    (("slabs", 0, "thickness_um"), 1e308, "slabs.0.thickness_um"),
    (("slabs", 0, "thickness_um"), float("inf"), "slabs.0.thickness_um"),
    (("slabs", 0, "thickness_um"), float("nan"), "slabs.0.thickness_um"),
    (("slabs", 0, "thickness_um"), True, "slabs.0.thickness_um"),
    (("slabs", 0, "thickness_um"), "42.0", "slabs.0.thickness_um"),
    (("slabs", 1, "medium"), True, "slabs.1.medium"),
    (("slabs", 1, "medium"), 9.0, "slabs.1.medium"),
    (("slabs", 2, "mask_top", "size_um"), False, "slabs.2.mask_top.size_um"),
    (("slabs", 2, "mask_top", "offset_x_um"), 1e12, "slabs.2.mask_top.offset_x_um"),
    (("reference_gap", "thickness_um"), 1e9, "reference_gap.thickness_um"),
    (("sensor", "rows"), True, "sensor.rows"),
    (("sensor", "lines"), "3", "sensor.lines"),
    (("sensor", "lines"), 3.0, "sensor.lines"),
    (("sensor", "pixel_pitch_um"), 1e-9, "sensor.pixel_pitch_um"),
    (("sensor", "acceptance_half_angle_deg"), float("nan"), "sensor.acceptance_half_angle_deg"),
    (("wavelength_um",), True, "wavelength_um"),
    (("object_medium",), "1.0", "object_medium"),
]


def _set(d: dict, path: tuple, value) -> dict:
    node = d
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return d


@pytest.mark.parametrize(("path", "value", "field"), BAD_DESIGN_VALUES)
def test_bad_design_values_are_refused(tmp_path, path, value, field):
    d = _set(preset_dict("paper2016"), path, value)
    with pytest.raises(DesignError, match=field.replace(".", r"\.")):
        design_from_dict(d)
    f = tmp_path / "bad.toml"
    f.write_text(to_toml(d))
    before = [f.name]
    res = run(["ghosts", "-d", f, "--rays", 1000, "--plot", tmp_path / "g.png"])
    assert_clean_refusal(res, field, tmp_path, before)


def test_thick_stack_is_refused():
    d = preset_dict("paper2016")
    for s in d["slabs"]:
        s["thickness_um"] = 60_000.0
    with pytest.raises(DesignError, match="stack is"):
        design_from_dict(d)


def test_bom_is_accepted_and_deep_nesting_refused(tmp_path):
    text = to_toml(preset_dict("paper2016"))
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode())
    assert load_design(bom).slabs[2].mask_top.size_um == 48.0
    deep = tmp_path / "deep.toml"
    deep.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(DesignError, match="nested too deeply"):
        load_design(deep)
    deep.write_text("a = " + "{x = " * 3000 + "1" + "}" * 3000 + "\n")
    assert_clean_refusal(run(["spots", "-d", deep]), str(deep))


def test_huge_design_file_is_refused(tmp_path):
    f = tmp_path / "big.toml"
    f.write_text("# x\n" * 400_000)
    with pytest.raises(DesignError, match="larger than"):
        load_design(f)


def test_small_holes_warn_that_geometric_optics_fails(tmp_path):
    d = preset_dict("paper2016")
    d["slabs"][2]["mask_top"]["size_um"] = 10.0
    f = tmp_path / "small.toml"
    f.write_text(to_toml(d))
    res = run(["rmtf", "-d", f, "--method", "paraxial", "--z", "0,1"])
    assert res.exit_code == 0, res.output
    assert "geometric optics does not hold there: the ray figures are off, either way" in res.output
    res = run(["rmtf", "--method", "paraxial", "--z", "0,1"])
    assert "geometric optics" not in res.output


# -- command-line options ------------------------------------------------------------------
BAD_OPTIONS = [
    (["rmtf", "--z", "0:1:inf"], "--z"),
    (["rmtf", "--z", "5:1:1"], "--z"),
    (["rmtf", "--z", "0:100:1e-9"], "--z"),
    (["rmtf", "--dof-dpi", "0"], "--dof-dpi"),
    (["rmtf", "--dof-dpi", "-200"], "--dof-dpi"),
    (["rmtf", "--dof-dpi", "nan"], "--dof-dpi"),
    (["rmtf", "--shift-um", "1e-6", "--method", "paraxial"], "--shift-um"),
    (["rmtf", "--threshold", "1"], "--threshold"),
    (["rmtf", "--window-um", "inf"], "--window-um"),
    (["psf", "--x-obj", "nan"], "--x-obj"),
    (["psf", "--x-obj", "1e300"], "--x-obj"),
    (["psf", "--y-obj", "inf"], "--y-obj"),
    (["psf", "--z", "-1"], "--z"),
    (["ghosts", "--detector-um", "-5"], "--detector-um"),
    (["ghosts", "--detector-um", "0"], "--detector-um"),
    (["ghosts", "--detector-um", "nan"], "--detector-um"),
    (["ghosts", "--rse-own", "0"], "--rse-own"),
    (["ghosts", "--rays", "10"], "--rays"),
    (["ghosts", "--z", "nan"], "--z"),
    (["diffraction", "--next-um", "nan"], "--next-um"),
    (["diffraction", "--gap-um", "inf"], "--gap-um"),
    (["diffraction", "--wavelength-um", "0.5,inf"], "--wavelength-um"),
    (["tolerance", "--misregistration-um", "nan"], "--misregistration-um"),
    (["tolerance", "--dpi", "0"], "--dpi"),
    (["tolerance", "--samples", "0"], "--samples"),
    (["search", "--pin", "hole1=nan"], "hole1"),
    (["search", "--pin", "slab1=-5"], "slab1"),
    (["search", "--pin", "hole1=1e9"], "hole1"),
    (["search", "--pin", "slab1=1000,slab2=1000,slab3=1000"], "slab1=1000"),
    (["search", "--pin", "t0=1000"], "slab1"),
    (["search", "--workers", "0"], "--workers"),
    (["chart", "bars", "-o", "c.png", "--dpi", "nan"], "--dpi"),
    (["chart", "bars", "-o", "c.png", "--points", "3"], "--points"),
    (["chart", "bars", "-o", "c.png", "--blocks", "100,abc"], "--blocks"),
    (["chart", "bars", "-o", "c.png", "--blocks", "5"], "--blocks"),
    (["chart", "bars", "-o", "c.png", "--blocks", "700"], "--blocks"),
    (["chart", "bars", "-o", "c.png", "--dpi", "300"], "--dpi"),
    (["chart", "edge", "-o", "c.png", "--blocks", "100"], "--blocks"),
    (["chart", "text", "-o", "c.png", "--points", "0.5"], "--points"),
    (["chart", "text", "-o", "c.png", "--face", "mono"], "--face"),
    (["chart", "text", "-o", "c.png", "--face", "sans,serif"], "--face"),
    (["scan", "doc.png", "-o", "s.png", "--z", "inf"], "--z"),
    (["scan", "doc.png", "-o", "s.png", "--z", "1", "--surround", "2"], "--surround"),
    (["scan", "doc.png", "-o", "s.png", "--z", "1", "--exposure-ms", "nan"], "--exposure-ms"),
]
SEED_COMMANDS = ["ghosts", "spots", "psf", "rmtf", "efficiency", "search", "tolerance", "report"]


@pytest.mark.parametrize(("args", "name"), BAD_OPTIONS)
def test_bad_options_are_refused_before_work(tmp_path, monkeypatch, args, name):
    monkeypatch.chdir(tmp_path)
    res = run(args)
    assert_clean_refusal(res, name, tmp_path, [])


@pytest.mark.parametrize("cmd", SEED_COMMANDS)
@pytest.mark.parametrize("seed", ["-1", str(2**63), "1.5", "x"])
def test_one_seed_rule_for_every_command(tmp_path, monkeypatch, cmd, seed):
    monkeypatch.chdir(tmp_path)
    assert_clean_refusal(run([cmd, "--seed", seed]), "--seed", tmp_path, [])


def test_seed_rule_in_the_library():
    assert check_seed(0) == 0 and check_seed(2**63 - 1) == 2**63 - 1
    for bad in (-1, 2**63, True, 1.0, "3"):
        with pytest.raises(InputError, match="seed"):
            check_seed(bad)


def test_grid_parser():
    assert parse_grid("0:1:0.25", "--z", 0, 10) == (0.0, 0.25, 0.5, 0.75, 1.0)
    assert parse_grid("0.5,2", "--z", 0, 10) == (0.5, 2.0)
    for bad in ("0:1", "a:b:c", "0:1:0", "0:1:-1", "1:0:0.1", "0:11:1", "", ","):
        with pytest.raises(InputError, match="--z"):
            parse_grid(bad, "--z", 0, 10)


# -- outputs: checked before the computation ---------------------------------------------
def test_output_paths_are_checked_first(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir.png").mkdir()
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    before = ["afile", "adir.png", "mine"]
    cases = [
        (["report", "--out", "afile"], "--out"),
        (["report", "--out", "mine"], "no report.json"),
        (["ghosts", "--plot", "afile/g.png"], "which is a file"),
        (["ghosts", "--plot", "adir.png"], "existing folder"),
        (["ghosts", "--plot", "g.jpg"], ".png"),
        (["ghosts", "--plot", "x" * 300 + ".png"], "255 bytes"),
        (["chart", "bars", "-o", "/proc/c.png"], "cannot write"),
        (["search", "-o", "s.csv"], ".nc"),
        (["scan", "doc.png", "-o", "s.bmp", "--z", "1"], "-o"),
    ]
    for args, name in cases:
        assert_clean_refusal(run(args), name, tmp_path, before)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


def test_missing_output_folders_are_created_and_suffix_kept(tmp_path):
    out = tmp_path / "new" / "deeper" / "C.PNG"
    res = run(["chart", "bars", "-o", out, "--dpi", "600"])
    assert res.exit_code == 0, res.output
    assert out.is_file()
