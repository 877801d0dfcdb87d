"""One responsivity, two engines (issue 23): the wave engine's in-band LSFs joined with the
tracer's out-of-band light, behind :func:`opticalstamp.analysis.responsivity.folded_lsf`."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from opticalstamp.analysis.lsf import FoldedLSF, fold_bins, traced_folded_lsf
from opticalstamp.analysis.responsivity import RAY, Optics, folded_lsf, join, resolve_optics
from opticalstamp.analysis.rmtf import rmtf, rmtf_from_lsf
from opticalstamp.analysis.wave import wave_response
from opticalstamp.analysis.wavebase import wave_sampling
from opticalstamp.analysis.wavecompare import fold, ray_in_band
from opticalstamp.design import load_design, with_unstated
from opticalstamp.validate import InputError

N = 1 << 17
ZS = np.array([0.0, 1.0, 2.0, 3.0])
PER = [254.0]  # the prototype's 200-dpi depth-of-field chart


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def _light(lsf: FoldedLSF) -> np.ndarray:
    """Each Z's light per row (um^2 sr)."""
    return lsf.h[0].sum(axis=(0, 1, 3)) / len(lsf.rows)


def _wave(design, **kw) -> Optics:
    return Optics("wave", "wave", "test", wave_sampling(design, **kw))


def test_out_of_band_fold_is_the_complement_of_the_band(paper):
    """The tracer's light outside the band (one test on s, conserved through the stack)
    equals all traced light minus the in-band light that ray_in_band tallies on its own;
    a band of 0 keeps every ray (bit for bit the plain fold)."""
    band = wave_sampling(paper).band
    out = traced_folded_lsf(paper, z_mm=ZS, periods_um=PER, n_rays=N, outside_band=band)
    ref = ray_in_band(paper, [0.0], band, period_um=PER[0], n_rays=N)
    expect = ref.traced_um2sr - ref.own_um2sr - ref.near_um2sr
    # row A alone: ray_in_band traces row A's pixel (0, 0)
    row_a = out.h[0][0].sum(axis=(0, 2))
    assert row_a[0] == pytest.approx(expect, rel=1e-9)
    assert expect > 0  # the prototype's far ghosts
    full = traced_folded_lsf(paper, z_mm=ZS, periods_um=PER, n_rays=N)
    zero = traced_folded_lsf(paper, z_mm=ZS, periods_um=PER, n_rays=N, outside_band=0.0)
    assert all(np.array_equal(a, b) for a, b in zip(full.h, zero.h, strict=True))


def test_join_adds_the_wave_light_without_changing_the_scatter():
    rng = np.random.default_rng(1)
    far_h = [rng.random((2, 16, 3, 10))]
    wave_h = [rng.random((2, 1, 3, 10))]
    zs, per = np.array([0.0, 1.0, 2.0]), np.array([5.0])
    far = FoldedLSF(zs, per, [(0, 0), (1, 1)], far_h, "trace", 160, True, False, np.ones(160))
    wave = FoldedLSF(zs, per, [(0, 0), (1, 1)], wave_h, "wave", 0, False, False)
    j = join(wave, far, 0.2, 1.0)
    assert j.method == "wave" and j.n_batches == 16
    np.testing.assert_allclose(j.h[0].sum(axis=1), far_h[0].sum(axis=1) + wave_h[0][:, 0])
    # the batch scatter, which gives the standard errors, is the traced part's
    np.testing.assert_allclose(np.std(j.h[0], axis=1), np.std(far_h[0], axis=1), atol=1e-12)
    # the wave light counts at the band's edge slope, 0.2 / sqrt(1 - 0.04)
    added = j.slope_power - far.slope_power
    assert added.sum() == pytest.approx(wave_h[0][:, :, 0].sum() / 2)
    assert np.flatnonzero(added).tolist() == [8]  # bins of 0.025: 0.204 lies in [0.2, 0.225)
    with pytest.raises(ValueError, match="share"):
        join(wave, FoldedLSF(zs[:2], per, [], [far_h[0][:, :, :2]], "trace", 1, 1, 0), 0.2, 1)


def test_the_sum_does_not_depend_on_where_the_band_is_split(paper):
    """Light and RMTF with the default band B and with 0.8 B: the light that moves from the
    tracer to the wave engine is counted once (measured: light 0.3 %, RMTF 0.004)."""
    b = wave_sampling(paper).band
    ls = [
        folded_lsf(paper, z_mm=ZS, periods_um=PER, optics=_wave(paper, band=f * b), n_rays=N)
        for f in (1.0, 0.8)
    ]
    light = [_light(x) for x in ls]
    np.testing.assert_allclose(light[0], light[1], rtol=0.01)
    r = [rmtf_from_lsf(x, paper, dpi=[200.0]).rmtf_max["200"] for x in ls]
    np.testing.assert_allclose(r[0], r[1], atol=0.01)


def test_geometric_limit_gives_the_ray_figures(paper):
    """At a wavelength shrunk 20x the joined responsivity gives the tracer's RMTF
    (max |difference| 0.0034, the tracer's standard error 0.003) and light (+0.56 %: the
    own path's diffraction excess falls as lambda, tests/test_wave.py)."""
    # below the range of a design's light: the wave engine alone at lambda / 20, folded as
    # wave_folded_lsf folds it, joined with the traced light beyond its band
    smp = wave_sampling(paper, wavelength_um=paper.wavelength_um / 20)
    rows = [wave_response(paper, ZS, pixel=(r, 0), sampling=smp) for r in (0, 1)]
    nb = int(fold_bins(np.array(PER))[0])
    h = np.stack([[fold(x.x_um, p, PER[0], nb) for p in x.lsf_x] for x in rows])[:, None]
    far = traced_folded_lsf(paper, z_mm=ZS, periods_um=PER, n_rays=N, outside_band=smp.band)
    w = join(replace(far, h=[h], method="wave"), far, smp.band, 1.0)
    r = folded_lsf(paper, z_mm=ZS, periods_um=PER, optics=RAY, n_rays=N)
    rw = rmtf_from_lsf(w, paper, dpi=[200.0])
    rr = rmtf_from_lsf(r, paper, dpi=[200.0])
    se = np.hypot(rw.rmtf_max_se["200"], rr.rmtf_max_se["200"])
    np.testing.assert_array_less(
        np.abs(np.subtract(rw.rmtf_max["200"], rr.rmtf_max["200"])), 3 * se + 0.005
    )
    np.testing.assert_allclose(_light(w), _light(r), rtol=0.01)
    # at the design's wavelength the wave light is clearly above the ray figure
    w1 = folded_lsf(paper, z_mm=ZS[:1], periods_um=PER, optics=_wave(paper), n_rays=N)
    assert _light(w1)[0] / _light(r)[0] - 1 > 0.05


def test_rmtf_says_which_optics(paper):
    r = rmtf(paper, dpi=[200.0], z_mm=[0.0, 1.0, 2.0], optics="wave", n_rays=N, refine=0)
    o = r.meta["optics"]
    assert o["engine"] == "wave" and o["asked"] == "wave" and 0 < o["band"] < 0.35
    assert r.method == "wave"
    assert (
        rmtf(paper, dpi=[200.0], z_mm=[0.0], n_rays=N, refine=0).meta["optics"]["engine"] == "ray"
    )


def test_the_optics_name_the_light(paper):
    """The wave engine's figures say under which light they were computed: the design's
    one wavelength, or its illumination's name and wavelengths (the sampling's
    wavelength, where the band is set, is the design's either way): in the record, the
    CLI's line, a fit's words and the report's headline."""
    from opticalstamp.analysis.responsivity import light_words
    from opticalstamp.cli.optics import optics_line
    from opticalstamp.design.variants import replace as changed
    from opticalstamp.report.html.page import _headline_optics
    from opticalstamp.studies.fitresult import optics_words

    mono = resolve_optics(paper, "wave").to_dict()
    assert mono["light"] == {"name": "mono", "wavelengths_um": [0.55]}
    assert light_words(mono) == "at 0.55 µm" and "optics: wave at 0.55 µm," in optics_line(mono)
    white = resolve_optics(changed(paper, {"electronics.illumination": "white"}), "wave")
    w = white.to_dict()
    assert w["light"]["name"] == "white" and len(w["light"]["wavelengths_um"]) == 7
    assert w["wavelength_um"] == 0.55  # the band's
    said = "under the white light (7 wavelengths, 0.407-0.757 µm)"
    assert light_words(w) == said and f"optics: wave {said}," in optics_line(w)
    assert said in optics_words(w | {"scheme": {}})
    assert f"scalar diffraction {said} in the band" in _headline_optics(w)
    assert resolve_optics(paper, "ray").to_dict()["light"] is None


def test_bad_optics_are_refused(paper):
    with pytest.raises(InputError, match="optics: must be one of ray, wave, auto"):
        resolve_optics(paper, "waves")
    circles = with_unstated(paper, hole_shape="circle")  # auto: ray, saying why
    assert "circular holes" in resolve_optics(circles, "auto").reason


def test_efficiency_by_wave_optics_is_the_joined_light(paper):
    """The headline light by wave optics is the wave engine's in-band light plus the traced
    light beyond the band; the same sum from the folded LSFs (another tally of other
    rays) agrees, and the ray figure it replaces is kept beside it."""
    from opticalstamp.analysis.efficiency import efficiency

    ray = efficiency(paper, area_scales=(1.0,), z_mm=(0.0,))
    wave = efficiency(paper, area_scales=(1.0,), z_mm=(0.0,), optics="wave", ghosts=None)
    o = wave.meta["optics"]
    assert o["engine"] == "wave"
    assert wave.etendue_um2sr == pytest.approx(o["wave_in_band_um2sr"] + o["far_traced_um2sr"])
    assert o["ray_etendue_um2sr"] == pytest.approx(ray.etendue_um2sr)
    assert wave.ratio == pytest.approx(wave.etendue_um2sr / wave.reference_etendue_um2sr)
    joined = folded_lsf(paper, z_mm=[0.0], periods_um=PER, optics=_wave(paper), n_rays=N)
    row_a = float(joined.h[0][0].sum())
    assert wave.etendue_um2sr == pytest.approx(row_a, rel=0.01)
    # the tracer's in-band light is below the wave engine's: diffraction adds light
    assert o["wave_in_band_um2sr"] > o["ray_in_band_um2sr"] * 1.05


def test_cli_optics(tmp_path):
    import json

    from typer.testing import CliRunner

    from opticalstamp.cli import app

    r = CliRunner().invoke(app, ["rmtf", "--optics", "waves", "--z", "0,1"])
    assert r.exit_code == 2 and "optics: must be one of ray, wave, auto" in r.output
    r = CliRunner().invoke(
        app,
        ["rmtf", "--optics", "wave", "--z", "0,1,2", "--dpi", "200", "--rays", "65536", "--json"],
    )
    assert r.exit_code == 0, r.output
    data = json.loads(r.output)
    assert data["meta"]["optics"]["engine"] == "wave" and data["method"] == "wave"


def test_wave_scan_kernels_are_the_joined_responsivity(paper):
    """Scan kernels by wave optics: the near-field part is the wave engine's in-band
    light (its map, SVD-separated: within 0.2 % of wave_response's light), the ghost part
    the traced light beyond the band (that of ray_in_band's tally within its noise)."""
    from opticalstamp.analysis.wave import wave_response
    from opticalstamp.imaging.kernels import scan_kernels

    zs = [0.0, 2.0]
    kw = scan_kernels(paper, zs, source="wave", n_rays=1 << 18)
    light = wave_response(paper, zs, sampling=wave_sampling(paper)).etendue_um2sr
    for k, g in zip(kw[0], light, strict=True):
        assert k.own_etendue == pytest.approx(g, rel=2e-3)
    band = wave_sampling(paper).band
    ref = ray_in_band(paper, [0.0], band, period_um=PER[0], n_rays=1 << 18)
    far = ref.traced_um2sr - ref.own_um2sr - ref.near_um2sr
    assert kw[0][0].ghost_etendue == pytest.approx(far, rel=0.05)
    # the rays' kernels: the own path's geometric light, less than the wave engine's here
    kr = scan_kernels(paper, zs, source="paraxial", n_rays=1 << 18)
    assert kr[0][0].own_etendue < 0.95 * kw[0][0].own_etendue


def test_wave_kernels_take_every_design_the_engine_does(paper):
    """A colour scanner's wave kernels are its grey light's (its three LEDs lit together:
    tests/test_grey_light.py), not refused; circular holes are not refused either (asked
    for, they take the 2-D path's maps: tests/test_wave_circle_maps.py)."""
    from opticalstamp.imaging.kernels import kernel_source

    rgb = paper.electronics.model_copy(update={"illumination": "rgb"})
    assert kernel_source(paper.model_copy(update={"electronics": rgb}), "wave") == "wave"
    assert kernel_source(with_unstated(paper, hole_shape="circle"), "wave") == "wave"


def test_scan_with_wave_kernels(tmp_path):
    """`scan --kernel wave` scans a bar chart through the wave kernels: the diffraction
    blur lowers the measured 200-dpi RMTF against the paraxial kernels' (Z = 1 mm)."""
    from typer.testing import CliRunner

    from opticalstamp.cli import app
    from opticalstamp.imaging.measure import measure_rmtf
    from opticalstamp.io.files import read_image

    run = CliRunner().invoke
    assert run(app, ["chart", "bars", "-o", str(tmp_path / "bars.png")]).exit_code == 0
    got = {}
    for kernel in ("wave", "paraxial"):
        out = tmp_path / f"{kernel}.png"
        r = run(app, ["scan", str(tmp_path / "bars.png"), "--z", "1", "--kernel", kernel,
                      "-o", str(out)])  # fmt: skip
        assert r.exit_code == 0, r.output
        img, dpi = read_image(out, linear=True)
        blocks = measure_rmtf(img, dpi)
        got[kernel] = next(b["rmtf"] for b in blocks if abs(b["dpi"] - 200) < 5)
    assert got["wave"] < got["paraxial"] - 0.01


def test_spots_by_wave_optics(paper):
    """Spots by wave optics: without ghost light they are the wave engine's maps alone
    (its centre-cell share, its FWHM on the same bins); with it, the far ghosts traced
    beyond the band lower the share; the extents stay the geometric own path's."""
    from opticalstamp.analysis.spots import fwhm, spots
    from opticalstamp.analysis.wavespectral import wave_response_spectral

    zs = (0.0, 2.0)
    alone = spots(paper, z_mm=zs, n_rays=1 << 18, ghosts=False, optics="wave")
    w = wave_response_spectral(paper, zs, sampling=wave_sampling(paper))
    ray = spots(paper, z_mm=zs, n_rays=1 << 18, ghosts=False)
    for iz, s in enumerate(alone.spots):
        assert s.center_cell_fraction == pytest.approx(w.center_cell_fraction[iz], rel=1e-9)
        e, m = w.spot(iz, s.x_edges_um[1] - s.x_edges_um[0], -s.x_edges_um[0])
        np.testing.assert_allclose(s.map_sr, m, rtol=1e-12, atol=0)
        c = 0.5 * (e[1:] + e[:-1])
        assert s.fwhm_x_um == pytest.approx(fwhm(m.sum(axis=0), c))
        assert s.extent_x_um == pytest.approx(ray.spots[iz].extent_x_um, rel=0.02)
    both = spots(paper, z_mm=zs, n_rays=1 << 18, optics="wave")
    assert both.meta["optics"]["engine"] == "wave"
    for a, b in zip(alone.spots, both.spots, strict=True):
        assert b.center_cell_fraction < a.center_cell_fraction


def test_rgb_light_is_ray_under_auto_and_refused_for_wave(paper):
    """An rgb design's three channels are not taken one by one by the map analyses yet
    (spots, scan kernels; the RMTF and the light do, tests/test_rgb_channels.py): auto
    picks ray there and says why, wave is refused naming the field."""
    from opticalstamp.design.variants import replace as vary

    rgb = vary(paper, {"electronics.illumination": "rgb"})
    o = resolve_optics(rgb, "auto")
    assert o.engine == "ray" and "electronics.illumination is rgb" in o.reason
    with pytest.raises(InputError, match="electronics.illumination is rgb"):
        resolve_optics(rgb, "wave")
    white = vary(paper, {"electronics.illumination": "white"})
    assert resolve_optics(white, "auto").engine == "wave"
