"""Artwork and exported files (issue 21): exported designs have file names without
spaces, the mask artwork sits on its 1-nm database grid and KLayout reads it with no
off-grid warning; a design off the grid is refused, not silently snapped."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from edges import assert_clean_refusal, run
from opticalstamp.design import design_toml, load_design, replace, scale_to_dpi
from opticalstamp.io import artwork
from opticalstamp.io.artwork import DBU_UM, OffGridError, grid_problems, write_masks
from opticalstamp.io.files import file_stem
from opticalstamp.raytrace.stack import output_pitch
from opticalstamp.units import dpi_of_pitch

db = pytest.importorskip("klayout.db", reason="KLayout's Python module (the test extra)")

SAFE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]*")


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def unsnapped_600(paper):
    """paper2016 at 600 dpi as scale_to_dpi made it before issue 21: lengths off the grid
    (pitch 84.66666... um), the design of the user's audit."""
    k = 25400.0 / 600.0 / 84.6
    s = paper.sensor
    changes = {
        f"sensor.{key}": getattr(s, key) * k
        for key in (
            "pixel_pitch_um",
            "sensitive_width_um",
            "sensitive_height_um",
            "row_pitch_um",
            "row_b_offset_x_um",
            "row_b_offset_y_um",
        )
    }
    changes |= {"slabs.0.mask_top.size_um": 20.0, "slabs.1.mask_top.size_um": 20.0}
    changes |= {"slabs.2.mask_top.size_um": 24.0}
    return replace(paper, changes, name="paper2016 at 600 dpi-p02")


def klayout_says(path) -> str:
    """What KLayout prints while it reads ``path`` in a process of its own: its warnings
    ("Warning: Off-grid AREF column vector - AREF will be split into subarrays") go to
    the process's stdout, so both streams are read."""
    code = "import sys, klayout.db as db; db.Layout().read(sys.argv[1])"
    res = subprocess.run(
        [sys.executable, "-c", code, str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stdout
    return res.stdout


# -- file names ------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "stem"),
    [
        ("paper2016", "paper2016"),
        ("paper2016 at 600 dpi", "paper2016-600dpi"),
        ("paper2016 at 600 dpi-p01", "paper2016-600dpi-p01"),
        ("paper2016 at 600 dpi, 2 layers, one row", "paper2016-600dpi-2-layers-one-row"),
        ("Stämp (v2) $HOME;rm -rf /*", "Stamp-v2-HOME-rm-rf"),
        ("--option", "option"),
        (".hidden", "hidden"),
        ("  ", "design"),
    ],
)
def test_file_stem_has_no_spaces_nor_shell_specials(name, stem):
    assert file_stem(name) == stem == file_stem(name)  # deterministic
    assert SAFE.fullmatch(stem)


def test_search_at_600_dpi_exports_the_file_names_the_docs_show(tmp_path):
    """search --dpi 600 --export-designs: paper2016-600dpi-pNN.toml, listed in front.json;
    `masks` on it writes an artwork KLayout reads without a warning."""
    out = tmp_path / "front"
    res = run(
        ["search", "--dpi", "600", "--population", "4", "--generations", "1", "--workers",
         "1", "--no-verify", "--near-mm", "0.01", "--budget-mm", "10", "--pin",
         "hole1=30,hole2=30,hole3=30,slab1=200,slab2=200,slab3=200",
         "--export-designs", str(out), "--json"]
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    index = json.loads((out / "front.json").read_text())["points"]
    assert [p["file"] for p in index] == ["paper2016-600dpi-p01.toml"]
    assert sorted(p.name for p in out.iterdir()) == ["front.json", "paper2016-600dpi-p01.toml"]
    point = load_design(str(out / "paper2016-600dpi-p01.toml"))
    assert point.name == "paper2016 at 600 dpi-p01"  # the readable name stays inside
    gds = tmp_path / "p01.gds"
    res = run(["masks", out / "paper2016-600dpi-p01.toml", "-o", gds])
    assert res.exit_code == 0, res.output
    assert "Warning" not in klayout_says(gds)


# -- the grid ----------------------------------------------------------------------------
@pytest.mark.parametrize("dpi", [150, 200, 300, 400, 600, 1200])
def test_scale_to_dpi_is_on_the_mask_grid(paper, dpi):
    d = scale_to_dpi(paper, dpi)
    s = d.sensor
    assert grid_problems(d) == []
    assert abs(dpi_of_pitch(output_pitch(d)) / dpi - 1) < 1e-4  # the price of the grid
    assert s.row_b_offset_x_um == s.row_b_offset_y_um == s.row_pitch_um / 2  # still half
    assert s.sensitive_width_um == s.pixel_pitch_um  # scaled alike


def test_scale_to_dpi_600_values(paper):
    s = scale_to_dpi(paper, 600).sensor
    assert (s.row_pitch_um, s.row_b_offset_x_um, s.pixel_pitch_um) == (84.666, 42.333, 21.166)


def test_klayout_reads_the_600dpi_artwork_exactly_with_no_warning(paper, tmp_path):
    """Every array reference is one regular array (not split into sub-arrays) whose
    column vector is the designed pitch in whole database units; KLayout prints no
    warning while reading, and the read-back hole centres are exactly one pitch apart."""
    d = scale_to_dpi(paper, 600)
    path = write_masks(d, tmp_path / "m600.gds")
    assert klayout_says(path) == ""
    ly = db.Layout()
    ly.read(str(path))
    assert ly.dbu == pytest.approx(DBU_UM)
    n = d.sensor.n_per_row
    pitch_dbu = round(d.sensor.row_pitch_um / DBU_UM)
    assert pitch_dbu == 84666
    insts = list(ly.top_cell().each_inst())
    assert len(insts) == 2 * len(d.masks)  # one array per row and layer, none split
    for inst in insts:
        assert inst.is_regular_array() and inst.na * inst.nb == n
        vec = inst.b if inst.nb == n else inst.a
        assert (vec.x, vec.y) == (pitch_dbu, 0)
    # the holes of one row, flattened: every step exactly the pitch
    li = ly.layer(1, 0)
    xs = {}
    it = ly.top_cell().begin_shapes_rec(li)
    while not it.at_end():
        if it.shape().is_box() or it.shape().is_polygon():
            c = it.shape().bbox().transformed(it.trans()).center()
            xs.setdefault(c.y, []).append(c.x)
        it.next()
    assert sorted(len(row) for row in xs.values()) == [n, n]
    for row in xs.values():
        steps = {b - a for a, b in zip(sorted(row), sorted(row)[1:], strict=False)}
        assert steps == {pitch_dbu}


def test_the_warning_is_caught_when_the_artwork_is_off_the_grid(paper, tmp_path, monkeypatch):
    """The control of the test above: the unsnapped 600-dpi design, written with the grid
    check switched off, makes KLayout print its off-grid warning, six times (one per
    array), so its absence above means something."""
    monkeypatch.setattr(artwork, "check_on_grid", lambda design: None)
    path = write_masks(unsnapped_600(paper), tmp_path / "off.gds")
    assert klayout_says(path).count("Warning: Off-grid AREF column vector") == 6


def test_masks_refuses_a_design_off_the_grid(paper, tmp_path):
    d = unsnapped_600(paper)
    problems = grid_problems(d)
    assert [p.split(" =")[0] for p in problems] == [
        "sensor.row_pitch_um",
        "sensor.row_b_offset_x_um",
        "sensor.row_b_offset_y_um",
    ]
    assert "84.667 µm" in problems[0] and "0.826 µm at the end of a row of 2480" in problems[0]
    with pytest.raises(OffGridError, match="database unit is 1 nm"):
        write_masks(d, tmp_path / "m.gds")
    with pytest.raises(OffGridError):
        write_masks(d, tmp_path / "m.dxf")
    f = tmp_path / "old.toml"
    f.write_text(design_toml(d))
    for fmt in ("gds", "dxf"):
        res = run(["masks", f, "-o", tmp_path / f"m.{fmt}"])
        assert_clean_refusal(res, "sensor.row_pitch_um = 84.66666666666667 µm", tmp_path,
                             before=["old.toml"])  # fmt: skip
        assert "84.667 µm" in res.output


def test_hole_sizes_and_offsets_on_the_grid(paper):
    """Hole sizes are drawn centred: whole multiples of 2 nm; misregistration 1 nm."""
    ok = replace(paper, {"slabs.0.mask_top.size_um": 40.002, "slabs.1.mask_top.offset_x_um": 0.001})
    assert grid_problems(ok) == []
    bad = replace(paper, {"slabs.0.mask_top.size_um": 40.001, "slabs.1.mask_top.offset_y_um": 1e-4})
    got = grid_problems(bad)
    assert [p.split(" =")[0] for p in got] == [
        "slabs.0.mask_top.size_um",
        "slabs.1.mask_top.offset_y_um",
    ]
    assert "2 nm" in got[0]
