"""Command line of the metrics: JSON keys, plots, images, and clear errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from PIL import Image
from scipy.special import ndtr
from typer.testing import CliRunner

from opticalstamp.cli.common import app
from opticalstamp.io.files import ImageError, read_image

runner = CliRunner()


def _run(*args):
    return runner.invoke(app, list(args))


def _json(res):
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def test_rmtf_json_keys(tmp_path):
    res = _run(
        "rmtf",
        "--z",
        "0,2,4",
        "--dpi",
        "100,200",
        "--rays",
        "200000",
        "--json",
        "--plot",
        str(tmp_path / "r.png"),
    )
    d = _json(res)
    assert d["z_mm"] == [0, 2, 4]
    for key in ("rmtf_max", "rmtf_mean", "rmtf_min"):
        assert set(d[key]) == {"100", "200"} and len(d[key]["200"]) == 3
    assert set(d["dof_mm"]) == {"100", "200"}
    assert d["provenance"]["seed"] == 0 and d["provenance"]["design"] == "paper2016"
    assert (tmp_path / "r.png").stat().st_size > 1000


def test_rmtf_paraxial_and_range():
    d = _json(_run("rmtf", "--method", "paraxial", "--z", "0:1:0.5", "--json", "--no-ghosts"))
    assert d["z_mm"] == [0, 0.5, 1.0] and d["method"] == "paraxial"


@pytest.mark.parametrize(
    ("args", "text"),
    [
        (["rmtf", "--dpi", "0"], "--dpi"),
        (["rmtf", "--z", "3:1:0.5"], "--z"),
        (["rmtf", "--method", "wave"], "--method"),
        (["rmtf", "--threshold", "2"], "--threshold"),
        (["diffraction", "--wavelength-um", "5"], "--wavelength-um"),
        (["diffraction", "--slit-um", "-1"], "--slit-um"),
    ],
)
def test_bad_options_name_the_field(args, text):
    res = _run(*args)
    assert res.exit_code == 2
    assert text in res.output
    assert "Traceback" not in res.output


def test_efficiency_json_keys():
    d = _json(_run("efficiency", "--json"))
    for key in ("etendue_um2sr", "reference_etendue_um2sr", "ratio", "working_f_number"):
        assert isinstance(d[key], float)
    assert d["working_f_number"] == pytest.approx(10 / np.sqrt(d["ratio"]))


def test_diffraction_json_keys():
    d = _json(
        _run("diffraction", "--json", "--slit-um", "48", "--wavelength-um", "0.4,0.7", "--z", "1")
    )
    assert d["geometric_edge_um"] == pytest.approx(31.89, abs=0.01)
    assert set(d["fraction_outside"]) == {"0.4", "0.7"}
    assert len(d["budget"]["layers"]) == 3


def _edge_png(path, dpi=300):
    yy, xx = np.mgrid[0:160, 0:100].astype(float)
    d = ((xx - 50) - np.tan(np.radians(6)) * (yy - 80)) * np.cos(np.radians(6))
    img = (255 * ndtr(d / 1.2)).round().astype(np.uint8)
    Image.fromarray(img).save(path, dpi=(dpi, dpi))


def test_sfr_command(tmp_path):
    p = tmp_path / "edge.png"
    _edge_png(p)
    d = _json(_run("sfr", str(p), "--json", "--plot", str(tmp_path / "s.png")))
    assert d["dpi"] == pytest.approx(300, abs=0.5)
    assert d["mtf50_cy_per_mm"] > 0 and set(d["sfr_at_dpi"]) == {"100", "200"}
    res = _run("sfr", str(p), "--roi", "0,0,10")
    assert res.exit_code == 2 and "--roi" in res.output


def test_measure_rmtf_command(tmp_path):
    x = (np.arange(2400) + 0.5) * 25400 / 1200
    prof = np.where((x > 2000) & (x < 12000), ((x - 2000) % 254) < 127, 1.0)
    img = (np.tile(prof, (30, 1)) * 60000).astype(np.uint16)
    p = tmp_path / "chart.tif"
    tifffile.imwrite(p, img, resolution=(1200, 1200), resolutionunit=2)
    d = _json(_run("measure-rmtf", str(p), "--json"))
    assert d["dpi"] == pytest.approx(1200)
    assert d["blocks"][0]["period_um"] == pytest.approx(254, rel=0.01)
    assert d["blocks"][0]["rmtf"] == pytest.approx(1.0, abs=1e-6)


def test_images_without_dpi_or_broken(tmp_path):
    p = tmp_path / "nodpi.png"
    Image.fromarray(np.zeros((20, 20), np.uint8)).save(p)
    res = _run("sfr", str(p))
    assert res.exit_code == 2 and "--dpi" in res.output
    bad = tmp_path / "broken.png"
    good = tmp_path / "good.png"
    _edge_png(good)
    bad.write_bytes(good.read_bytes()[:200])
    res = _run("measure-rmtf", str(bad), "--dpi", "600")
    assert res.exit_code == 2 and "cannot read" in res.output
    with pytest.raises(ImageError, match="no such file"):
        read_image(tmp_path / "missing.png")


def test_read_image_grey_rgb_16bit(tmp_path):
    rgb = np.zeros((4, 5, 3), np.uint8)
    rgb[..., 1] = 255
    Image.fromarray(rgb).save(tmp_path / "c.png", dpi=(600, 600))
    a, dpi = read_image(tmp_path / "c.png")
    assert a.shape == (4, 5) and a.max() == pytest.approx(0.7152) and dpi == pytest.approx(600)
    g16 = np.full((3, 3), 32768, np.uint16)
    Image.fromarray(g16).save(tmp_path / "g.png")
    b, dpi = read_image(tmp_path / "g.png")
    assert b[0, 0] == pytest.approx(32768 / 65535) and dpi is None
    lin, _ = read_image(tmp_path / "g.png", linear=True)
    assert lin[0, 0] == pytest.approx(((32768 / 65535 + 0.055) / 1.055) ** 2.4)
