"""Results as labelled arrays: ``to_dataset()`` holds the same numbers as ``to_dict()``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.spots import psf, spots
from opticalstamp.design import load_design
from opticalstamp.raytrace.stack import output_pitch
from opticalstamp.studies.tolerance import error_names, tolerance

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def _units_everywhere(ds) -> None:
    missing = [k for k in ds.data_vars if "units" not in ds[k].attrs]
    assert missing == []


def _same(a, b) -> None:
    """Equal as floats, None matching NaN."""
    a = np.array([math.nan if v is None else v for v in np.ravel(a)], dtype=np.float64)
    b = np.array([math.nan if v is None else v for v in np.ravel(b)], dtype=np.float64)
    np.testing.assert_array_equal(a, b)


def test_ghost_dataset(paper):
    g = analyse_ghosts(paper, z_mm=(0.0, 3.0), n_rays=1 << 16, seed=1)
    d = g.to_dict()
    ds = g.to_dataset()
    _units_everywhere(ds)
    assert list(ds.z_mm.values) == [0.0, 3.0] and ds.z_mm.attrs["units"] == "mm"
    bin_um = output_pitch(paper)
    assert ds.attrs["bin_um"] == bin_um and ds.distance_um.attrs["units"] == "um"
    n_bins = ds.sizes["distance_um"]
    assert ds.attrs["distance_overflow_um"] == pytest.approx(n_bins * bin_um)
    np.testing.assert_allclose(ds.distance_lo_um, np.arange(n_bins) * bin_um)
    np.testing.assert_allclose(ds.distance_um, (np.arange(n_bins) + 0.5) * bin_um)
    for iz, (key, land) in enumerate(d["landing"].items()):
        hist = land["etendue_by_distance_um2sr"]
        assert len(hist) == n_bins + 1  # the last bin is the overflow
        _same(ds.landing_um2sr.isel(z_mm=iz), hist[:-1])
        assert float(ds.landing_overflow_um2sr.isel(z_mm=iz)) == hist[-1]
        z = float(key)
        for k in ("nearest_um", "median_um", "within_detector_um2sr", "within_detector_se"):
            _same(ds[k].sel(z_mm=z), [land[k]])
        # every ghost ray is binned: the bins and the overflow add up to the ghost etendue
        total = float(ds.landing_um2sr.sel(z_mm=z).sum() + ds.landing_overflow_um2sr.sel(z_mm=z))
        assert total == pytest.approx(d["etendue_ghost_um2sr"], rel=1e-12)
    for k in (
        "etendue_own_um2sr",
        "etendue_own_se",
        "etendue_ghost_um2sr",
        "etendue_ghost_se",
        "ghost_fraction",
        "ghost_fraction_se",
    ):
        assert float(ds[k]) == d[k] and ds[k].dims == ()
    paths = d["paths"]
    assert ds.sizes["path"] == len(paths) > 0
    assert list(ds.mask.values) == [h["mask"] for h in paths[0]["holes"]]
    _same(ds.path_etendue_um2sr, [p["etendue_um2sr"] for p in paths])
    _same(ds.path_etendue_se, [p["etendue_se"] for p in paths])
    _same(ds.path_share, [p["share"] for p in paths])
    _same(ds.path_n_rays, [p["n_rays"] for p in paths])
    _same(ds.emission_angle_lo_deg, [p["emission_angle_deg"][0] for p in paths])
    _same(ds.emission_angle_hi_deg, [p["emission_angle_deg"][1] for p in paths])
    _same(ds.hole_dk, [[h["dk"] for h in p["holes"]] for p in paths])
    assert ds.hole_row.values.tolist() == [[h["row"] for h in p["holes"]] for p in paths]
    _same(
        ds.path_nearest_landing_um,
        [[p["nearest_landing_um"][k] for k in d["landing"]] for p in paths],
    )
    # a path's label names its holes, and selects it
    first = str(ds.path.values[0])
    assert first.startswith(f"{paths[0]['holes'][0]['mask']}:")
    assert float(ds.path_etendue_um2sr.sel(path=first)) == paths[0]["etendue_um2sr"]
    assert len(set(ds.path.values.tolist())) == len(paths)
    for plane, counts in d["ledger"].items():
        for status in ds.status.values:
            assert int(ds.ledger.sel(plane=plane, status=status)) == counts.get(str(status), 0)
    a = ds.attrs
    assert (a["design"], a["fingerprint"], a["seed"], a["n_rays"], a["fresnel"]) == (
        d["design"],
        d["fingerprint"],
        1,
        1 << 16,
        0,
    )
    assert a["detector_half_um"] == d["landing"]["0"]["detector_half_um"]
    assert "estimator" not in a  # the traced analysis records none in its meta


def test_spot_dataset(paper):
    sp = spots(paper, z_mm=(0.0, 1.0), n_rays=1 << 16, seed=2)
    d = sp.to_dict()
    ds = sp.to_dataset()
    _units_everywhere(ds)
    np.testing.assert_array_equal(ds.z_mm, d["z_mm"])
    for k in ("extent_x_um", "extent_y_um", "fwhm_x_um", "fwhm_y_um", "center_cell_fraction"):
        _same(ds[k], d[k])
    assert ds.map_sr.attrs["units"] == "sr" and ds.x_um.attrs["units"] == "um"
    assert ds.attrs["cell_um"] == output_pitch(paper) and ds.attrs["ghosts"] == 1
    for s in sp.spots:
        m = ds.map_sr.sel(z_mm=s.z_mm).dropna("x", how="all").dropna("y", how="all")
        np.testing.assert_array_equal(m.values, s.map_sr)
        np.testing.assert_allclose(m.x_um, 0.5 * (s.x_edges_um[1:] + s.x_edges_um[:-1]))
        np.testing.assert_allclose(m.y_um, 0.5 * (s.y_edges_um[1:] + s.y_edges_um[:-1]))
    assert ds.sizes["x"] == max(s.map_sr.shape[1] for s in sp.spots)


def test_psf_dataset(paper):
    p = psf(paper, z_mm=1.0, n_rays=1 << 16, window_um=200.0)
    ds = p.to_dataset()
    _units_everywhere(ds)
    np.testing.assert_array_equal(ds.grid_power.values, p.grid_power)
    np.testing.assert_array_equal(ds.fine_map.values, p.fine_map)
    np.testing.assert_allclose(ds.column_x_um[0], p.grid_x0_um + p.grid_pitch_um / 2)
    ex, ey = p.fine_edges_x_um, p.fine_edges_y_um
    np.testing.assert_allclose(ds.x_um, 0.5 * (ex[1:] + ex[:-1]))
    np.testing.assert_allclose(ds.y_um, 0.5 * (ey[1:] + ey[:-1]))
    assert ds.line_y_um.attrs["units"] == "um" and ds.fine_map.attrs["units"] == "1/um^2"
    for k in (
        "own_pixel",
        "neighbour_own_path",
        "neighbour_ghost",
        "insensitive",
        "reaching_sensor",
    ):
        assert float(ds[k]) == getattr(p, k)
    # a column's centre is that of the sensor pixel under it: the own pixel's lies on one
    own = p.own_pixel_id
    assert np.abs(ds.column_x_um.values - own["x_um"]).min() == pytest.approx(0, abs=1e-9)
    assert np.abs(ds.line_y_um.values - own["y_um"]).min() == pytest.approx(0, abs=1e-9)


def test_tolerance_dataset(paper):
    sg = {"misregistration_um": 0.0, "hole_um": 0.0, "thickness_um": 0.0, "tilt_deg": 0.02}
    r = tolerance(paper, samples=3, sigmas=sg, workers=1, ghost_rays=1 << 14, spec="dof>=2")
    before = r.to_dict()
    ds = r.to_dataset()
    assert r.to_dict() == before
    _units_everywhere(ds)
    names = error_names(paper)
    assert list(ds.error.values) == names and ds.sizes["sample"] == 3
    assert list(ds.z_mm.values) == r.z_mm and float(ds.dpi) == r.dpi
    for i, (e, s) in enumerate(zip(r.errors, r.samples, strict=True)):
        _same(ds.errors.isel(sample=i), [e[n] for n in names])
        _same(ds.rmtf.isel(sample=i), [s["rmtf_at"][f"{z:g}"] for z in r.z_mm])
        for k in ("dof_mm", "efficiency_ratio", "ghost_fraction", "nearest_ghost_mm"):
            assert float(ds[k].isel(sample=i)) == s[k]
    assert ds.ok.values.tolist() == [1, 1, 1]
    _same(ds.nominal_rmtf, [r.nominal["rmtf_at"][f"{z:g}"] for z in r.z_mm])
    assert float(ds.nominal_dof_mm) == r.nominal["dof_mm"]
    # the sensitivity table: only the tilt has a sigma here; the rest are NaN
    (row,) = r.sensitivity
    assert row["error"] == "tilt"
    sens = ds.sel(error="tilt")
    for k in ("sigma", "d_dof_mm", "d_efficiency_ratio", "d_ghost_fraction"):
        assert float(sens[k]) == row[k]
    _same(sens.d_rmtf, [row[f"d_rmtf@{z:g}"] for z in r.z_mm])
    assert (
        np.isnan(ds.d_dof_mm.sel(error="dx1")) and ds.error_units.sel(error="tilt").item() == "deg"
    )
    assert float(ds.sigma.sel(error="tilt")) == r.sigmas["tilt_deg"] == 0.02
    assert float(ds.yield_fraction) == before["yield"]
    assert ds.attrs["sigma_tilt_deg"] == 0.02 and ds.attrs["spec"] == "dof>=2"
    assert ds.attrs["estimator"] == r.meta["estimator"]


def test_ghost_median_beyond_the_bins_is_a_lower_bound(paper):
    """The median landing distance counts the overflow bin's light; where the median falls
    in it (all ghost light beyond 34 mm at Z = 20 mm) it is the bins' end, flagged as a
    lower bound, never a bin centre past the end."""
    g = analyse_ghosts(paper, z_mm=(0.0, 4.0, 20.0), n_rays=1 << 18, seed=2)
    ds = g.to_dataset()
    end = ds.attrs["distance_overflow_um"]
    for z, land in g.landing.items():
        h = np.asarray(land["etendue_by_distance_um2sr"])
        c = np.cumsum(h) / h.sum()
        beyond = bool(c[-2] < 0.5)  # half the light or more lies beyond the regular bins
        assert land["median_beyond"] is beyond
        assert bool(ds.median_beyond.sel(z_mm=float(z))) is beyond
        if beyond:
            assert land["median_um"] == pytest.approx(end)
        else:  # a regular bin's centre, where the cumulative share first reaches 1/2
            i = int(np.searchsorted(c, 0.5))
            assert land["median_um"] == pytest.approx((i + 0.5) * ds.attrs["bin_um"])
    assert bool(ds.median_beyond.sel(z_mm=20.0)) and not bool(ds.median_beyond.sel(z_mm=0.0))
