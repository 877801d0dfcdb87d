"""Circular holes through the wave engine's 2-D maps (issue 23): the 2-D path's
responsivity maps (:mod:`opticalstamp.analysis.wave2dmaps`) behind the spectral response
every analysis takes (:func:`~opticalstamp.analysis.wavespectral.wave_response_spectral`),
checked against the separable engine on square holes, against the marginals' line-spread
functions and an independent full-grid object side on circles; the analyses and the CLI
take them where ``--optics wave`` is asked for; ``auto`` as documented."""

from __future__ import annotations

import json

import numpy as np
import pytest

from opticalstamp.analysis import wave, wavebase
from opticalstamp.analysis.responsivity import resolve_optics
from opticalstamp.analysis.wave2d import wave_response_2d
from opticalstamp.analysis.wave2dlsf import lsf_source_2d
from opticalstamp.analysis.wave2dmaps import expected_seconds, maps_on_gpu, wave_maps_2d
from opticalstamp.analysis.wavespectral import wave_response_spectral
from opticalstamp.design import design_from_dict, load_design
from opticalstamp.design.variants import with_hole_shape
from test_wave import _stack

ZS = (0.0, 0.4)
OFFSETS = [(1.5, -1.0), (0.0, 0.0), (-2.0, 0.7)]


@pytest.fixture(scope="module")
def smp():
    """A coarse band (0.2 of the default 0.35) and half the margin: a legitimate sampling
    (the band holds the own path; both engines get the same), cheap on 2 cores."""
    d = _stack((10.0, 10.0, 12.0), offsets=OFFSETS)
    return wavebase.wave_sampling(d, band=0.2).refined(margin=0.5)


@pytest.fixture(scope="module")
def circles(smp):
    """The small two-row stamp of test_wave with circular holes, two masks misregistered:
    its 2-D maps (exact stack) and the marginals' source."""
    d = _stack((10.0, 10.0, 12.0), shape="circle", offsets=OFFSETS)
    return d, wave_maps_2d(d, ZS, sampling=smp), lsf_source_2d(d, max(ZS), sampling=smp)


def test_square_maps_equal_the_separable_maps(smp):
    """Square holes, where both paths apply (paraxial propagator in the stack): the 2-D
    path's maps on 2-um bins equal the separable engine's to 3e-5 of their peak (measured
    6e-6 and 8e-6 at Z = 0 and 0.4 mm), its light to 1e-5 (7.6e-7), the central cell's
    share to 1e-5 (8e-7 absolute) and its line-spread functions to 2e-5 of the peak."""
    d = _stack((10.0, 10.0, 12.0), offsets=OFFSETS)
    sep = wave.wave_response(d, ZS, sampling=smp)
    two = wave_maps_2d(d, ZS, sampling=smp, propagator="paraxial")
    np.testing.assert_allclose(two.etendue_um2sr, sep.etendue_um2sr, rtol=1e-5)
    np.testing.assert_allclose(two.center_cell_fraction, sep.center_cell_fraction, atol=1e-5)
    for iz in range(len(ZS)):
        for half in (40.0, None):  # a caller's extent, and each path's own default
            e1, m1 = sep.spot(iz, 2.0, half)
            e2, m2 = two.spot(iz, 2.0, half)
            np.testing.assert_array_equal(e1, e2)
            assert np.abs(m2 - m1).max() < 3e-5 * m1.max()
        lsf = np.interp(sep.x_um, two.x_um, two.lsf_x[iz])
        assert np.abs(lsf - sep.lsf_x[iz]).max() < 2e-5 * sep.lsf_x[iz].max()


def test_circle_maps_marginals_equal_the_line_spread_functions(circles, smp):
    """Circles: the maps' x and y marginals (the window's intensity summed over y and
    over x) equal the marginal source's line-spread functions (wave2dlsf: the x LSFs of
    lsf_source_2d, the y ones from its marginal_modes) to 1e-5 of their peak (measured
    3-4e-6), the window holds the maps' light to 1e-5 (its tails are 1e-6 a side), and
    that light is lsf_source_2d's (the same stack, the same modes) to 5e-5: the object
    grid keeps the in-band part of the stack grid's fields, and a circle's slowly
    decaying diffraction leaves 1.2e-5 of the light at the stack grid's edge (7.6e-7 for
    the squares above)."""
    d, maps, src = circles
    x, lsf, light, _ = src.lsf_x(ZS)
    assert maps.etendue_um2sr[0] == pytest.approx(light, rel=5e-5)
    step = smp.step_um
    for iz in range(len(ZS)):
        xw, yw, inten = maps.windows[iz]
        inten = inten.astype(np.float64)
        mx, my = inten.sum(axis=0) * step, inten.sum(axis=1) * step
        assert np.abs(mx - np.interp(xw, x, lsf[iz])).max() < 1e-5 * mx.max()
        assert np.abs(my - np.interp(yw, maps.y_um, maps.lsf_y[iz])).max() < 1e-5 * my.max()
        assert inten.sum() * step * step == pytest.approx(maps.etendue_um2sr[iz], rel=1e-5)
        assert 0.2 < maps.center_cell_fraction[iz] <= 1.0
    # not separable: the product of the marginals is not the map
    _, m = maps.spot(0, 2.0, 20.0)
    prod = np.outer(m.sum(axis=1), m.sum(axis=0)) / m.sum()
    assert np.abs(prod - m).max() > 1e-3 * m.max()


def test_circle_maps_equal_the_full_grid_object_side(smp):
    """The pruned, windowed object side against the 2-D path's own full-grid one
    (:func:`~opticalstamp.analysis.wave2d.wave_response_2d`: every mode through full 2-D
    FFTs of the object grid, paraxial throughout): maps on 2-um bins to 1e-5 of their peak,
    the central cell's share (exact band-limited weights on both sides) to 1e-5."""
    d = _stack((10.0, 10.0, 12.0), shape="circle", offsets=OFFSETS)
    full = wave_response_2d(d, ZS, sampling=smp, propagator="paraxial", map_half_um=40.0)
    two = wave_maps_2d(d, ZS, sampling=smp, propagator="paraxial")
    np.testing.assert_allclose(two.center_cell_fraction, full.center_cell_fraction, atol=1e-5)
    for iz in range(len(ZS)):
        edges, m = two.spot(iz, 2.0, 40.0)
        np.testing.assert_allclose(edges, full.edges_um)
        assert np.abs(m - full.maps[iz]).max() < 1e-5 * full.maps[iz].max()


def test_spectral_response_takes_the_2d_maps(circles, smp, capsys):
    """``wave_response_spectral`` on circles: the 2-D path's figures and maps (no engine
    branch for the analyses), and with ``progress`` on the CPU the expected cost on
    stderr before any work."""
    d, maps, _ = circles
    r = wave_response_spectral(d, ZS, spectrum="mono", sampling=smp, progress=True)
    assert r.meta["path"] == "2d" and r.parts[0].meta["path"] == "2d"
    np.testing.assert_allclose(r.etendue_um2sr, maps.etendue_um2sr, rtol=1e-12)
    np.testing.assert_allclose(r.center_cell_fraction, maps.center_cell_fraction, rtol=1e-12)
    np.testing.assert_array_equal(r.spot(1, 4.0)[1], maps.spot(1, 4.0)[1])
    assert r.budget[-1]["lost_to_band"] == maps.budget[-1]["lost_to_band"] > 0
    assert not maps_on_gpu()
    assert "expect about" in capsys.readouterr().err
    json.dumps(r.to_dict())  # plain data


def test_wave_scan_kernels_of_circles():
    """Scan kernels by wave optics for circular holes (``source="wave"``, as ``scan
    --kernel wave`` and the report ask; the design's own sampling): each row's near-field
    kernel holds the 2-D maps' light to 1e-2 (measured -0.35 %: the kernels' SVD keeps
    at most 4 separable terms of a map, and a circle's map is not separable; 2e-3 for
    squares, tests/test_optics_engines.py) and row B, row A's mirror twin, is row A's
    kernel mirrored (one 2-D run for both rows)."""
    from opticalstamp.analysis.wavespectral import mirror_rows
    from opticalstamp.imaging import kernels

    d = _cheap_circles(rows=2)
    assert mirror_rows(d, resolve_optics(d, "wave").sampling) == [None, 0]
    zs = (0.0, 0.1)
    sets = kernels.scan_kernels(d, zs, source="wave", ghosts=False, n_rays=1 << 14)
    r = wave_response_spectral(d, zs)
    for row in (0, 1):
        for k, e in zip(sets[row], r.etendue_um2sr, strict=True):
            assert k.own_etendue == pytest.approx(e, rel=1e-2)
    np.testing.assert_allclose(sets[1][1].cum_y[:, -1], sets[0][1].cum_y[:, -1], rtol=1e-12)
    np.testing.assert_allclose(
        sets[1][1].cum_y, sets[0][1].cum_y[:, -1:] - sets[0][1].cum_y[:, ::-1]
    )


def _cheap_circles(rows: int = 1):
    """A stamp whose default wave sampling is cheap (thin plates, the near infrared): for
    the command line and the scan kernels, which take the design's sampling."""
    return design_from_dict(
        {
            "name": "tiny-circles",
            "wavelength_um": 0.85,
            "sensor": {
                "pixel_pitch_um": 6.0,
                "lines": 4,
                "sensitive_width_um": 6.0,
                "sensitive_height_um": 6.0,
                "rows": rows,
                "row_pitch_um": 36.0,
                "row_b_offset_x_um": 18.0,
                "row_b_offset_y_um": 18.0,
                "pixels_per_row": 51,
            },
            "slabs": [
                {"medium": m, "thickness_um": t, "mask_top": {"shape": "circle", "size_um": h}}
                for m, t, h in (("air", 30.0, 8.0), (1.52, 30.0, 8.0), (1.52, 40.0, 10.0))
            ],
            "reference_gap": {"medium": "air", "thickness_um": 40.0},
        }
    )


def test_cli_spots_by_wave_optics_on_circles(tmp_path):
    """``opticalstamp spots --optics wave`` on a small circular-hole design exits 0 and
    reports wave optics (the 2-D path's maps joined with the traced far ghosts); ``auto``
    keeps ray optics there on the CPU and names ``--optics wave``."""
    from typer.testing import CliRunner

    from opticalstamp.cli.common import app
    from opticalstamp.design.files import design_toml

    path = tmp_path / "tiny.toml"
    path.write_text(design_toml(_cheap_circles()))
    runner = CliRunner()
    args = ["spots", "-d", str(path), "--z", "0,0.1", "--rays", "20000", "--json"]
    res = runner.invoke(app, ["--device", "cpu", *args, "--optics", "wave"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["meta"]["optics"]["engine"] == "wave"
    assert len(data["fwhm_x_um"]) == 2 and min(data["fwhm_x_um"]) > 0
    res = runner.invoke(app, ["--device", "cpu", *args[:-1], "--optics", "auto"])
    assert res.exit_code == 0, res.output
    assert "optics: ray" in res.stdout and "--optics wave" in res.stdout


def test_cli_wave_compares_ray_and_wave_on_circles(tmp_path):
    """``opticalstamp wave`` on a small two-row circular-hole design exits 0 with both
    engines' figures: the wave side the 2-D path's (its budget the object-side mask's
    record), row B's LSFs row A's (mirror twins)."""
    from typer.testing import CliRunner

    from opticalstamp.cli.common import app
    from opticalstamp.design.files import design_toml

    path = tmp_path / "tiny2.toml"
    path.write_text(design_toml(_cheap_circles(rows=2)))
    args = ["--device", "cpu", "wave", "-d", str(path), "--z", "0,0.1", "--rays", "20000"]
    res = CliRunner().invoke(app, [*args, "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["wave"]["light_um2sr"] > 0 and data["ray"]["light_um2sr"] > 0
    assert len(data["wave"]["rmtf"]) == 2 and data["meta"]["rows"] == 2
    assert [b["mask"] for b in data["budget"]] == [2] and data["budget"][0]["lost_to_band"] > 0


def test_auto_keeps_ray_for_circles_on_a_cpu_and_follows_the_rule_on_a_gpu(monkeypatch):
    """``auto`` on the circular prototype: ray on a CPU, saying why and naming
    ``--optics wave``; where the maps run on a GPU (the run's device cuda with CuPy) the
    validity rule decides, as for squares (the prototype's own-path Fresnel number is
    below the rule's bound: wave); ``wave`` takes the 2-D path either way; the report's
    ray-vs-wave section is not measured for circles under ``auto`` on a CPU."""
    from opticalstamp.analysis import wave2dmaps
    from opticalstamp.analysis.raywave import NEEDS_RECTANGLES
    from opticalstamp.analysis.validity import choose_optics
    from opticalstamp.report.wave import wave_section
    from opticalstamp.report.work import report_work

    circ = with_hole_shape(load_design("paper2016"), "circle")
    auto = resolve_optics(circ, "auto")
    assert auto.engine == "ray" and "--optics wave" in auto.reason
    assert choose_optics(circ).engine == "ray"
    assert resolve_optics(circ, "wave").engine == "wave"
    with pytest.raises(ValueError, match="--optics wave"):
        wave_section(circ, report_work(quick=True), seed=0, dof_dpi=200.0, optics=auto)
    assert "--optics wave" in NEEDS_RECTANGLES
    monkeypatch.setattr(wave2dmaps, "maps_on_gpu", lambda: True)
    gpu = resolve_optics(circ, "auto")
    assert gpu.engine == "wave" and "circular" not in gpu.reason
    assert choose_optics(circ).engine == "wave"


def test_expected_cost_scales_with_the_grids():
    """The CPU estimate before any work: the circular prototype's own figures at its
    default sampling (the calibration), less for a design of smaller grids."""
    circ = with_hole_shape(load_design("paper2016"), "circle")
    est = expected_seconds(circ, wavebase.wave_sampling(circ), 4.5, 19)
    assert est["stack_s"] == pytest.approx(37.0, rel=1e-9)  # its 1120^2 operator grid
    assert est["height_s"] == pytest.approx(28.0, rel=1e-9)  # its 6750^2 object grid
    assert est["total_s"] == pytest.approx(est["stack_s"] + 20 * est["height_s"])
    small = _cheap_circles()
    assert expected_seconds(small, wavebase.wave_sampling(small), 0.1, 2)["total_s"] < 60
