"""Scan simulation: metrics on simulated scans, shading, noise statistics, bookkeeping."""

from __future__ import annotations

import numpy as np
import pytest

from opticalstamp.analysis.paraxial import paraxial_etendue
from opticalstamp.analysis.rmtf import rmtf
from opticalstamp.design import design_from_dict, load_design
from opticalstamp.imaging.charts import bar_chart
from opticalstamp.imaging.heightmap import HeightMapError, load_height_map, shape_map
from opticalstamp.imaging.kernels import paraxial_kernel, scan_kernels, separable_terms
from opticalstamp.imaging.measure import measure_rmtf
from opticalstamp.imaging.scan import ScanSettings, simulate_scan
from opticalstamp.imaging.sensor import SensorModel

PITCH = 84.6


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


@pytest.mark.parametrize("z", [0.5, 1.5, 2.5, 3.5])
def test_rmtf_measured_on_scan_matches_computed(paper, z):
    """247 dpi (206 um, incommensurate with 84.6 um): every chart position gives the same
    RMTF, so the scan of a 2400-dpi chart must measure the computed value."""
    doc = bar_chart(2400.0, chart_dpi=(247.0,), block_mm=8.0, height_mm=3.0)
    r = simulate_scan(doc, 2400.0, paper, z_mm=z, noiseless=True, ghosts=False)
    n = r.image.shape[0]
    got = measure_rmtf(r.image, r.dpi, rows=(n // 3, 2 * n // 3))  # inside the bars
    ref = rmtf(paper, dpi=(247.0,), z_mm=(z,), method="paraxial", window_um=6000.0)
    lo, hi = ref.rmtf_min["247"][0], ref.rmtf_max["247"][0]
    if hi < 0.05:  # beyond the null near 3.3 mm: too little contrast to find the bars
        return
    assert len(got) == 1
    assert lo - 0.015 <= got[0]["rmtf"] <= hi + 0.015, (got[0]["rmtf"], lo, hi)


def test_rmtf_200dpi_within_shift_range_with_traced_kernel(paper):
    doc = bar_chart(2400.0, chart_dpi=(200.0,), block_mm=8.0, height_mm=3.0)
    st = ScanSettings(kernel="trace")
    r = simulate_scan(doc, 2400.0, paper, z_mm=2.0, noiseless=True, ghosts=False, settings=st)
    n = r.image.shape[0]
    got = measure_rmtf(r.image, r.dpi, rows=(n // 3, 2 * n // 3))[0]["rmtf"]
    ref = rmtf(paper, dpi=(200.0,), z_mm=(2.0,), method="paraxial", window_um=6000.0)
    assert ref.rmtf_min["200"][0] - 0.02 <= got <= ref.rmtf_max["200"][0] + 0.02


def test_white_page_is_flat_after_shading(paper):
    doc = np.ones((300, 400))
    st = ScanSettings(surround=1.0, illumination="ripple", ripple_period_mm=3.0)
    r = simulate_scan(doc, 1200.0, paper, z_mm=0.0, noiseless=True, settings=st)
    np.testing.assert_allclose(r.image, 1.0, atol=1e-6)  # float32 passes
    # with noise: flat on average, pixel to pixel within the photon statistics
    rn = simulate_scan(doc, 1200.0, paper, z_mm=0.0, settings=st, seed=3)
    assert abs(rn.image.mean() - 1) < 2e-3
    col_means = rn.image.mean(axis=0)
    assert col_means.std() < 5 * rn.image.std() / np.sqrt(rn.image.shape[0])


def _electrons(r, st: SensorModel, row: int = 0) -> np.ndarray:
    return r.raw[row] * st.gain_e_per_dn


def test_black_page_gives_zero_plus_expected_noise(paper):
    sm = SensorModel()
    doc = np.zeros((400, 400))  # a black page with the lid open (a black surround)
    st = ScanSettings(surround=0.0)
    r = simulate_scan(doc, 1200.0, paper, z_mm=1.0, seed=1, ghosts=False, settings=st)
    assert abs(r.image.mean()) < 5e-4
    white_e = (r.white[0] - r.dark[0]).mean() * sm.gain_e_per_dn
    sigma_e = np.sqrt(sm.read_noise_e**2 + sm.dark_e + sm.gain_e_per_dn**2 / 12)
    # temporal noise per pixel (the fixed DSNU cancels in the dark subtraction)
    got = r.image[:, :].std(axis=0).mean() * white_e
    assert got == pytest.approx(sigma_e, rel=0.1)


def test_noise_variance_follows_photon_statistics(paper):
    sm = SensorModel(read_noise_e=0.0, prnu=0.0, dsnu_e=0.0, adc_bits=20)
    st = ScanSettings(sensor=sm, surround=0.5)
    doc = np.full((1200, 60), 0.5)
    r = simulate_scan(doc, 1200.0, paper, z_mm=0.0, seed=5, settings=st)
    e = _electrons(r, sm)
    mean, var = e.mean(axis=0), e.var(axis=0, ddof=1)
    expect = mean + sm.gain_e_per_dn**2 / 12  # Poisson (dark included) + quantisation
    n = e.shape[0]
    # the variance of a sample variance is 2 var^2 / (n - 1): check the average ratio
    ratio = (var / expect).mean()
    assert ratio == pytest.approx(1.0, abs=4 * np.sqrt(2 / (n - 1) / var.size))
    # and the mean electrons are the radiometry: E/pi * etendue * rate * QE * t * rho
    k = scan_kernels(paper, [0.0], ghosts=True)[0][0]
    pred = 0.5 * (k.own_etendue + k.ghost_etendue) * sm.electrons_per_um2sr + sm.dark_e
    assert mean.mean() == pytest.approx(pred, rel=0.01)


def test_feature_position_orientation_and_row_delay(paper):
    """A dot at a known (x, y) appears at output pixel (x / L - 1/2, y / L - 1/2); a
    horizontal line is found on the same output line by row A and row B columns."""
    dpi = 1200.0
    p = 25400.0 / dpi
    doc = np.ones((600, 900))
    x0, y0 = 3000.0, 5000.0  # um: left of and above the centre
    doc[int(y0 / p) - 2 : int(y0 / p) + 3, int(x0 / p) - 2 : int(x0 / p) + 3] = 0.0
    r = simulate_scan(doc, dpi, paper, z_mm=0.0, noiseless=True, ghosts=False)
    iy, ix = np.unravel_index(np.argmin(r.image), r.image.shape)
    assert abs(ix - (x0 / PITCH - 0.5)) <= 0.6
    assert abs(iy - (y0 / PITCH - 0.5)) <= 0.6
    line = np.ones((600, 900))
    line[300:302, :] = 0.0  # horizontal line at y = 301 p
    st = ScanSettings(surround=1.0)
    r = simulate_scan(line, dpi, paper, z_mm=0.5, noiseless=True, ghosts=False, settings=st)
    prof_a = 1 - r.image[:, 10:-10:2].mean(axis=1)
    prof_b = 1 - r.image[:, 11:-10:2].mean(axis=1)
    y = np.arange(prof_a.size)
    ya = (y * prof_a).sum() / prof_a.sum()
    yb = (y * prof_b).sum() / prof_b.sum()
    assert abs(ya - yb) < 0.05  # a wrong delay would put them a line or more apart
    assert abs(ya - (301 * p / PITCH - 0.5)) < 0.1


def test_vertical_and_slanted_lines_stay_straight(paper):
    dpi = 1200.0
    p = 25400.0 / dpi
    doc = np.ones((800, 800))
    doc[:, 150:154] = 0.0  # one 300-dpi pixel wide (4 x 21.2 um), output column ~38
    yy, xx = np.mgrid[0:800, 0:800]
    doc[np.abs(xx - 400 - 0.3 * yy) < 2] = 0.0  # a slanted line, columns ~100-160
    st = ScanSettings(surround=1.0)
    r = simulate_scan(doc, dpi, paper, z_mm=1.0, noiseless=True, ghosts=False, settings=st)
    img = 1 - r.image[5:-5]
    # vertical line: its centroid column is the same on every line
    cols = np.arange(img.shape[1])
    band = img[:, 25:52]
    cen = (band * cols[25:52]).sum(axis=1) / band.sum(axis=1)
    assert cen.std() < 0.02
    # slanted line: centroids on a straight line, no alternating (zig-zag) residual
    y_lines = np.arange(img.shape[0])
    x_exp = (400 + 0.3 * ((y_lines + 5 + 0.5) * PITCH / p)) * p / PITCH - 0.5
    cs = []
    for i, xe in enumerate(x_exp):
        lo, hi = int(xe) - 6, int(xe) + 7
        w = img[i, lo:hi]
        cs.append((w * cols[lo:hi]).sum() / w.sum())
    res = np.asarray(cs) - np.polyval(np.polyfit(y_lines, cs, 1), y_lines)
    zigzag = np.abs(np.mean(res[::2]) - np.mean(res[1::2]))
    assert zigzag < 0.05 and np.abs(res).max() < 0.2


def test_height_map_blur_follows_height(paper):
    doc = bar_chart(1200.0, chart_dpi=(150.0,), block_mm=8.0, height_mm=24.0)
    h_mm, w_mm = doc.shape[0] * 25.4 / 1200, doc.shape[1] * 25.4 / 1200
    hm = shape_map("tilt:0:4", h_mm, w_mm)
    r = simulate_scan(doc, 1200.0, paper, height_map=hm, noiseless=True, ghosts=False)
    n = r.image.shape[0]
    top = measure_rmtf(r.image, r.dpi, rows=(int(0.1 * n), int(0.2 * n)))[0]["rmtf"]
    bottom = measure_rmtf(r.image, r.dpi, rows=(int(0.75 * n), int(0.85 * n)))[0]["rmtf"]
    assert top > bottom + 0.2
    # a flat height map equals the constant-Z scan
    flat = simulate_scan(
        doc, 1200.0, paper, height_map=np.full((4, 4), 1.0), noiseless=True, ghosts=False
    )
    const = simulate_scan(doc, 1200.0, paper, z_mm=1.0, noiseless=True, ghosts=False)
    np.testing.assert_allclose(flat.image, const.image, atol=1e-9)


def test_height_maps_shapes_and_errors(tmp_path):
    a = shape_map("crumple:1:10", 50, 40, seed=4)
    b = shape_map("crumple:1:10", 50, 40, seed=4)
    np.testing.assert_array_equal(a, b)
    assert a.min() == 0 and a.max() == pytest.approx(1.0)
    g = shape_map("gutter:3:40", 50, 40)
    assert g.max() == pytest.approx(3.0) and g[:, 0].max() < 3.0
    np.save(tmp_path / "bad.npy", np.zeros((10, 30)))
    with pytest.raises(HeightMapError, match="aspect"):
        load_height_map(str(tmp_path / "bad.npy"), 50, 40)
    np.save(tmp_path / "high.npy", np.full((50, 40), 12.0))
    with pytest.raises(HeightMapError, match="outside the modelled range"):
        load_height_map(str(tmp_path / "high.npy"), 50, 40)
    with pytest.raises(HeightMapError, match="unknown shape|neither"):
        load_height_map("wobble:3", 50, 40)


def test_colour_channels(paper):
    doc = np.ones((300, 300, 3))
    doc[100:200, 100:200] = [0.9, 0.1, 0.1]  # a red square
    r = simulate_scan(
        doc,
        1200.0,
        paper,
        z_mm=0.5,
        noiseless=True,
        color=True,
        ghosts=False,
        settings=ScanSettings(surround=1.0),
    )
    assert r.image.shape[2] == 3
    centre = r.image[30:40, 30:40]
    assert centre[..., 0].mean() == pytest.approx(0.9, abs=0.02)
    assert centre[..., 1].mean() == pytest.approx(0.1, abs=0.02)
    np.testing.assert_allclose(r.image[2:8, 2:60], 1.0, atol=1e-6)


def test_speed_error_stretches_the_page(paper):
    doc = np.ones((900, 200))
    doc[700:703, :] = 0.0
    fast = simulate_scan(
        doc,
        1200.0,
        paper,
        z_mm=0.0,
        noiseless=True,
        ghosts=False,
        settings=ScanSettings(speed_error=0.1, surround=1.0),
    )
    y_line = np.argmin(fast.image.mean(axis=1))
    y0 = 701.5 * 25400 / 1200
    assert abs(y_line - (y0 / (PITCH * 1.1) - 0.5)) <= 1


def test_kernels(paper):
    k = paraxial_kernel(paper, 1.0)
    assert k.own_etendue == pytest.approx(paraxial_etendue(paper), rel=1e-6)
    tk = scan_kernels(paper, [1.0], source="trace", ghosts=False, n_rays=1 << 20)[0][0]
    assert tk.own_etendue == pytest.approx(paraxial_etendue(paper), rel=0.01)
    m = np.outer(np.hanning(20), np.hamming(30))
    s, u, v = separable_terms(m)
    assert s.size == 1
    np.testing.assert_allclose(s[0] * np.outer(u[0], v[0]), m, atol=1e-12)
    circ = paper.model_dump(mode="json", exclude_none=True)
    for sl in circ["slabs"]:
        sl["mask_top"]["shape"] = "circle"
    cd = design_from_dict(circ)
    with pytest.raises(ValueError, match="rectangular"):
        scan_kernels(cd, [1.0], source="paraxial")
    ck = scan_kernels(cd, [1.0], ghosts=False, n_rays=1 << 20)[0][0]
    assert ck.scale.size > 1  # a disk-like map is not separable


def test_scan_rejects_bad_input(paper):
    with pytest.raises(ValueError, match="z_mm"):
        simulate_scan(np.ones((50, 50)), 1200.0, paper, z_mm=-1.0)
    with pytest.raises(ValueError, match="dpi"):
        simulate_scan(np.ones((50, 50)), -5.0, paper, z_mm=1.0)
    with pytest.raises(ValueError, match="outside the modelled range"):
        simulate_scan(np.ones((50, 50)), 1200.0, paper, height_map=np.full((3, 3), 20.0))


def test_motion_smear_adds_a_box_of_one_line(paper):
    """The pixel integrates while the page moves one line: the y weights are the kernel
    convolved with a box of width duty x L, which adds (duty L)^2 / 12 to their variance
    (the box is sampled by the midpoint rule at n = 9 points: (n^2 - 1) / (12 n^2) L^2)."""
    from opticalstamp.imaging.scan import _taps

    k = paraxial_kernel(paper, 2.0)
    p = 0.5
    centre = np.array([1000.0])

    def variance(smear: float) -> float:
        i0, w = _taps(k, 0, centre, p, smear)
        y = (i0[0] + np.arange(w.shape[2]) + 0.5) * p
        wt = w[0, 0]
        m = (y * wt).sum() / wt.sum()
        return ((y - m) ** 2 * wt).sum() / wt.sum()

    n = 9
    expected = PITCH**2 * (n * n - 1) / (12 * n * n)
    assert variance(PITCH) - variance(0.0) == pytest.approx(expected, rel=1e-3)
    assert expected == pytest.approx(PITCH**2 / 12, rel=0.02)
