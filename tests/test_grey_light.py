"""A colour scanner's grey scans by wave optics (issue 23, "light as it is"): its three
LEDs lit together at the luminance weights (``spectrum.grey_light``), the wave scan
kernels under that light, and a colour scan through wave kernels refused by name."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from opticalstamp.analysis.responsivity import resolve_optics
from opticalstamp.analysis.spectrum import channels, grey_light
from opticalstamp.analysis.wavespectral import wave_response_spectral
from opticalstamp.cli import app
from opticalstamp.design import load_design
from opticalstamp.design.electronics import LUMA
from opticalstamp.design.variants import replace
from opticalstamp.imaging.charts import bar_chart
from opticalstamp.imaging.kernels import GREY_POINTS, wave_near_kernels
from opticalstamp.imaging.scan import ScanSettings, simulate_scan

RGB = ("red", "green", "blue")


@pytest.fixture(scope="module")
def rgb():
    return replace(load_design("paper2016"), {"electronics.illumination": "rgb"})


def test_grey_light_is_the_channels_at_the_luminance_weights(rgb):
    """The grey light's wavelengths are the three channels', each weight its channel's
    times that channel's luminance weight; one channel's design keeps its own light."""
    g = grey_light(rgb)
    ch = channels(rgb)
    assert g.wavelengths_um == sum((ch[n].wavelengths_um for n in RGB), ())
    parts = [luma * np.asarray(ch[n].weights) for n, luma in zip(RGB, LUMA, strict=True)]
    want = np.concatenate(parts)
    np.testing.assert_allclose(g.weights, want, rtol=1e-12)
    assert sum(g.weights) == pytest.approx(1.0, abs=1e-12)
    mono = load_design("paper2016")
    assert grey_light(mono) == channels(mono)["mono"]
    white = replace(mono, {"electronics.illumination": "white"})
    assert grey_light(white) == channels(white)["white"]


def test_wave_kernels_of_a_colour_scanner_hold_its_grey_light(rgb):
    """The wave kernels take the grey light: the engine under it gives the luminance-
    weighted sum of the channels' light (1e-9), and the kernel (its map binned and
    SVD-separated, one wavelength per LED: GREY_POINTS) holds that light to 2e-4; not
    the green channel's, which differs by 0.3 %."""
    z = 1.0
    smp = resolve_optics(rgb, "wave", channels=True).sampling
    lights = {
        n: float(wave_response_spectral(rgb, [z], spectrum=s, sampling=smp).etendue_um2sr[0])
        for n, s in channels(rgb, None, GREY_POINTS).items()
    }
    mix = sum(luma * lights[n] for n, luma in zip(RGB, LUMA, strict=True))
    grey = wave_response_spectral(rgb, [z], spectrum=grey_light(rgb, GREY_POINTS), sampling=smp)
    assert float(grey.etendue_um2sr[0]) == pytest.approx(mix, rel=1e-9)
    (k,) = wave_near_kernels(rgb, [z], 0)
    assert k.own_etendue == pytest.approx(mix, rel=2e-4)
    assert abs(lights["green"] / mix - 1) > 1e-3  # the test tells the lights apart


def test_a_colour_scanners_grey_scan_takes_wave_kernels(rgb):
    """A grey scan of an rgb design through wave kernels runs and says so; a colour scan
    through them is refused, naming --color (not a silent grey kernel for every LED)."""
    doc = bar_chart(600, chart_dpi=(100.0,), block_mm=3.0, height_mm=1.0)
    st = ScanSettings(kernel="wave", sensor=rgb.electronics)
    r = simulate_scan(doc, 600, rgb, z_mm=1.0, settings=st, ghosts=False, noiseless=True)
    assert r.meta["kernel_source"] == "wave" and np.isfinite(r.image).all()
    with pytest.raises(ValueError, match="--color"):
        simulate_scan(doc, 600, rgb, z_mm=1.0, settings=st, ghosts=False, color=True)


def test_cli_colour_scan_through_wave_kernels_exits_2(rgb, tmp_path):
    design = tmp_path / "rgb.toml"
    runner = CliRunner()
    text = runner.invoke(app, ["presets", "show", "paper2016"]).output
    design.write_text(text + '\n[electronics]\nillumination = "rgb"\n')
    doc = tmp_path / "bars.png"
    assert runner.invoke(app, ["chart", "bars", "-o", str(doc)]).exit_code == 0
    res = runner.invoke(
        app,
        ["scan", str(doc), "-o", str(tmp_path / "s.png"), "-d", str(design), "--z", "1",
         "--color", "--kernel", "wave"],
    )  # fmt: skip
    assert res.exit_code == 2 and "--color" in res.output
    assert not (tmp_path / "s.png").exists()
