"""A colour scanner's channels taken one by one (issue 23, "light as it is"): an rgb
design under wave optics gets one RMTF, depth of field and light per channel, each equal
to the same channel run on its own as a one-channel design, the headline the worst
channel's depth of field and the weakest channel's light."""

from __future__ import annotations

import io

import numpy as np
import pytest
import xarray as xr

from opticalstamp.analysis.colour import channel_designs
from opticalstamp.analysis.efficiency import efficiency
from opticalstamp.analysis.responsivity import Optics, pixel_light, resolve_optics
from opticalstamp.analysis.rmtf import rmtf
from opticalstamp.analysis.spectrum import channels
from opticalstamp.design import load_design
from opticalstamp.design.variants import replace as vary
from opticalstamp.validate import InputError

N = 1 << 14  # quick: the traced light beyond the band only
ZS = np.array([0.0, 1.5, 3.0, 4.5])
RGB = ("red", "green", "blue")
#: the prototype's plates as a dispersive catalogue glass (its own are n = 1.52 flat)
SODA = {"slabs.1.medium": "soda-lime", "slabs.2.medium": "soda-lime"}


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


@pytest.fixture(scope="module")
def rgb(paper):
    return vary(paper, {"electronics.illumination": "rgb"})


def _by_hand(design, channel: str, optics: Optics, **kw):
    """The channel as a one-channel design: its LED as the illumination, traced at the
    channel's mean wavelength, under the rgb design's wave sampling."""
    mean = channels(design)[channel].mean_um
    one = vary(design, {"electronics.illumination": channel, "wavelength_um": mean})
    return rmtf(one, optics=optics, **kw)


def test_each_channel_is_its_own_one_channel_design(paper):
    """Each channel's RMTF curve and depth of field equal the one-channel design's, run
    on its own (over a dispersive glass, so that each channel's far light is traced at
    its own wavelength); the headline is the least depth of field, and the netCDF
    carries all."""
    d = vary(paper, {"electronics.illumination": "rgb"} | SODA)
    opt = resolve_optics(d, "wave", channels=True)
    kw = {"z_mm": ZS, "n_rays": N, "dpi": [200], "refine": 0}
    res = rmtf(d, optics="wave", **kw)
    per = res.meta["channels"]
    assert list(per) == list(RGB)
    for ch in RGB:
        alone = _by_hand(d, ch, opt, **kw)
        np.testing.assert_allclose(per[ch]["rmtf_max"]["200"], alone.rmtf_max["200"], rtol=1e-12)
        assert per[ch]["dof_mm"]["200"] == pytest.approx(alone.dof_mm["200"], rel=1e-12)
    dofs = {ch: per[ch]["dof_mm"]["200"] for ch in RGB}
    worst = min(dofs, key=dofs.get)
    assert res.meta["headline"]["channel"] == worst
    assert res.dof_mm["200"] == dofs[worst]
    assert len(set(dofs.values())) == 3  # the channels differ: the headline is a choice
    ds = res.to_dataset()
    assert list(ds["channel"].values) == list(RGB)
    np.testing.assert_array_equal(ds["dof_channel_mm"].sel(dpi=200).values, list(dofs.values()))
    assert ds.attrs["headline_channel"] == worst
    back = xr.open_dataset(io.BytesIO(ds.to_netcdf(engine="scipy")), engine="scipy")
    assert list(back["channel"].values) == list(RGB)  # netCDF3 keeps the channels' names
    np.testing.assert_array_equal(back["rmtf_channel"].values, ds["rmtf_channel"].values)


def test_the_far_light_is_traced_at_each_channels_wavelength(paper):
    """Flat indices (the prototype's): one trace for all channels; a dispersive glass:
    each channel traced at its own mean wavelength, whose far light differs."""
    flat = channel_designs(vary(paper, {"electronics.illumination": "rgb"}))
    assert all(d.wavelength_um == paper.wavelength_um for d in flat.values())
    soda = vary(paper, {"electronics.illumination": "rgb"} | SODA)
    per = channel_designs(soda)
    for ch, d in per.items():
        assert d.wavelength_um == pytest.approx(channels(soda)[ch].mean_um)
    opt = resolve_optics(soda, "wave", channels=True)
    eff = efficiency(
        soda, optics=opt, n_rays=N, rse_own=0.2, rse_ghost=0.5, area_scales=(1.0,), z_mm=(0.0,)
    )
    lights = eff.meta["optics"]["channels"]
    assert lights["red"]["far_traced_um2sr"] != lights["blue"]["far_traced_um2sr"]


def test_efficiency_gives_each_channels_light_the_weakest_as_headline(rgb):
    opt = resolve_optics(rgb, "wave", channels=True)
    eff = efficiency(
        rgb, optics="wave", n_rays=N, rse_own=0.2, rse_ghost=0.5, area_scales=(1.0,), z_mm=(0.0,)
    )
    o = eff.meta["optics"]
    assert list(o["channels"]) == list(RGB)
    for ch in RGB:
        alone = pixel_light(rgb, opt, n_rays=N, spectrum=channels(rgb)[ch])
        for k in ("etendue_um2sr", "wave_in_band_um2sr", "far_traced_um2sr"):
            assert o["channels"][ch][k] == pytest.approx(alone[k], rel=1e-12)
    signal = {ch: o["channels"][ch]["wave_in_band_um2sr"] for ch in RGB}
    weakest = min(signal, key=signal.get)
    assert o["headline"]["channel"] == weakest
    assert eff.etendue_own_um2sr == signal[weakest]
    assert eff.etendue_um2sr == o["channels"][weakest]["etendue_um2sr"]


def test_auto_follows_the_rule_at_the_reddest_channel(paper, rgb):
    """auto applies the validity rule to the channel of the lowest Fresnel number (the
    longest wavelength) instead of picking ray for every rgb design; the analyses that
    do not take channels one by one (the maps) still refuse wave, naming the field."""
    o = resolve_optics(rgb, "auto", channels=True)
    rule = o.rule
    assert rule["channel"] == "red"
    assert rule["channel_predictors"]["red"] == min(rule["channel_predictors"].values())
    red = vary(paper, {"wavelength_um": channels(rgb)["red"].mean_um})
    assert o.engine == resolve_optics(red, "auto").engine == "wave"
    assert rule["predictor"] == pytest.approx(resolve_optics(red, "auto").rule["predictor"])
    assert resolve_optics(rgb, "wave", channels=True).engine == "wave"
    with pytest.raises(InputError, match="electronics.illumination is rgb"):
        resolve_optics(rgb, "wave")
