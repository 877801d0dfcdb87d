"""A colour scanner's report (issue 23, "light as it is"): a design whose LEDs are lit in
turn (``electronics.illumination`` "rgb") gets one RMTF, depth of field and light per
channel in the report's RMTF and light sections, as ``opticalstamp rmtf`` and
``efficiency`` give them; its verdict takes the worst channel's depth of field and the
weakest channel's light."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from opticalstamp.analysis.rmtf import rmtf
from opticalstamp.design import load_design
from opticalstamp.design.variants import replace as vary
from opticalstamp.report import build

RGB = ["red", "green", "blue"]
LSF_RAYS = 1 << 16


def _small(real):
    """The quick report's work with fewer rays: every section still runs."""

    def work(*args, **kwargs):
        w = real(*args, **kwargs)
        return replace(
            w,
            ghost_rays=1 << 17,
            map_rays=1 << 15,
            concept_rays=1 << 15,
            lsf_rays=LSF_RAYS,
            kernel_rays=1 << 15,
        )

    return work


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """A quick report of the prototype lit red, green and blue in turn (auto optics: the
    validity rule takes wave optics at the red channel, whose own-path Fresnel number,
    0.58, is the lowest)."""
    mp = pytest.MonkeyPatch()
    mp.setattr(build, "report_work", _small(build.report_work))
    d = vary(load_design("paper2016"), {"electronics.illumination": "rgb"})
    out = tmp_path_factory.mktemp("rgb") / "r"
    try:
        build.build_report(d, out, quick=True, spec="dof>=2")
    finally:
        mp.undo()
    return d, out, json.loads((out / "report.json").read_text())


def test_the_rmtf_section_has_each_channel_and_the_worst_as_headline(report):
    """The channels in report.json; the headline depth of field is the least of the
    three (red: diffraction grows with the wavelength) and the verdict's; each channel's
    curve is what ``opticalstamp rmtf --optics wave`` computes for the design with the
    same rays (the report's trace shared with its other analyses changes nothing)."""
    d, _, data = report
    assert data["optics"]["engine"] == "wave" and data["optics"]["rule"]["channel"] == "red"
    r = data["rmtf"]
    key = f"{r['dof_dpi']:g}"
    chans = r["meta"]["channels"]
    assert list(chans) == RGB
    dofs = {name: c["dof_mm"][key] for name, c in chans.items()}
    assert r["dof_mm"][key] == min(dofs.values())
    assert r["meta"]["headline"]["channel"] == min(dofs, key=dofs.get) == "red"
    assert dofs["red"] < dofs["green"] < dofs["blue"]
    assert r["rmtf_max"][key] == chans["red"]["rmtf_max"][key]
    figures = {f["figure"]: f for f in data["summary"]["figures"]}
    assert figures["dof"]["value"] == min(dofs.values())
    assert figures["dof"]["check"]["pass"] is True
    assert figures["dof"]["text"].endswith("(red channel, the worst)")
    assert data["summary"]["headline_channels"] == {
        "dof": "red",
        "light": "blue",
        "channels": RGB,
    }
    alone = rmtf(
        d,
        optics="wave",
        z_mm=r["z_mm"],
        dpi=r["dpi"],
        dof_dpi=r["dof_dpi"],
        n_rays=LSF_RAYS,
        refine=0,
    )
    for name in RGB:
        np.testing.assert_allclose(
            chans[name]["rmtf_max"][key],
            alone.meta["channels"][name]["rmtf_max"][key],
            rtol=1e-9,
            err_msg=name,
        )


def test_the_light_section_has_each_channel_and_the_weakest_as_headline(report):
    _, _, data = report
    e = data["efficiency"]
    o = e["meta"]["optics"]
    lights = {name: c["wave_in_band_um2sr"] for name, c in o["channels"].items()}
    assert list(lights) == RGB
    assert o["headline"]["channel"] == min(lights, key=lights.get) == "blue"
    assert e["etendue_own_um2sr"] == min(lights.values())
    figures = {f["figure"]: f for f in data["summary"]["figures"]}
    assert figures["light"]["value"] == pytest.approx(
        min(lights.values()) / e["reference_etendue_um2sr"], rel=1e-12
    )
    assert figures["light"]["text"].endswith("(blue channel, the weakest)")


def test_the_one_light_analyses_say_their_optics(report):
    """The scans and restoration are grey scans by wave optics under the three LEDs lit
    together (grey_light), the spots take the channels one by one by wave optics (each
    LED's light in the band, the widest channel the headline); the background studies
    take one light: ray optics for a colour scanner, saying so (optics_one_light); the
    ray-vs-wave section compares the engines at the red channel."""
    _, out, data = report
    one = data["optics_one_light"]
    assert one["engine"] == "ray" and "rgb" in one["reason"]
    for key in ("spots", "scans", "restoration", "ray_vs_wave"):
        assert "not_measurable" not in data[key], key
    assert data["ray_vs_wave"]["meta"]["spectrum"]["name"] == "red"
    assert data["summary"]["optics"].startswith("(the red channel")
    # each section recorded its optics, and the verdict box says so, with the reason
    assert data["summary"]["one_light_engines"] == {
        "spots": "wave", "scans": "wave", "restoration": "wave"
    }  # fmt: skip
    sp = data["spots"]
    chans, head = sp["meta"]["channels"], sp["meta"]["headline"]
    assert list(chans) == RGB and [c["spectrum"]["name"] for c in chans.values()] == RGB
    share = {n: sum(c["center_cell_fraction"]) for n, c in chans.items()}
    assert head["channel"] == min(share, key=share.get)
    assert sp["center_cell_fraction"] == chans[head["channel"]]["center_cell_fraction"]
    assert len(set(share.values())) == 3  # each channel its own light
    page = (out / "index.html").read_text()
    assert "the scans and restoration are by wave optics, grey scans under the three" in page
    assert "the spots are by wave optics, channel by channel" in page
    assert f"figure are the {head['channel']} channel's, the widest" in page


def test_the_page_shows_the_channels(report):
    _, out, data = report
    page = (out / "index.html").read_text()
    assert "Colour: one exposure per LED (illumination rgb)" in page
    assert "Colour: the light per LED (illumination rgb)" in page
    for name in RGB:
        assert f"<td>{name} (" in page and f"RMTF 200 dpi, {name}" in page
    assert "red (0.630 µm) — the headline" in page and "blue — the headline" in page
    assert "the verdict's depth of field the red channel's" in page
    assert "(red channel, the worst)" in page and "(blue channel, the weakest)" in page
    assert (out / "rmtf.png").stat().st_size > 0
