"""The tool's own images are decoded right by default (issue: a scan's sRGB PNG measured
as linear read RMTF 0.43 instead of 0.76)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from edges import run
from opticalstamp.io.files import encode_png, encode_tiff16, image_encoding


def test_encodings_are_stated_and_read_back(tmp_path):
    v = np.linspace(0, 1, 64 * 64).reshape(64, 64)
    (tmp_path / "s.png").write_bytes(encode_png(v, 300))
    (tmp_path / "l.png").write_bytes(encode_png(v, 300, srgb=False))
    (tmp_path / "t.tif").write_bytes(encode_tiff16(v, 300))
    Image.fromarray((v * 255).astype(np.uint8)).save(tmp_path / "u.png")
    assert image_encoding(tmp_path / "s.png") == "srgb"
    assert image_encoding(tmp_path / "l.png") == "linear"
    assert image_encoding(tmp_path / "t.tif") == "linear"
    assert image_encoding(tmp_path / "u.png") == "untagged"


@pytest.fixture(scope="module")
def scanned(tmp_path_factory):
    d = tmp_path_factory.mktemp("scan")
    assert run(["chart", "bars", "-o", d / "bars.png"]).exit_code == 0
    res = run(["scan", d / "bars.png", "-o", d / "s.png", "--z", "1", "--noiseless"])
    assert res.exit_code == 0, res.output
    return d


def _rmtf(path, *extra):
    res = run(["measure-rmtf", path, "--json", *extra])
    assert res.exit_code == 0, res.output
    return {round(b["dpi"], -1): b["rmtf"] for b in json.loads(res.stdout)["blocks"]}, res


def test_measure_rmtf_reads_the_scans_png_as_its_tiff(scanned):
    png, _ = _rmtf(scanned / "s.png")
    tif, _ = _rmtf(scanned / "s.tif")
    assert png.keys() == tif.keys()
    for k in png:
        assert png[k] == pytest.approx(tif[k], abs=0.01)
    stored, _ = _rmtf(scanned / "s.png", "--as-stored")  # the old reading: far too low
    assert stored[200.0] < png[200.0] - 0.15


def test_untagged_8bit_image_warns_naming_linear(scanned, tmp_path):
    with Image.open(scanned / "s.png") as im:
        im.load()
        Image.fromarray(np.asarray(im)).save(tmp_path / "u.png", dpi=(300, 300))
    _, res = _rmtf(tmp_path / "u.png")
    assert "--linear" in res.stderr and "without colour information" in res.stderr
    _, res = _rmtf(tmp_path / "u.png", "--linear")
    assert "warning" not in res.stderr
