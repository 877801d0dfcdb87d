"""`opticalstamp show`: the design as built, layers numbered from the object side."""

from __future__ import annotations

import json

from PIL import Image

from edges import assert_clean_refusal, run
from opticalstamp.design import load_design


def test_show_stamp_table_and_drawing(tmp_path):
    res = run(["show", "paper2016", "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    stack = data["stack"]
    assert stack[0].get("reference_gap") and stack[0]["z_top_um"] == 2850  # object side first
    masks = [r for r in stack if r["mask"]]
    assert [r["layer"] for r in masks] == [1, 2, 3]
    assert [r["mask"]["width_um"] for r in masks] == [48, 40, 40]  # the paper's layer 1: 48 um
    assert data["output_pitch_um"] == 169.2 / 2  # the merged rows' pitch (300.24 dpi)
    png = tmp_path / "stack.png"
    res = run(["show", "paper2016", "--plot", png])
    assert res.exit_code == 0 and "square 48 × 48 µm" in res.output
    with Image.open(png) as im:
        assert im.size[0] > 400 and im.size[1] > 400


def test_show_rod_lens_derived_quantities():
    res = run(["show", "sla-2row-20deg", "--json"])
    assert res.exit_code == 0, res.output
    der = json.loads(res.stdout)["derived"]
    a = load_design("sla-2row-20deg").array
    assert der["conjugate_length_mm"] == a.conjugate_um / 1000
    assert_clean_refusal(run(["show", "sla-2row-20deg", "--plot", "x.png"]), "--plot")
