"""Restoration: the output-grid blur model against the scan simulation, the methods
against closed forms, and the `restore` command's refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest
import tifffile
from tests.edges import assert_clean_refusal, run

from opticalstamp.design import load_design
from opticalstamp.imaging.charts import bar_chart, text_chart
from opticalstamp.imaging.measure import measure_rmtf
from opticalstamp.imaging.outputkernel import output_kernel
from opticalstamp.imaging.restore import (
    blur,
    estimate_height,
    restore,
    restore_scan,
    wiener_noise_gain,
)
from opticalstamp.imaging.scan import ScanSettings, simulate_scan


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def _band_limited_page(shape, cutoff, seed=1):
    """A random page with no detail above ``cutoff`` cycles per output pixel, in [0, 1]."""
    rng = np.random.default_rng(seed)
    f = np.fft.fft2(rng.random(shape))
    vy = np.fft.fftfreq(shape[0])[:, None]
    vx = np.fft.fftfreq(shape[1])[None, :]
    page = np.fft.ifft2(f * ((vy**2 + vx**2) < cutoff**2)).real
    return (page - page.min()) / (page.max() - page.min())


def _band_limited_doc(shape_out, pitch_um, doc_dpi, cutoff, seed=1):
    """The same page drawn at ``doc_dpi`` (for the scan simulation) and its samples at the
    output cells' centres (the ideal the model restores to)."""
    from scipy import ndimage

    page = _band_limited_page(shape_out, cutoff, seed)
    step = 25400.0 / doc_dpi
    ny, nx = (int(n * pitch_um / step) for n in shape_out)
    # the band-limited page is smooth: cubic interpolation of its samples draws it finely
    yy = ((np.arange(ny) + 0.5) * step / pitch_um) - 0.5
    xx = ((np.arange(nx) + 0.5) * step / pitch_um) - 0.5
    gy, gx = np.meshgrid(yy, xx, indexing="ij")
    doc = ndimage.map_coordinates(page, [gy, gx], order=3, mode="reflect")
    return np.clip(doc, 0, 1).astype(np.float32), page


def test_model_predicts_the_simulated_scan_of_a_band_limited_page(paper):
    """The output-grid model (the responsivity band-limited and sampled, integrated over
    no cell again) reproduces the scan simulation of a page without detail finer than the
    output grid to 0.3 % of white; the cell-integrated kernel would miss 200-dpi transfer by
    17-38 % (docs/restore.md)."""
    st = ScanSettings()
    pitch = 84.6
    doc, page = _band_limited_doc((120, 160), pitch, 1200.0, 0.25)
    for z in (1.5, 3.0):
        r = simulate_scan(doc, 1200.0, paper, z_mm=z, noiseless=True, ghosts=False, settings=st)
        ok = output_kernel(paper, z, settings=st, ghosts=False)
        n = min(r.image.shape[0], page.shape[0]), min(r.image.shape[1], page.shape[1])
        want = blur(page[: n[0], : n[1]], ok)
        err = (r.image[: n[0], : n[1]] - want)[15:-15, 15:-15]
        assert np.sqrt((err**2).mean()) < 0.003, z


def test_restoring_the_models_own_blur_recovers_the_page(paper):
    """A page blurred by the same kernel without noise: Wiener (sigma 0.01) recovers the
    band-limited page to 0.1 % rms, Richardson-Lucy to 1 %; TV to 2.5 % (its prior is
    a page of flat areas: it flattens this smooth one a little, its known bias)."""
    ok = output_kernel(paper, 3.0, ghosts=False)
    page = _band_limited_page((200, 260), 0.2)
    g = blur(page, ok)
    for method, tol in (("wiener", 1e-3), ("rl", 0.01), ("tv", 0.025)):
        f = restore(g, ok, method=method, sigma=0.01).image
        err = (f - page)[30:-30, 30:-30]
        assert np.sqrt((err**2).mean()) < tol, method


def test_wiener_noise_gain_matches_its_closed_form(paper):
    """White noise through the Wiener filter of the two staggered phases: the measured
    rms gain equals sqrt(sum |W|^2 / N) to 2 %."""
    ok = output_kernel(paper, 3.0, ghosts=False)
    rng = np.random.default_rng(0)
    for sigma in (0.003, 0.03):
        noise = 1 + sigma * rng.standard_normal((500, 600))
        f = restore(noise, ok, method="wiener", sigma=sigma).image
        measured = f[40:-40, 40:-40].std() / sigma
        assert measured == pytest.approx(wiener_noise_gain(ok, noise.shape, sigma), rel=0.02)


@pytest.fixture(scope="module")
def bars_at_3mm(paper):
    doc = bar_chart(1200.0, chart_dpi=(100.0, 200.0))
    return simulate_scan(doc, 1200.0, paper, z_mm=3.0, seed=3)


def _amp(image, dpi, near):
    b = min(measure_rmtf(image, dpi), key=lambda b: abs(b["dpi"] - near))
    assert abs(b["dpi"] - near) < 10
    return b


@pytest.mark.parametrize("method", ["wiener", "rl", "tv"])
def test_restored_amplitude_never_exceeds_the_ideal(paper, bars_at_3mm, method):
    """At the right height every method raises the 200-dpi amplitude over the raw scan's
    and none exceeds the ideal's (2/pi) by more than 5 %; overshoot past white or black
    stays under 0.35."""
    r = bars_at_3mm
    raw = _amp(r.image, r.dpi, 200)
    f = restore_scan(r.image, paper, z_mm=3.0, method=method, seed=3).image
    for near in (100, 200):
        b = _amp(f, r.dpi, near)
        assert b["amplitude_rel"] <= 1.05 and b["overshoot"] < 0.35, (near, b)
    assert _amp(f, r.dpi, 200)["amplitude_rel"] > raw["amplitude_rel"] + 0.1


def test_a_wrong_height_degrades_as_measured(paper, bars_at_3mm):
    """Restored with the kernel of 2.5 or 3.5 mm instead of 3 mm, the 200-dpi amplitude is
    off by more than 20 % (too little or too much sharpening); at 3 mm it is nearest the
    ideal."""
    r = bars_at_3mm
    amp = {
        z: _amp(restore_scan(r.image, paper, z_mm=z, seed=3).image, r.dpi, 200)["amplitude_rel"]
        for z in (2.5, 3.0, 3.5)
    }
    assert amp[2.5] < 0.8 * amp[3.0] and amp[3.5] > 1.2 * amp[3.0]
    assert abs(amp[3.0] - 1) < min(abs(amp[2.5] - 1), abs(amp[3.5] - 1))


def test_a_flat_height_map_restores_as_its_height(paper, bars_at_3mm):
    r = bars_at_3mm
    a = restore_scan(r.image, paper, z_mm=3.0, seed=3).image
    b = restore_scan(r.image, paper, height_map=np.full((4, 4), 3.0), seed=3).image
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_restore_cli_reads_the_sidecar(tmp_path):
    out = tmp_path / "s.tif"
    res = run(["chart", "bars", "-o", tmp_path / "bars.png"])
    assert res.exit_code == 0, res.output
    res = run(["scan", tmp_path / "bars.png", "-o", out, "--z", "3", "--restore", "wiener"])
    assert res.exit_code == 0, res.output
    res = run(["restore", out, "-o", tmp_path / "r.tif", "--json"])
    assert res.exit_code == 0, res.output
    meta = json.loads(res.stdout)
    assert meta["restoration"]["z_mm"] == 3.0 and meta["restoration"]["method"] == "wiener"
    side = json.loads((tmp_path / "r.json").read_text())
    assert side["design"] == "paper2016" and side["restoration"]["sigma"] > 0
    # the restoration scan --restore wrote, but for its input's 16 bits, clipped to white
    # (noise over white is lost in the file)
    a = tifffile.imread(tmp_path / "r.tif") / 65535.0
    b = tifffile.imread(tmp_path / "s-restored.tif") / 65535.0
    assert np.abs(a - b).mean() < 0.003 and np.abs(a - b).max() < 0.05


def test_restore_bad_inputs(tmp_path):
    """No sidecar and no --z, a height outside the kernels' range, a non-finite image, an
    unknown method: exit 2 naming the option, nothing written."""
    img = np.full((40, 40), 0.5, np.float32)
    tifffile.imwrite(tmp_path / "plain.tif", img, resolution=(300.0, 300.0))
    out = tmp_path / "o"
    out.mkdir()
    cases = [
        (["restore", tmp_path / "plain.tif", "-o", out / "r.tif"], ("--z",)),
        (["restore", tmp_path / "plain.tif", "-o", out / "r.tif", "--z", "12"], ("--z",)),
        (
            ["restore", tmp_path / "plain.tif", "-o", out / "r.tif", "--estimate-height"],
            ("--estimate-height",),
        ),
        (
            ["restore", tmp_path / "plain.tif", "-o", out / "r.tif", "--z", "1", "--method", "x"],
            ("--method",),
        ),
    ]
    bad = img.copy()
    bad[3, 3] = np.nan
    tifffile.imwrite(tmp_path / "nan.tif", bad, resolution=(300.0, 300.0))
    cases.append((["restore", tmp_path / "nan.tif", "-o", out / "r.tif", "--z", "1"], ("nan.tif",)))
    for args, names in cases:
        assert_clean_refusal(run(args), names, out)


def test_restore_refuses_to_overwrite_or_guess(tmp_path):
    """The output may not replace the scan or its sidecar; a restoration's own sidecar
    states no scan height; a rod-lens design is refused before `scan --restore` writes
    anything; a height-map scan is not given one estimated height."""
    assert run(["chart", "bars", "-o", tmp_path / "bars.png"]).exit_code == 0
    res = run(
        ["scan", tmp_path / "bars.png", "-o", tmp_path / "s.tif", "--z", "3", "--restore", "rl"]
    )
    assert res.exit_code == 0, res.output
    before = sorted(p.name for p in tmp_path.iterdir())
    s, rod = tmp_path / "s.tif", ["--design", "sla-1row-12deg"]
    for args, names in (
        (["restore", s, "-o", s], ("-o",)),
        (["restore", s, "-o", tmp_path / "s.png"], ("-o",)),
        (["restore", tmp_path / "s-restored.tif", "-o", tmp_path / "r2.tif"], ("--z",)),
        (["restore", s, "-o", tmp_path / "r3.tif", *rod], ("--design",)),
        (["scan", tmp_path / "bars.png", "-o", tmp_path / "t.png", "--z", "1", "--restore", "tv",
          *rod], ("--restore",)),
    ):  # fmt: skip
        assert_clean_refusal(run(args), names)
        assert sorted(p.name for p in tmp_path.iterdir()) == before, args
    hm = ["scan", tmp_path / "bars.png", "-o", tmp_path / "h.tif", "--height-map", "tilt:2:3"]
    assert run(hm).exit_code == 0
    res = run(["restore", tmp_path / "h.tif", "-o", tmp_path / "hr.tif", "--estimate-height"])
    assert_clean_refusal(res, ("--estimate-height",))


@pytest.mark.parametrize("z", [1.0, 3.1])
def test_height_estimated_from_text_or_refused(paper, z):
    """Black-and-white text: the height whose restoration is most black-and-white is the
    scan's to +0.3 mm (measured: 0.0-0.3 mm high; docs/restore.md). A blank page and a
    smooth grey one are refused, with the reason."""
    doc, _ = text_chart(1200.0, 4.0)
    r = simulate_scan(doc, 1200.0, paper, z_mm=z, seed=5)
    est = estimate_height(r.image, paper)
    assert est.refused is None and -0.1 <= est.z_mm - z <= 0.3, est
    if z == 1.0:
        blank = simulate_scan(np.ones((300, 400), np.float32), 1200.0, paper, z_mm=z, seed=5)
        assert estimate_height(blank.image, paper).refused
        yy, xx = np.mgrid[0:600, 0:800]
        smooth = (0.5 + 0.3 * np.sin(xx / 150) * np.cos(yy / 200)).astype(np.float32)
        s = simulate_scan(smooth, 1200.0, paper, z_mm=z, seed=5)
        assert estimate_height(s.image, paper).refused


def _unequal_rows(ok):
    """The kernel with row B's blur widened: a merged image that is not shift-invariant."""
    from dataclasses import replace

    from scipy import ndimage

    k1 = ndimage.uniform_filter(ok.own[1], 3)
    return replace(ok, own=np.stack([ok.own[0], k1 * ok.own[1].sum() / k1.sum()]))


def test_unequal_rows_are_solved_exactly(paper):
    """Rows with different blurs (beyond STATIONARY_TOLERANCE): restoration couples each
    frequency with its alias (the 2 x 2 solve) and recovers the band-limited page as the
    shift-invariant case does (to 0.2 %); the Wiener noise gain still matches its closed form."""
    from opticalstamp.imaging.restore import STATIONARY_TOLERANCE

    ok = _unequal_rows(output_kernel(paper, 3.0, ghosts=False))
    assert ok.row_difference > 10 * STATIONARY_TOLERANCE
    page = _band_limited_page((200, 260), 0.2)
    g = blur(page, ok)
    r = restore(g, ok, method="wiener", sigma=0.01)
    assert not r.meta["shift_invariant"]  # 0.2 % rms: row B's wider blur, regularised
    assert np.sqrt(((r.image - page)[30:-30, 30:-30] ** 2).mean()) < 2e-3
    # the mean kernel alone leaves the rows' difference: a striped error 10x larger
    mean = type(ok)(**{**ok.__dict__, "own": np.repeat(ok.own.mean(0, keepdims=True), 2, 0)})
    wrong = restore(g, mean, method="wiener", sigma=0.01).image
    assert np.sqrt(((wrong - page)[30:-30, 30:-30] ** 2).mean()) > 0.01
    noise = 1 + 0.01 * np.random.default_rng(2).standard_normal((400, 500))
    f = restore(noise, ok, method="wiener", sigma=0.01).image
    gain = f[40:-40, 40:-40].std() / 0.01
    assert gain == pytest.approx(wiener_noise_gain(ok, noise.shape, 0.01), rel=0.03)


def test_restored_dof_closed_form_agrees_with_the_simulated_study(paper):
    """The search's closed-form restored depth of field (Wiener chain at 200 dpi, noise
    gain in closed form) against the one measured on simulated, restored scans: within
    0.2 mm (measured: 4.17 and 4.17 mm); both beyond the raw scan's."""
    from opticalstamp.studies.restoration import restoration_study, restored_dof_closed_form

    sim = restoration_study(paper, z_mm=(3.0, 3.5, 4.0, 4.5), methods=("wiener",))
    closed = restored_dof_closed_form(paper, ghost_fraction=0.12)
    assert closed["dof_mm"] == pytest.approx(sim["dof"]["wiener"]["dof_mm"], abs=0.2)
    assert closed["dof_mm"] > 3.5 > 2.6 > sim["dof"]["raw"]["dof_mm"]
    assert sim["transfer_zero_mm"] == pytest.approx(4.7, abs=0.15)  # the ceiling


def test_search_for_the_restored_depth_of_field(paper):
    """search(objective="restored-dof") ranks by the restored depth of field: every
    feasible record has it, and the front is non-dominated in (light, restored DOF).
    Each design's ghost check on 2^15 rays (the search's default 2^17): the ranking and
    the front are checked against the records' own figures, whatever their noise. One
    generation of 12 designs (the prototype among them), not two of 8: the same three
    feasible designs (seed 0), the front two of them, the third dominated."""
    from opticalstamp.studies.search import pareto_front, search

    res = search(
        paper, population=12, generations=1, workers=1, objective="restored-dof",
        ghost_rays=1 << 15,
    )  # fmt: skip
    assert res.meta["objective"] == "restored_dof_mm"
    ok = [r for r in res.records if r["feasible"]]
    assert ok and all(np.isfinite(r["restored_dof_mm"]) for r in ok)
    pts = np.array([[r["efficiency_ratio"], r["restored_dof_mm"]] for r in ok])
    front = {(tuple(ok[i]["holes_um"]), tuple(ok[i]["thicknesses_um"])) for i in pareto_front(pts)}
    assert front == {(tuple(r["holes_um"]), tuple(r["thicknesses_um"])) for r in res.pareto}
    assert res.reference["restored_dof_mm"] > res.reference["dof_mm"]
