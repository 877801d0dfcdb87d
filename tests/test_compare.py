"""`opticalstamp compare`: any mix of kinds, one JSON object per design, one page."""

from __future__ import annotations

import json

import pytest

from edges import assert_clean_refusal, run
from opticalstamp.design import load_design
from opticalstamp.studies.compare import evaluate


def test_compare_cli_writes_page_json_and_figures(tmp_path):
    out = tmp_path / "cmp"
    # --optics ray: the option reaches each stamp's row (the wave headline's figures are
    # tests/test_compare_optics.py's); the ray-vs-wave block below runs either way
    res = run(
        ["compare", "paper2016", "sla-1row-12deg", "-o", str(out), "--json", "--optics", "ray"]
    )
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)["designs"]
    assert [r["kind"] for r in rows] == ["stamp", "rod-lens-array"]
    assert rows[0]["optics"]["engine"] == rows[0]["optics"]["asked"] == "ray"
    assert "optics" not in rows[1]  # a rod-lens array has its own tracer
    for r in rows:
        for key in ("light_vs_f10", "working_f_number", "thickness_mm", "dof_mm", "ghost_fraction"):
            assert key in r
        low, high = r["dof_mm"]
        assert r["dof_span_mm"] == pytest.approx(high - low)
    assert rows[0]["dof_mm"][0] == 0.0 and rows[1]["dof_mm"][0] < 0 < rows[1]["dof_mm"][1]
    stamp, rodl = rows
    assert rodl["ghost_fraction"] == 0.0 and "no stray path" in rodl["ghost_note"]
    # paper section 4: the stamp has about 1/100 of a rod-lens array's light; >= 15 mm thick
    assert 50 < rodl["light_vs_f10"] / stamp["light_vs_f10"] < 200
    assert rodl["thickness_mm"] > 5 * stamp["thickness_mm"]
    assert {p.name for p in out.iterdir()} == {
        "index.html",
        "compare.json",
        "contrast.png",
        "light.png",
        "text.png",
        "rodlens-1.png",
    }
    assert "sla-1row-12deg" in (out / "index.html").read_text()
    assert "<td>ray (asked for)</td>" in (out / "index.html").read_text()
    # ray vs wave optics (issue 23): the stamp's smallest Fresnel number (48 um over the
    # 1 mm reference gap at 0.55 um), the wave figures judged; the rod-lens array has none
    assert stamp["fresnel_min"] == pytest.approx(24.0**2 / (0.55 * 1000.0))
    w = stamp["wave"]
    assert w["light_wave_over_ray"] == pytest.approx(w["light_wave_um2sr"] / w["light_ray_um2sr"])
    assert w["light_wave_over_ray"] == pytest.approx(1.10, abs=0.01)  # docs/wave.md: +10.0 %
    assert w["holds"] == "wave" and w["dof_dpi"] == stamp["dof_dpi"]
    assert len(w["rmtf_wave"]) == len(w["rmtf_ray"]) == len(w["heights_mm"])
    assert w["dof_wave_mm"] == pytest.approx(w["dof_ray_mm"], abs=0.2)
    assert rodl["fresnel_min"] is None and rodl["wave"] == {"note": "n/a (not an aperture stack)"}
    assert "diffraction dominates" in (out / "index.html").read_text()


def test_stamp_light_is_own_path_only():
    d = load_design("paper2016")
    r = evaluate(d)
    assert r["light_vs_f10"] < r["light_vs_f10_with_ghosts"]
    assert r["ghost_fraction"] == pytest.approx(
        1 - r["light_vs_f10"] / r["light_vs_f10_with_ghosts"], rel=1e-9
    )


@pytest.mark.parametrize("cmd", [["ghosts"], ["spots"], ["rmtf"], ["psf"], ["report"]])
def test_stamp_commands_refuse_a_rod_lens_design_clearly(cmd):
    res = run([*cmd, "--design", "sla-1row-12deg"])
    assert_clean_refusal(res, "rod-lens-array design")


@pytest.mark.parametrize(
    ("patch", "field"),
    [
        ("numerical_aperture = 1.7", "numerical_aperture"),
        ("core_radius_um = 400.0", "core_radius_um"),
        ("overlap = 0.2", "overlap"),
        ("rows = 3", "rows"),
    ],
)
def test_bad_rod_design_files_exit_2_naming_the_field(tmp_path, patch, field):
    key = patch.split(" =")[0]
    lines = [
        'kind = "rod-lens-array"',
        "wavelength_um = 0.55",
        "[array]",
        "rows = 1",
        "rod_radius_um = 250.0",
        "core_radius_um = 235.0",
        "n0 = 1.6",
        "numerical_aperture = 0.2",
        "overlap = 1.7",
    ]
    lines = [patch if ln.startswith(key + " ") else ln for ln in lines]
    f = tmp_path / "bad.toml"
    f.write_text("\n".join(lines) + "\n")
    res = run(["compare", "paper2016", str(f), "-o", str(tmp_path / "o")])
    assert_clean_refusal(res, field)
    assert not (tmp_path / "o").exists()


def test_efficiency_command_takes_a_rod_lens_design():
    res = run(["efficiency", "--design", "sla-1row-12deg", "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["estimator"] == "trace" and data["ratio"] > 1
    assert data["working_f_number"] == pytest.approx(10 / data["ratio"] ** 0.5)
    res = run(["efficiency", "--design", "sla-1row-12deg", "--study"])
    assert_clean_refusal(res, "--study")
