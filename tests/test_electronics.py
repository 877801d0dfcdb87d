"""A design's [electronics] table (issue 12, item 8): it round-trips through a design file,
sets the scan's electrons as the closed form says, is refused field by field when wrong,
leaves every fingerprint alone when absent, and gives the report's signal-and-noise
numbers."""

from __future__ import annotations

import json
import math
import tomllib
from types import SimpleNamespace

import pytest
from PIL import Image

from edges import assert_clean_refusal, run
from opticalstamp.design import DesignError, design_from_dict, load_design, preset_text
from opticalstamp.design.electronics import Electronics
from opticalstamp.imaging.sensor import SensorModel, signal_budget
from opticalstamp.report.build import signal_and_noise
from opticalstamp.report.html import signal_html

#: Every preset's fingerprint before the table existed: a design without it keeps its own.
PRESET_FINGERPRINTS = {
    "fig1b": "4d63c67877b2",
    "fig1c": "730667031ac2",
    "fig1d": "e4422c3da4cb",
    "paper2016": "bc4f1a6ca8a9",
    "sla-1row-12deg": "bd0e4fccc5c4",
    "sla-2row-20deg": "23298fe20473",
    "three-layer-single-row": "7b2fa50f4de4",
}

TABLE = {
    "quantum_efficiency": 0.25,
    "illuminance_lux": 20_000.0,
    "exposure_ms": 0.5,
    "full_well_e": 80_000.0,
    "read_noise_e": 12.0,
    "prnu": 0.02,
    "dsnu_e": 5.0,
    "dark_current_e_per_s": 200.0,
    "adc_bits": 14,
    "black_level_dn": 128,
    "photons_per_lumen_s": 8.0e15,
    "exposure_duty": 0.9,
    "channel_response": [0.7, 1.0, 0.5],
    "illumination": "white",
}


def _toml(value) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value)


def _design_file(path, table: dict, preset: str = "paper2016"):
    """The preset's file with an [electronics] table appended."""
    lines = [f"{k} = {_toml(v)}" for k, v in table.items()]
    path.write_text(preset_text(preset) + "\n[electronics]\n" + "\n".join(lines) + "\n")
    return path


def test_sensor_model_is_the_design_table_with_the_same_defaults():
    assert SensorModel is Electronics
    m = SensorModel()
    assert m.model_dump() == {
        "illuminance_lux": 10_000.0,
        "exposure_ms": 1.0,
        "photons_per_lumen_s": 9.1e15,
        "quantum_efficiency": 0.5,
        "full_well_e": 60_000.0,
        "read_noise_e": 30.0,
        "prnu": 0.01,
        "dsnu_e": 20.0,
        "dark_current_e_per_s": 1000.0,
        "adc_bits": 12,
        "black_level_dn": 64,
        "exposure_duty": 1.0,
        "channel_response": (0.8, 1.0, 0.6),
        "illumination": "mono",
    }
    assert load_design("paper2016").electronics == m


@pytest.mark.parametrize("name", sorted(PRESET_FINGERPRINTS))
def test_fingerprints_unchanged_without_the_table(name):
    d = load_design(name)
    assert d.fingerprint() == PRESET_FINGERPRINTS[name]
    assert "electronics" not in d.model_dump(mode="json")
    # a table that states the defaults is the same design
    data = tomllib.loads(preset_text(name)) | {"electronics": {"quantum_efficiency": 0.5}}
    assert design_from_dict(data).fingerprint() == PRESET_FINGERPRINTS[name]


@pytest.mark.parametrize("preset", ["paper2016", "sla-1row-12deg"])
def test_table_round_trips_through_a_design_file(tmp_path, preset):
    d = load_design(_design_file(tmp_path / "d.toml", TABLE, preset))
    want = TABLE | {"channel_response": tuple(TABLE["channel_response"])}
    assert d.electronics.model_dump() == want
    dumped = d.model_dump(mode="json")
    assert dumped["electronics"] == TABLE
    again = design_from_dict(dumped, "dump")
    assert again == d and again.fingerprint() == d.fingerprint()
    assert d.fingerprint() != PRESET_FINGERPRINTS[preset]  # the electronics are content
    # show --json prints the table with the design
    res = run(["show", tmp_path / "d.toml", "--json"])
    assert res.exit_code == 0, res.output
    if preset == "sla-1row-12deg":
        assert json.loads(res.stdout)["design"]["electronics"] == TABLE


def _scan_signal(tmp_path, design, *extra) -> dict:
    page = tmp_path / "white.png"
    if not page.exists():
        Image.new("L", (64, 64), 255).save(page, dpi=(600, 600))
    out = tmp_path / f"s{len(list(tmp_path.glob('s*.json')))}.png"
    res = run(["scan", page, "-o", out, "--z", "1", "--noiseless", "--design", design, *extra])
    assert res.exit_code == 0, res.output
    return json.loads(out.with_suffix(".json").read_text())


def test_scan_uses_the_design_electronics_as_the_closed_form_says(tmp_path):
    """Electrons at white ∝ QE × illuminance × exposure (and photons per lumen-second);
    the SNR and the exposure for SNR 100 follow signal_budget with the file's numbers;
    --illuminance-lux and --exposure-ms override the file's values only."""
    table = {"quantum_efficiency": 0.25, "illuminance_lux": 30_000.0, "exposure_ms": 0.4}
    f = _design_file(tmp_path / "d.toml", table)
    base = _scan_signal(tmp_path, "paper2016")
    mine = _scan_signal(tmp_path, f)
    ratio = (0.25 * 30_000.0 * 0.4) / (0.5 * 10_000.0 * 1.0)
    assert mine["signal"]["electrons_white"] == pytest.approx(
        base["signal"]["electrons_white"] * ratio, rel=1e-12
    )
    sensor = SensorModel(**table)
    assert mine["settings"]["sensor"] == json.loads(sensor.model_dump_json())
    white = base["signal"]["electrons_white"] / SensorModel().electrons_per_um2sr
    want = signal_budget(sensor, white)
    assert mine["signal"].keys() == want.keys()
    for k, v in want.items():
        assert mine["signal"][k] == (v if isinstance(v, bool) else pytest.approx(v, rel=1e-9)), k
    # the command line's light and exposure win over the file's; its QE stays
    over = _scan_signal(tmp_path, f, "--exposure-ms", "2", "--illuminance-lux", "5000")
    assert over["settings"]["sensor"]["quantum_efficiency"] == 0.25
    assert over["settings"]["sensor"]["exposure_ms"] == 2.0
    assert over["signal"]["electrons_white"] == pytest.approx(
        base["signal"]["electrons_white"] * (0.25 * 5000.0 * 2.0) / (0.5 * 10_000.0), rel=1e-12
    )


def test_scan_warns_when_the_design_electronics_saturate(tmp_path):
    f = _design_file(tmp_path / "d.toml", {"full_well_e": 10_000.0})
    page = tmp_path / "white.png"
    Image.new("L", (64, 64), 255).save(page, dpi=(600, 600))
    res = run(["scan", page, "-o", tmp_path / "s.png", "--z", "1", "--design", f])
    assert res.exit_code == 0, res.output
    assert "warning: white saturates" in res.output


@pytest.mark.parametrize(
    ("table", "field"),
    [
        ({"full_well_e": -1.0}, "electronics.full_well_e"),
        ({"quantum_efficiency": 1.5}, "electronics.quantum_efficiency"),
        ({"read_noise_e": True}, "electronics.read_noise_e"),
        ({"illuminance_lux": "10000"}, "electronics.illuminance_lux"),
        ({"adc_bits": 12.5}, "electronics.adc_bits"),
        ({"adc_bits": 30}, "electronics.adc_bits"),
        ({"prnu": 0.5}, "electronics.prnu"),
        ({"exposure_ms": 0.0}, "electronics.exposure_ms"),
        ({"dark_current_e_per_s": -5.0}, "electronics.dark_current_e_per_s"),
        ({"channel_response": [1.0, 0.0, 1.0]}, "electronics.channel_response"),
        ({"gain": 2.0}, "electronics.gain"),
        ({"adc_bits": 6}, "black_level_dn"),  # the 64 DN pedestal does not fit in 6 bits
    ],
)
def test_bad_values_are_refused_naming_the_field(tmp_path, table, field):
    f = _design_file(tmp_path / "d.toml", table)
    with pytest.raises(DesignError, match=field.replace(".", r"\.")):
        load_design(f)
    assert_clean_refusal(run(["show", f]), field)
    page = tmp_path / "white.png"
    Image.new("L", (64, 64), 255).save(page, dpi=(600, 600))
    before = sorted(p.name for p in tmp_path.iterdir())
    res = run(["scan", page, "-o", tmp_path / "s.png", "--z", "1", "--design", f])
    assert_clean_refusal(res, field, tmp_path, before)


def test_bad_values_are_refused_in_a_rod_lens_design(tmp_path):
    f = _design_file(tmp_path / "r.toml", {"full_well_e": math.inf}, "sla-1row-12deg")
    assert_clean_refusal(run(["show", f]), "electronics.full_well_e")


def test_report_signal_equals_signal_budget():
    """The report's "signal": signal_budget of the design's electronics at its own-path
    etendue; the page's block prints its numbers rounded."""
    eff = SimpleNamespace(etendue_own_um2sr=2.4, etendue_um2sr=2.5)
    paper = load_design("paper2016")
    s = signal_and_noise(paper, eff)
    assert {k: s[k] for k in signal_budget(SensorModel(), 2.4)} == signal_budget(SensorModel(), 2.4)
    assert s["etendue_own_um2sr"] == 2.4 and s["electronics"]["full_well_e"] == 60_000.0
    data = tomllib.loads(preset_text("paper2016")) | {"electronics": TABLE}
    d = design_from_dict(data)
    mine = signal_and_noise(d, eff)
    assert {k: mine[k] for k in signal_budget(d.electronics, 2.4)} == signal_budget(
        d.electronics, 2.4
    )
    # closed form: electrons = E / pi * 1e-12 * photons per lumen-second * QE * t * G
    e = TABLE["illuminance_lux"] / math.pi * 1e-12 * TABLE["photons_per_lumen_s"]
    e *= TABLE["quantum_efficiency"] * TABLE["exposure_ms"] * 1e-3 * 2.4
    assert mine["electrons_white"] == pytest.approx(e, rel=1e-12)
    assert mine["electrons_grey18"] == pytest.approx(0.18 * e, rel=1e-12)
    text = signal_html(s, {"etendue_um2sr": 2.5})
    assert "Signal and noise" in text and "warning" not in text
    assert f"{s['electrons_white']:,.0f}" in text and f"{s['snr_white']:.3g}" in text
    assert f"{s['exposure_for_target_ms']:.3g} ms" in text
    assert f"{s['max_line_rate_for_target_hz']:,.0f} lines/s" in text
    assert "4.2 % more" in text  # the ghost light a white page adds
    bright = signal_and_noise(paper, SimpleNamespace(etendue_own_um2sr=5.0))
    assert bright["saturated_white"]
    assert "warning:</b> white saturates" in signal_html(bright)
    assert signal_html(None) == ""
