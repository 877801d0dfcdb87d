"""A pixel's signal and noise budget (electrons, SNR, the exposure for a target SNR)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from edges import run
from opticalstamp.imaging.sensor import (
    SensorModel,
    exposure_for_white,
    signal_budget,
    snr,
)


def test_budget_closed_forms():
    m = SensorModel()
    g = 2.0  # um^2 sr: about the prototype's pixel
    b = signal_budget(m, g, target_snr=100.0)
    assert b["electrons_white"] == pytest.approx(m.electrons_per_um2sr * g)
    assert b["electrons_grey18"] == pytest.approx(0.18 * b["electrons_white"])
    # at the exposure found, the SNR at white is the target
    m2 = m.model_copy(update={"exposure_ms": b["exposure_for_target_ms"]})
    assert float(snr(m2, m2.electrons_per_um2sr * g)) == pytest.approx(100.0, rel=1e-9)
    assert b["max_line_rate_for_target_hz"] == pytest.approx(1e3 / b["exposure_for_target_ms"])
    # shot-noise limit: SNR -> sqrt(signal) for a noiseless sensor
    quiet = m.model_copy(update={"read_noise_e": 0.0, "dark_current_e_per_s": 0.0, "adc_bits": 24})
    assert float(snr(quiet, 1e4)) == pytest.approx(100.0, rel=1e-3)


def test_auto_exposure_fills_the_well():
    m = SensorModel()
    ms = exposure_for_white(m, 1000.0, 0.8)  # a rod-lens array's etendue
    m2 = m.model_copy(update={"exposure_ms": ms})
    b = signal_budget(m2, 1000.0)
    assert b["full_well_fraction_white"] == pytest.approx(0.8, rel=1e-9)
    assert not b["saturated_white"]
    assert signal_budget(m, 1000.0)["saturated_white"]  # at the default exposure: clipped


def test_scan_reports_the_budget_and_warns_when_white_clips(tmp_path):
    doc = tmp_path / "bars.png"
    assert run(["chart", "bars", "-o", doc, "--dpi", "600"]).exit_code == 0
    res = run(["scan", doc, "-o", tmp_path / "s.png", "--z", "1", "--json"])
    sig = json.loads(res.stdout)["signal"]
    assert sig["snr_white"] > sig["snr_grey18"] > 1 and not sig["saturated_white"]
    assert json.loads((tmp_path / "s.json").read_text())["signal"] == sig
    res = run(["scan", doc, "-o", tmp_path / "r.png", "--z", "0", "-d", "sla-1row-12deg"])
    assert res.exit_code == 0 and "white saturates" in res.output
    assert np.isfinite(sig["exposure_for_target_ms"])
