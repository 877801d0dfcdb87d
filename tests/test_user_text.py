"""What a user reads (issue 21): no cut words, slabs named as the user counts them, no
regular expressions or Python values on screen, units as an engineer writes them, progress
bars only on a terminal."""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest
from pydantic import ValidationError

from edges import assert_clean_refusal, run
from helpers import preset_dict
from opticalstamp.design import DesignError, Sensor, design_from_dict, load_design, preset_names
from opticalstamp.imaging.scan import KERNELS, ScanSettings
from opticalstamp.raytrace.launch import progress_bar
from opticalstamp.studies.tolerance import parse_spec

DOCS = Path(__file__).resolve().parents[1] / "docs"
PYTHON_VALUES = re.compile(r"\b(True|False|None)\b")


def test_presets_are_cut_at_a_word_with_an_ellipsis():
    res = run(["presets"])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert len(lines) == len(preset_names())
    for line, name in zip(lines, preset_names(), strict=True):
        summary = load_design(name).description.split(":")[0]
        shown = line.split(maxsplit=2)[2]
        if shown != summary:  # shortened: whole words, then an ellipsis
            assert shown.endswith("…") and len(shown) <= 70, line
            kept = shown.removesuffix("…")
            assert summary.startswith(kept) and summary[len(kept)] == " ", line


def _design_error(mutate) -> str:
    data = preset_dict("paper2016")
    mutate(data)
    with pytest.raises(DesignError) as info:
        design_from_dict(data)
    return str(info.value)


def test_a_slab_is_named_as_the_file_and_the_paper_count_it():
    # the second [[slabs]] table of three (from the sensor) is the paper's slab 2 (L2)
    msg = _design_error(lambda d: d["slabs"][1].__setitem__("thickness_um", -5.0))
    assert (
        "  [[slabs]] table 2 of 3 counted from the sensor (slab 2 from the object side) — "
        "slabs.1.thickness_um: must be at least 0.1 um (got -5.0)"
    ) in msg
    # the first table, nearest the sensor: slab 3 and mask layer 3 from the object side
    msg = _design_error(lambda d: d["slabs"][0]["mask_top"].__setitem__("size_um", -1))
    assert (
        "[[slabs]] table 1 of 3 counted from the sensor (slab 3 from the object side, its "
        "mask layer 3) — slabs.0.mask_top.size_um: "
    ) in msg
    # a rule of the whole design about one slab's mask reads the same, not "(top level)"
    msg = _design_error(lambda d: d["slabs"][2]["mask_top"].__setitem__("size_um", 90.0))
    assert "(top level)" not in msg
    assert (
        "[[slabs]] table 3 of 3 counted from the sensor (slab 1 from the object side, its "
        "mask layer 1) — slabs.2.mask_top: holes of 90.0 x 90.0 um overlap"
    ) in msg
    msg = _design_error(lambda d: d["sensor"].__setitem__("lines", 0))
    assert "\n  sensor.lines: Input should be" in msg  # no slab, no count


def test_a_slab_without_a_mask_shifts_the_layer_numbers():
    def mutate(d):
        d["slabs"][1].pop("mask_top")  # layer 2 removed: the sensor-side mask is layer 2
        d["slabs"][0]["mask_top"]["size_um"] = -1

    msg = _design_error(mutate)
    assert "(slab 3 from the object side, its mask layer 2) — slabs.0.mask_top" in msg


def test_kernel_choices_are_listed_not_a_pattern(tmp_path):
    res = run(["scan", tmp_path / "page.png", "-o", tmp_path / "s.png", "--z", 1, "--kernel",
               "fast"])  # fmt: skip
    assert_clean_refusal(res, "--kernel: expected one of auto, paraxial, trace, wave (got 'fast')")
    assert "pattern" not in res.output and "^(" not in res.output
    for field, value in (("kernel", "fast"), ("illumination", "sunny")):
        with pytest.raises(ValidationError) as info:
            ScanSettings(**{field: value})
        assert "pattern" not in str(info.value) and "^(" not in str(info.value)
    assert KERNELS == ("auto", "paraxial", "trace", "wave")


def test_every_sensor_key_is_explained():
    text = (DOCS / "design-files.md").read_text(encoding="utf-8")
    section = text.split("## The sensor: `[sensor]`")[1].split("\n## ")[0]
    for key in Sensor.model_fields:
        assert f"`{key}`" in section, key


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bars_only_on_a_terminal():
    assert not progress_bar(total=10, progress=True, file=_Terminal()).disable
    assert progress_bar(total=10, progress=True, file=io.StringIO()).disable  # a captured log
    assert progress_bar(total=10, progress=False, file=_Terminal()).disable


def test_rmtf_says_which_light_it_counts():
    res = run(["rmtf", "--method", "paraxial", "--z", "0:1:0.5", "--no-ghosts"])
    assert res.exit_code == 0, res.output
    assert "own path only" in res.output
    assert not PYTHON_VALUES.search(res.output), res.output


def test_units_as_an_engineer_writes_them():
    res = run(["diffraction", "--slit-um", "48", "--z", "1"])
    assert res.exit_code == 0, res.output
    assert "slit 48 µm" in res.output
    assert not re.search(r"\bum\b", res.output), res.output
    res = run(["show", "sla-2row-20deg"])
    assert res.exit_code == 0, res.output
    assert re.search(r"conjugate length: [0-9.]+ mm", res.output)
    assert "g: " in res.output and "mm⁻¹" in res.output


@pytest.mark.parametrize(
    ("command", "units"),
    [
        ("report", ("dof (mm", "ratio to the paper's F/10 reference lens", "a fraction 0 to 1")),
        ("tolerance", ("dof (mm", "ratio to the paper's F/10 reference lens", "a fraction 0")),
    ],
)
def test_spec_help_gives_each_figures_unit(command, units):
    res = run([command, "--help"])
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    for unit in units:
        assert unit in text, unit


def test_tolerance_spec_names_only_distances_it_traces():
    # was a KeyError traceback after the whole study
    res = run(["tolerance", "--samples", 2, "--spec", "rmtf@5>=0.3"])
    assert_clean_refusal(res, "--spec: rmtf@5 asks for the RMTF at Z = 5 mm, not one of the")
    with pytest.raises(ValueError, match="not one of the distances"):
        parse_spec("rmtf@5>=0.3", [1.0, 2.0])
    assert parse_spec("rmtf@2>=0.3", [1.0, 2.0]) == [("rmtf@2", ">=", 0.3)]
    with pytest.raises(ValueError, match="cannot read"):
        parse_spec("rmtf@1.2.3>=0.3")
