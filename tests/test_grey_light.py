"""A colour scanner's grey scans by wave optics (issue 23, "light as it is"): its three
LEDs lit together at the luminance weights (``spectrum.grey_light``), the wave scan
kernels under that light, and its colour scans through each LED's own wave kernels."""

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
from opticalstamp.imaging.measure import measure_rmtf
from opticalstamp.imaging.scan import ScanSettings, led_designs, simulate_scan

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
    weighted sum of the channels' responses (each channel run on its own: light 1e-9,
    x LSF in L1 to 1e-4 against the channels' LSFs carried to the grey grid by linear
    interpolation), and the kernel (its map binned and SVD-separated, one wavelength per
    LED: GREY_POINTS) holds that light to 2e-4; not the green channel's, 0.3 % away."""
    z = 1.0
    smp = resolve_optics(rgb, "wave", channels=True).sampling
    each = {
        n: wave_response_spectral(rgb, [z], spectrum=s, sampling=smp)
        for n, s in channels(rgb, None, GREY_POINTS).items()
    }
    lights = {n: float(r.etendue_um2sr[0]) for n, r in each.items()}
    mix = sum(luma * lights[n] for n, luma in zip(RGB, LUMA, strict=True))
    grey = wave_response_spectral(rgb, [z], spectrum=grey_light(rgb, GREY_POINTS), sampling=smp)
    assert float(grey.etendue_um2sr[0]) == pytest.approx(mix, rel=1e-9)
    lsf = sum(
        luma * np.interp(grey.x_um, each[n].x_um, each[n].lsf_x[0], left=0, right=0)
        for n, luma in zip(RGB, LUMA, strict=True)
    )
    l1 = np.abs(lsf - grey.lsf_x[0]).sum() / grey.lsf_x[0].sum()
    assert l1 < 1e-4
    green = np.interp(grey.x_um, each["green"].x_um, each["green"].lsf_x[0], left=0, right=0)
    assert np.abs(green - grey.lsf_x[0]).sum() / grey.lsf_x[0].sum() > 10 * l1
    (k,) = wave_near_kernels(rgb, [z], 0)
    assert k.own_etendue == pytest.approx(mix, rel=2e-4)
    assert abs(lights["green"] / mix - 1) > 1e-3  # the test tells the lights apart


def test_a_colour_scanners_scans_through_wave_kernels(rgb):
    """A grey scan of an rgb design through wave kernels is under its grey light; a colour
    scan takes each LED's own kernels (led_designs): its channels differ as the LEDs'
    diffraction does, red the softest (one kernel set for every LED would give three
    equal channels of a grey chart). Measured 200-dpi RMTF at 1 mm: red 0.598, green
    0.625, blue 0.643; grey 0.621."""
    doc = bar_chart(600, chart_dpi=(200.0,), block_mm=10.0, height_mm=4.0)
    st = ScanSettings(kernel="wave", sensor=rgb.electronics)
    leds = led_designs(rgb)
    assert [d.electronics.illumination for d in leds] == list(RGB)
    assert led_designs(load_design("paper2016")) is None

    def rmtf200(image, dpi):
        (block,) = [b for b in measure_rmtf(image, dpi) if abs(b["dpi"] - 200) < 5]
        return block["rmtf"]

    kw = dict(z_mm=1.0, settings=st, ghosts=False, noiseless=True)
    grey = simulate_scan(doc, 600, rgb, **kw)
    assert grey.meta["kernel_source"] == "wave" and grey.image.ndim == 2
    c = simulate_scan(doc, 600, rgb, color=True, **kw)
    red, green, blue = (rmtf200(c.image[..., ch], c.dpi) for ch in range(3))
    assert red < green < blue and blue - red > 0.02
    assert red < rmtf200(grey.image, grey.dpi) < blue


def test_cli_colour_scan_through_wave_kernels(rgb, tmp_path):
    """`scan --color --kernel wave` of an rgb design writes its scan (each LED's kernels)."""
    design = tmp_path / "rgb.toml"
    runner = CliRunner()
    text = runner.invoke(app, ["presets", "show", "paper2016"]).output
    design.write_text(text + '\n[electronics]\nillumination = "rgb"\n')
    doc = tmp_path / "bars.png"
    assert runner.invoke(app, ["chart", "bars", "-o", str(doc)]).exit_code == 0
    res = runner.invoke(
        app,
        ["scan", str(doc), "-o", str(tmp_path / "s.png"), "-d", str(design), "--z", "1",
         "--color", "--kernel", "wave", "--no-ghosts"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert (tmp_path / "s.png").exists() and (tmp_path / "s.json").exists()
