"""Measuring images: slanted-edge SFR against known kernels, bar-chart RMTF."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d
from scipy.special import ndtr

from opticalstamp.imaging.measure import measure_rmtf, sfr


def _edge(kernel: str, size: float, angle_deg: float = 5.0, shape=(200, 120)):
    ny, nx = shape
    yy, xx = np.mgrid[0:ny, 0:nx].astype(float)
    a = np.radians(angle_deg)
    d = ((xx - nx / 2) - np.tan(a) * (yy - ny / 2)) * np.cos(a)  # perpendicular distance
    if kernel == "gauss":
        return 0.1 + 0.8 * ndtr(d / size)
    return np.clip((d + size / 2) / size, 0, 1)  # box of width `size` px


@pytest.mark.parametrize("sigma", [0.8, 1.5, 3.0])
def test_sfr_of_gaussian_edge(sigma):
    """MTF of a Gaussian of sigma px: exp(-2 pi^2 sigma^2 f^2); MTF50 in closed form.
    Tolerance 0.02: ISO 12233 leaves the 1/4-px binning's sinc uncorrected."""
    dpi = 300.0
    r = sfr(_edge("gauss", sigma), dpi)
    f = r["freq_cy_per_mm"] * 25.4 / dpi
    m = f <= 0.5
    np.testing.assert_allclose(r["sfr"][m], np.exp(-2 * np.pi**2 * sigma**2 * f[m] ** 2), atol=0.02)
    f50 = np.sqrt(np.log(2) / (2 * np.pi**2 * sigma**2)) * dpi / 25.4
    assert r["mtf50_cy_per_mm"] == pytest.approx(f50, rel=0.02)
    assert r["edge_angle_deg"] == pytest.approx(-5.0, abs=0.05) or r["edge_angle_deg"] == (
        pytest.approx(5.0, abs=0.05)
    )
    assert r["direction"] == "x"


@pytest.mark.parametrize("width", [2.0, 3.0])
def test_sfr_of_box_edge_along_y(width):
    """A box of width b px: |sinc(b f)|; a near-horizontal edge gives the SFR along y."""
    r = sfr(_edge("box", width).T, 600.0)
    assert r["direction"] == "y"
    f = r["freq_cy_per_mm"] * 25.4 / 600.0
    m = f <= 0.5
    np.testing.assert_allclose(r["sfr"][m], np.abs(np.sinc(width * f[m])), atol=0.02)


def test_sfr_value_at_the_paper_frequencies():
    r = sfr(_edge("gauss", 1.0), 300.0)
    f200 = 200 / 50.8 * 25.4 / 300  # 200 dpi chart fundamental, cycles per pixel
    assert r["sfr_at_dpi"]["200"] == pytest.approx(np.exp(-2 * np.pi**2 * f200**2), abs=0.02)


def test_sfr_rejects_aligned_edges_and_flat_images():
    with pytest.raises(ValueError, match="too close to the pixel grid"):
        sfr(_edge("gauss", 1.0, angle_deg=0.0), 300.0)
    with pytest.raises(ValueError):
        sfr(np.ones((50, 50)), 300.0)
    with pytest.raises(ValueError, match="dpi"):
        sfr(_edge("gauss", 1.0), 0)


def _chart(dpi: float, blocks, blur_um: float, n=3200):
    px = 25400 / dpi
    x = (np.arange(n) + 0.5) * px
    fine = 8  # area-average each pixel over 8 sub-samples
    xs = ((np.arange(n * fine) + 0.5) / fine) * px
    f = np.ones_like(xs)
    for per, a, b in blocks:
        sel = (xs > a) & (xs < b)
        f[sel] = ((xs[sel] - a) % per) < per / 2
    prof = gaussian_filter1d(f, blur_um / px * fine).reshape(n, fine).mean(axis=1)
    return x, prof, np.tile(prof, (40, 1))


def test_measure_rmtf_finds_blocks_and_values():
    dpi = 1200.0
    blocks = [(508.0, 2000, 9000), (254.0, 11000, 17000), (205.7, 19000, 25000)]
    x, prof, img = _chart(dpi, blocks, blur_um=40.0)
    got = measure_rmtf(img, dpi)
    nominal = (100, 150, 200, 247)
    assert [min(nominal, key=lambda d, b=b: abs(d - b["dpi"])) for b in got] == [100, 200, 247]
    for b, (per, a, e) in zip(got, blocks, strict=True):
        assert b["period_um"] == pytest.approx(per, rel=0.01)
        inner = (x > a + per) & (x < e - per)
        imax, imin = prof[inner].max(), prof[inner].min()
        assert b["rmtf"] == pytest.approx((imax - imin) / (imax + imin), abs=0.01)
    # more blur, less contrast, same order of blocks
    low = measure_rmtf(_chart(dpi, blocks, blur_um=90.0)[2], dpi)
    assert all(lo["rmtf"] < hi["rmtf"] for lo, hi in zip(low, got, strict=True))


def test_measure_rmtf_bars_along_y_and_errors():
    _, _, img = _chart(1200.0, [(254.0, 2000, 9000)], blur_um=30.0, n=1000)
    got = measure_rmtf(img.T, 1200.0, axis=1)
    assert len(got) == 1 and got[0]["period_um"] == pytest.approx(254, rel=0.01)
    with pytest.raises(ValueError, match="dpi"):
        measure_rmtf(img, -3)
    assert measure_rmtf(np.full((20, 500), 0.5), 600.0) == []


def test_sfr_along_x_and_y_of_a_slanted_square():
    """A dark square tilted by 5 degrees, blurred by a Gaussian of sigma px: both edges
    give exp(-2 pi^2 sigma^2 f^2)."""
    from opticalstamp.imaging.measure import sfr_xy

    n, sig, a = 240, 1.3, np.radians(5.0)
    yy, xx = np.mgrid[0:n, 0:n].astype(float) - n / 2
    u = xx * np.cos(a) + yy * np.sin(a)
    v = -xx * np.sin(a) + yy * np.cos(a)
    # distance outside the square |u|, |v| < n/4 (exact near the edges' middles)
    d = np.maximum(np.abs(u), np.abs(v)) - n / 4
    img = 0.05 + 0.9 * ndtr(d / sig)
    res = sfr_xy(img, 600.0)
    for axis in ("x", "y"):
        r = res[axis]
        assert r["direction"] == axis
        f = r["freq_cy_per_mm"] * 25.4 / 600.0
        m = f <= 0.4
        np.testing.assert_allclose(
            r["sfr"][m], np.exp(-2 * np.pi**2 * sig**2 * f[m] ** 2), atol=0.02
        )


@pytest.mark.parametrize("amp, sigma", [(0.3, 0.01), (0.1, 0.02)])
def test_fundamental_amplitude_cnr_and_overshoot(amp, sigma):
    """A sinusoidal chart 0.5 + amp cos (period 254 um at 300 dpi) with white noise: the
    fitted amplitude over the ideal's 2/pi, the contrast to noise 2 amp / sigma, and the
    overshoot past white or black, as constructed; the RMTF of an overshooting chart
    clipped to [0, 1] is pinned at 1 while its amplitude is not."""
    dpi = 300.0
    px = 25400.0 / dpi
    x = (np.arange(600) + 0.5) * px
    rows = 200
    rng = np.random.default_rng(1)
    prof = 0.5 + amp * np.cos(2 * np.pi * x / 254.0)
    prof[(x < 3000) | (x > 47000)] = 0.5
    img = prof[None, :] + sigma * rng.standard_normal((rows, x.size))
    (b,) = [b for b in measure_rmtf(img, dpi) if abs(b["period_um"] - 254) < 5]
    assert b["amplitude_rel"] == pytest.approx(amp / (2 / np.pi), rel=0.02)
    assert b["cnr"] == pytest.approx(2 * amp / sigma, rel=0.05)
    over = np.clip(0.5 + 0.7 * np.cos(2 * np.pi * x / 254.0), -1, 2)[None, :].repeat(20, 0)
    (o,) = [b for b in measure_rmtf(over, dpi) if abs(b["period_um"] - 254) < 5]
    assert o["overshoot"] == pytest.approx(0.2, abs=0.02)
    (c,) = [b for b in measure_rmtf(np.clip(over, 0, 1), dpi) if abs(b["period_um"] - 254) < 5]
    assert c["rmtf"] == pytest.approx(1.0) and c["amplitude_rel"] < 1.0


def test_chart_blocks_of_any_resolution_are_drawn_and_found(tmp_path):
    """`chart bars --blocks`: a 600-dpi design's depth-of-field chart (400 dpi) among the
    blocks; :func:`measure_rmtf` finds each block of the chart image itself at its own
    resolution, every one of them sharp (RMTF above 0.9: drawn, not scanned)."""
    from typer.testing import CliRunner

    from opticalstamp.cli import app
    from opticalstamp.io.files import read_image

    out = tmp_path / "bars.png"
    res = CliRunner().invoke(
        app, ["chart", "bars", "-o", str(out), "--dpi", "2400", "--blocks", "100,200,400"]
    )
    assert res.exit_code == 0, res.output
    img, dpi = read_image(out, linear=True)
    assert dpi == pytest.approx(2400, rel=1e-3)
    found = measure_rmtf(img, dpi)
    assert sorted(round(b["dpi"]) for b in found) == [100, 200, 400]
    assert min(b["rmtf"] for b in found) > 0.9
