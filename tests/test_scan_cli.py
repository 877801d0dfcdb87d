"""Scan, chart and OCR from the command line; wrong inputs get clear errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from PIL import Image
from typer.testing import CliRunner

from opticalstamp.cli.common import app
from opticalstamp.design import load_design
from opticalstamp.imaging.charts import text_chart
from opticalstamp.imaging.ocr import (
    character_error_rate,
    edit_distance,
    recognise,
    tesseract_available,
)
from opticalstamp.imaging.scan import simulate_scan
from opticalstamp.io.files import ImageError, linear_to_srgb, read_document

runner = CliRunner()
needs_tesseract = pytest.mark.skipif(
    not tesseract_available(),
    reason="tesseract is not installed (apt-get install tesseract-ocr; .ci/run installs it)",
)


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def _ok(res):
    assert res.exit_code == 0, res.output
    return res


def test_chart_then_scan_writes_png_tiff_json(tmp_path):
    _ok(_run("chart", "bars", "-o", tmp_path / "bars.png", "--dpi", "600"))
    _ok(_run("scan", tmp_path / "bars.png", "-o", tmp_path / "s.png", "--z", "1.0"))
    with Image.open(tmp_path / "s.png") as im:
        assert im.mode == "L" and im.info["dpi"][0] == pytest.approx(25400 / 84.6, abs=0.01)
    with tifffile.TiffFile(tmp_path / "s.tif") as tf:
        assert tf.pages[0].dtype == np.uint16
        num, den = tf.pages[0].tags["XResolution"].value
        assert num / den == pytest.approx(25400 / 84.6, rel=1e-4)
    meta = json.loads((tmp_path / "s.json").read_text())
    assert meta["design"] == "paper2016" and meta["seed"] == 0 and "opticalstamp_version" in meta
    # one default with the report: the page on a white surround (a scanner's lid)
    assert meta["settings"]["surround"] == 1.0


def test_scan_takes_the_optics_the_other_commands_take(tmp_path):
    """--kernel auto follows --optics as every other command does: the prototype (wave
    by the validity rule) is scanned through wave kernels by default, and says so in its
    output and sidecar (the optics and the kernel used); --optics ray gives the closed
    form's scan, the same image as --kernel paraxial, which names no optics."""
    from opticalstamp.analysis.responsivity import resolve_optics

    assert resolve_optics(load_design("paper2016"), "auto").engine == "wave"
    doc = tmp_path / "bars.png"
    _ok(_run("chart", "bars", "-o", doc, "--dpi", "600"))
    out = {}
    for name, extra in (
        ("auto", ()),
        ("ray", ("--optics", "ray")),
        ("paraxial", ("--kernel", "paraxial")),
        ("wave", ("--kernel", "wave")),
    ):
        res = _ok(_run("scan", doc, "-o", tmp_path / f"{name}.png", "--z", "1.0", *extra))
        meta = json.loads((tmp_path / f"{name}.json").read_text())
        out[name] = (res.output, meta, tifffile.imread(tmp_path / f"{name}.tif"))
    text, meta, auto = out["auto"]
    assert meta["optics"]["engine"] == "wave" and meta["kernel_used"] == "wave"
    assert "optics: wave" in text
    assert np.array_equal(auto, out["wave"][2])
    _, ray_meta, ray = out["ray"]
    assert ray_meta["optics"]["engine"] == "ray" and ray_meta["kernel_used"] == "paraxial"
    assert "optics: ray" in out["ray"][0]
    assert np.array_equal(ray, out["paraxial"][2]) and not np.array_equal(ray, auto)
    assert "optics" not in out["paraxial"][1] and "optics:" not in out["paraxial"][0]


def test_measure_rmtf_on_a_scanned_tiff(tmp_path):
    """The CLI's own chain: chart -> scan (16-bit linear TIFF) -> measure-rmtf."""
    _ok(_run("chart", "bars", "-o", tmp_path / "bars.png"))
    _ok(_run("scan", tmp_path / "bars.png", "-o", tmp_path / "s.tif", "--z", "0.5", "--noiseless"))
    res = _ok(_run("measure-rmtf", tmp_path / "s.tif", "--json"))
    blocks = json.loads(res.stdout)["blocks"]
    nominal = [min((100, 150, 200, 247), key=lambda d, b=b: abs(d - b["dpi"])) for b in blocks]
    assert nominal == [100, 150, 200, 247]
    assert blocks[0]["rmtf"] > blocks[2]["rmtf"] > 0.3


def test_scan_height_map_shapes_and_colour(tmp_path):
    _ok(_run("chart", "lines", "-o", tmp_path / "l.png", "--dpi", "600"))
    _ok(
        _run(
            "scan",
            tmp_path / "l.png",
            "-o",
            tmp_path / "g.png",
            "--height-map",
            "gutter:3:20",
            "--color",
        )
    )
    with Image.open(tmp_path / "g.png") as im:
        assert im.mode == "RGB"


@pytest.mark.parametrize(
    ("args", "text"),
    [
        (["--z", "1", "--height-map", "tilt"], "exactly one"),
        ([], "exactly one"),
        (["--z", "-2"], "--z"),
        (["--z", "20"], "--z"),
        (["--height-map", "wobble:1"], "neither a shape"),
        (["--height-map", "tilt:0:30"], "outside the modelled range"),
        (["--z", "1", "--dpi", "-300"], "--dpi"),
        (["--z", "1", "--illumination", "disco"], "--illumination"),
        (["--z", "1", "--speed-error", "3"], "--speed-error"),
        (["--z", "1", "--illuminance-lux", "-5"], "--illuminance-lux"),
        (["--z", "1", "--exposure-ms", "0"], "--exposure-ms"),
        (["--z", "1", "--illumination", "missing.csv"], "--illumination"),
    ],
)
def test_scan_bad_options(tmp_path, args, text):
    _ok(_run("chart", "edge", "-o", tmp_path / "e.png", "--dpi", "300"))
    res = _run("scan", tmp_path / "e.png", "-o", tmp_path / "out.png", *args)
    assert res.exit_code == 2, res.output
    assert text in res.output and "Traceback" not in res.output
    assert not (tmp_path / "out.png").exists()


def test_scan_bad_files(tmp_path):
    good = tmp_path / "g.png"
    _ok(_run("chart", "edge", "-o", good, "--dpi", "300"))
    bad = tmp_path / "trunc.png"
    bad.write_bytes(good.read_bytes()[:300])
    res = _run("scan", bad, "-o", tmp_path / "o.png", "--z", "1")
    assert res.exit_code == 2 and "cannot read" in res.output
    assert not (tmp_path / "o.png").exists()
    np.save(tmp_path / "hm.npy", np.zeros((5, 50)))
    res = _run("scan", good, "-o", tmp_path / "o.png", "--height-map", tmp_path / "hm.npy")
    assert res.exit_code == 2 and "aspect ratio" in res.output
    res = _run("scan", good, "-o", tmp_path / "o.jpg", "--z", "1")
    assert res.exit_code == 2 and "-o" in res.output
    nodpi = tmp_path / "nodpi.png"
    Image.fromarray(np.full((40, 40), 255, np.uint8)).save(nodpi)
    res = _run("scan", nodpi, "-o", tmp_path / "o.png", "--z", "1")
    assert res.exit_code == 2 and "--dpi" in res.output
    res = _run("chart", "bogus", "-o", tmp_path / "c.png")
    assert res.exit_code == 2 and "KIND" in res.output


def test_coarse_document_warns(tmp_path):
    _ok(_run("chart", "edge", "-o", tmp_path / "e.png", "--dpi", "300"))
    res = _ok(_run("scan", tmp_path / "e.png", "-o", tmp_path / "o.png", "--z", "1"))
    assert "at least 600 dpi is recommended" in res.output


def test_memory_estimate_refuses_huge_documents(tmp_path):
    p = tmp_path / "big.png"
    Image.new("L", (4000, 3000), 255).save(p, dpi=(1200, 1200))
    with pytest.raises(ImageError, match=r"needs about .* GiB .* available"):
        read_document(p, memory_limit_bytes=10_000_000)
    doc, dpi = read_document(p)
    assert doc.dtype == np.float32 and doc.shape == (3000, 4000) and dpi == 1200


def test_edit_distance_and_cer():
    assert edit_distance("kitten", "sitting") == 3
    assert edit_distance("", "abc") == 3
    assert character_error_rate("a  b\nc", "a b c") == 0.0
    assert character_error_rate("abcd", "abed") == 0.25


@needs_tesseract
def test_ocr_reads_the_simulated_scans():
    """Paper Fig. 8: 8-pt characters are read at every distance up to 2.5 mm."""
    doc, truth = text_chart(1200.0)
    d = load_design("paper2016")
    for z in (0.5, 2.5):
        r = simulate_scan(doc, 1200.0, d, z_mm=z, seed=1)
        cer = character_error_rate(truth, recognise(linear_to_srgb(r.image), r.dpi))
        assert cer < 0.02, (z, cer)


@needs_tesseract
def test_ocr_eval_command(tmp_path):
    _ok(_run("chart", "text", "-o", tmp_path / "t.png"))
    res = _ok(
        _run(
            "ocr-eval", tmp_path / "t.png", "--text", tmp_path / "t.txt", "--z", "0.5,4.5", "--json"
        )
    )
    d = json.loads(res.stdout)
    assert d["z_mm"] == [0.5, 4.5] and len(d["cer"]) == 2
    assert d["cer"][0] < 0.02 and d["cer"][1] >= d["cer"][0]


def test_sfr_both_axes_on_a_scanned_square(tmp_path):
    """chart edge -> scan -> sfr --direction both: motion smear makes y softer than x."""
    _ok(_run("chart", "edge", "-o", tmp_path / "e.png"))
    _ok(_run("scan", tmp_path / "e.png", "-o", tmp_path / "s.tif", "--z", "1", "--noiseless"))
    res = _ok(_run("sfr", tmp_path / "s.tif", "--direction", "both", "--json"))
    d = json.loads(res.stdout)
    assert d["x"]["direction"] == "x" and d["y"]["direction"] == "y"
    assert d["y"]["mtf50_cy_per_mm"] < d["x"]["mtf50_cy_per_mm"]


def test_user_illumination_profile_is_corrected_by_shading(tmp_path):
    """A user-given light-guide profile darkens the raw signal where it dips, and the
    white calibration takes it out again."""
    _ok(_run("chart", "edge", "-o", tmp_path / "e.png", "--dpi", "600"))
    (tmp_path / "ill.csv").write_text("# x_mm,relative\n0,1.0\n4,0.5\n8,1.0\n20,1.0\n")
    _ok(
        _run(
            "scan",
            tmp_path / "e.png",
            "-o",
            tmp_path / "a.tif",
            "--z",
            "0.5",
            "--noiseless",
            "--illumination",
            tmp_path / "ill.csv",
        )
    )
    _ok(_run("scan", tmp_path / "e.png", "-o", tmp_path / "b.tif", "--z", "0.5", "--noiseless"))
    a = tifffile.imread(tmp_path / "a.tif").astype(float)
    b = tifffile.imread(tmp_path / "b.tif").astype(float)
    assert np.abs(a - b).max() <= 2  # 16-bit rounding


def test_chart_text_of_any_size_and_face(tmp_path):
    """`chart text --points 2.5 --face serif` writes the chart ocr-eval reads at that size
    (the same pixels as text_chart) and its ground truth beside it."""
    from opticalstamp.imaging.charts import text_chart

    _ok(_run("chart", "text", "-o", tmp_path / "t.png", "--points", "2.5", "--face", "serif"))
    want, truth = text_chart(1200.0, 2.5, face="serif")
    with Image.open(tmp_path / "t.png") as im:
        got = np.asarray(im)
    assert got.shape == want.shape and (tmp_path / "t.txt").read_text() == truth + "\n"
    _ok(_run("chart", "text", "-o", tmp_path / "t8.png"))
    with Image.open(tmp_path / "t8.png") as im:
        assert im.size[0] > 2 * got.shape[1]  # 8-pt sans by default: a larger chart
