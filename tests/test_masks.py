"""Mask artwork read back by an independent reader (KLayout), presets, --version."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from edges import assert_clean_refusal, run
from opticalstamp import __version__
from opticalstamp.design import design_from_dict, load_design, preset_names
from opticalstamp.io.artwork import CIRCLE_TOLERANCE_UM

TOL = 2 * CIRCLE_TOLERANCE_UM  # a circle is a polygon: its bounding box centre moves by that
db = pytest.importorskip("klayout.db", reason="KLayout's Python module (the test extra)")


def read_holes(path):
    """{layer: [(cx, cy, w, h) in um]} of every shape, flattened by KLayout; a layer is
    (number, datatype, name): GDS layers have numbers, DXF layers names."""
    ly = db.Layout()
    ly.read(str(path))
    top = ly.top_cell()
    out = {}
    for li in ly.layer_indexes():
        info = ly.get_info(li)
        it = top.begin_shapes_rec(li)
        boxes = []
        while not it.at_end():
            sh = it.shape()
            if sh.is_box() or sh.is_polygon() or sh.is_path():
                b = sh.bbox().transformed(it.trans())
                boxes.append(
                    (
                        b.center().x * ly.dbu,
                        b.center().y * ly.dbu,
                        b.width() * ly.dbu,
                        b.height() * ly.dbu,
                    )
                )
            it.next()
        out[(info.layer, info.datatype, info.name)] = boxes
    return out


def offset_circle_design():
    d = load_design("paper2016").model_dump(mode="json")
    d["sensor"]["pixels_per_row"] = 50
    d["slabs"][0]["mask_top"] |= {"shape": "circle", "size_um": 36.0, "offset_x_um": 3.0}
    d["slabs"][2]["mask_top"]["offset_y_um"] = -2.0
    return design_from_dict(d, "test")


@pytest.mark.parametrize("fmt", ["gds", "dxf"])
@pytest.mark.parametrize("which", ["paper2016", "offsets"])
def test_artwork_reads_back_hole_for_hole(tmp_path, fmt, which):
    d = load_design("paper2016") if which == "paper2016" else offset_circle_design()
    if which == "paper2016":
        res = run(["masks", "paper2016", "-o", tmp_path / f"m.{fmt}"])
    else:
        from opticalstamp.io.artwork import write_masks

        write_masks(d, tmp_path / f"m.{fmt}")
        res = None
    assert res is None or res.exit_code == 0, res.output
    shapes = read_holes(tmp_path / f"m.{fmt}")
    s = d.sensor
    n = s.n_per_row
    masks = list(reversed(d.masks))  # layer 1 = the object side (the paper's numbering)
    holes = {k: v for k, v in shapes.items() if len(v) == 2 * n}
    assert len(holes) == len(masks)
    for (layer, _, _), boxes in sorted(holes.items()):
        m = masks[layer - 1]
        b = np.array(boxes)
        assert np.allclose(b[:, 2], m.hole_width_um, atol=0.05)  # circles: polygon bbox
        assert np.allclose(b[:, 3], m.hole_height_um, atol=0.05)
        row_b = b[:, 1] > s.row_b_offset_y_um / 2 + m.offset_y_um
        xa = np.sort(b[~row_b, 0])
        xb = np.sort(b[row_b, 0])
        assert xa.size == xb.size == n
        assert np.allclose(np.diff(xa), s.row_pitch_um, atol=TOL)  # pitch
        k_lo = -(n // 2)
        assert xa[0] == pytest.approx(k_lo * s.row_pitch_um + m.offset_x_um, abs=TOL)
        assert np.allclose(xb - xa, s.row_b_offset_x_um, atol=TOL)  # stagger
        assert np.allclose(b[~row_b, 1], m.offset_y_um, atol=TOL)
        assert np.allclose(b[row_b, 1], s.row_b_offset_y_um + m.offset_y_um, atol=TOL)
    marks = [v for k, v in shapes.items() if len(v) == 4]
    assert len(marks) == len(masks)  # two crosses of two arms on every layer
    assert all(sorted(v) == sorted(marks[0]) for v in marks)  # at the same place


def test_gds_is_small_and_labelled(tmp_path):
    from opticalstamp.io.artwork import write_masks

    d = load_design("paper2016")
    path = write_masks(d, tmp_path / "m.gds")
    assert path.stat().st_size < 10_000  # array references, not 7,446 polygons
    ly = db.Layout()
    ly.read(str(path))
    texts = []
    for li in ly.layer_indexes():
        it = ly.top_cell().begin_shapes_rec(li)
        while not it.at_end():
            if it.shape().is_text():
                texts.append(it.shape().text_string)
            it.next()
    assert any(d.fingerprint() in t and "layer 1" in t for t in texts)


def test_masks_refuses_a_rod_lens_design_and_other_suffixes(tmp_path):
    assert_clean_refusal(run(["masks", "sla-1row-12deg", "-o", tmp_path / "m.gds"]), "rod-lens")
    assert_clean_refusal(run(["masks", "paper2016", "-o", tmp_path / "m.txt"]), ".gds")
    assert_clean_refusal(
        run(["masks", "paper2016", "-o", tmp_path / "m.gds", "--format", "oas"]), "--format"
    )
    assert list(tmp_path.iterdir()) == []


def test_presets_list_and_show_round_trip(tmp_path):
    res = run(["presets"])
    assert res.exit_code == 0
    for name in preset_names():
        assert name in res.output
    assert "rod-lens-array" in res.output
    res = run(["presets", "show", "paper2016"])
    f = tmp_path / "mine.toml"
    f.write_text(res.stdout)
    assert load_design(str(f)).fingerprint() == load_design("paper2016").fingerprint()
    assert tomllib.loads(res.stdout)["name"] == "paper2016"
    assert_clean_refusal(run(["presets", "show", "nope"]), "no preset")


def test_version():
    res = run(["--version"])
    assert res.exit_code == 0 and __version__ in res.output
