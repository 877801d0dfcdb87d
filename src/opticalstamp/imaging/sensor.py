"""Illumination and the sensor's electronics: from etendue-weighted reflectance to counts.

The model (:class:`SensorModel`) is a design's ``[electronics]`` table,
:class:`opticalstamp.design.electronics.Electronics`: illuminance, exposure, photon rate
and quantum efficiency give the mean photo-electrons per um^2 sr of white. Then, per pixel
and line: photon shot noise (Poisson), PRNU (a fixed gain per pixel), dark signal with its
shot noise and DSNU (a fixed offset per pixel), full-well clipping, read noise and an ADC
of ``adc_bits`` over the full well with a black-level pedestal of ``black_level_dn`` (so
that dark noise is not clipped at zero). The defaults and their sources are in
:mod:`opticalstamp.design.electronics`.
"""

from __future__ import annotations

import numpy as np

from ..design.electronics import Electronics

#: Illumination, exposure and sensor electronics (validated, frozen): a design's
#: ``electronics``, the same class.
SensorModel = Electronics


def fixed_pattern(model: SensorModel, n_pixels: int, rng: np.random.Generator):
    """Per-pixel gain (PRNU) and dark offset (DSNU), drawn once per sensor."""
    gain = 1.0 + model.prnu * rng.standard_normal(n_pixels)
    offset = model.dsnu_e * rng.standard_normal(n_pixels)
    return np.clip(gain, 0.0, None), offset


def expose(
    mean_e: np.ndarray,
    model: SensorModel,
    pattern: tuple[np.ndarray, np.ndarray],
    rng: np.random.Generator | None,
) -> np.ndarray:
    """Counts (DN, float) of lines [line, pixel] given the mean photo-electrons.

    ``rng`` None: the noiseless mode (expected values, no fixed pattern, no quantisation).
    """
    if rng is None:
        return (mean_e + model.dark_e) / model.gain_e_per_dn + model.black_level_dn
    gain, offset = pattern
    # photo-electrons and dark electrons together: a sum of Poisson variables is Poisson;
    # the well holds at most full_well_e
    e = rng.poisson(np.clip(mean_e * gain, 0, None) + model.dark_e).astype(np.float64)
    e = np.minimum(e, model.full_well_e) + offset
    e += model.read_noise_e * rng.standard_normal(e.shape)
    dn = np.floor(e / model.gain_e_per_dn) + model.black_level_dn
    return np.clip(dn, 0, 2**model.adc_bits - 1)


#: Reflectance of the mid-grey at which the SNR is quoted (an 18 % grey card).
GREY = 0.18
#: SNR at white that :func:`signal_budget` finds the exposure for, by default.
TARGET_SNR = 100.0


def snr(model: SensorModel, signal_e) -> np.ndarray:
    """Temporal SNR at a mean signal (electrons): shot noise of signal and dark current,
    read noise and the ADC's quantisation (PRNU is a fixed pattern that the shading
    correction removes)."""
    s = np.asarray(signal_e, dtype=np.float64)
    noise2 = s + model.dark_e + model.read_noise_e**2 + model.gain_e_per_dn**2 / 12
    return s / np.sqrt(noise2)


def signal_budget(
    model: SensorModel, white_etendue_um2sr: float, target_snr: float = TARGET_SNR
) -> dict:
    """Electrons and SNR of a pixel of this etendue at white and at 18 % grey, and the
    exposure (and the highest line rate) that gives ``target_snr`` at white.

    Solves (k t)^2 = T^2 (k t + d t + r^2 + q^2) for the exposure t, with k the
    photo-electron rate at white, d the dark current, r the read noise, q the ADC's
    quantisation noise. A pixel no light reaches (``white_etendue_um2sr`` 0) reaches no
    SNR at any exposure: the exposure for the target is infinite, the line rate 0.
    """
    white = model.electrons_per_um2sr * white_etendue_um2sr
    k = white / (model.exposure_ms * 1e-3)  # e-/s at white
    d = model.dark_current_e_per_s
    c = model.read_noise_e**2 + model.gain_e_per_dn**2 / 12
    t2 = target_snr**2
    if k > 0:
        t_s = (t2 * (k + d) + np.sqrt(t2**2 * (k + d) ** 2 + 4 * k * k * t2 * c)) / (2 * k * k)
    else:  # no light: no exposure gives the target
        t_s = float("inf")
    return {
        "electrons_white": float(white),
        "electrons_grey18": float(GREY * white),
        "full_well_fraction_white": float((white + model.dark_e) / model.full_well_e),
        "saturated_white": bool(white + model.dark_e > model.full_well_e),
        "exposure_to_full_well_ms": float(model.full_well_e / (k + d) * 1e3)
        if k + d > 0
        else float("inf"),
        "snr_white": float(snr(model, white)),
        "snr_grey18": float(snr(model, GREY * white)),
        "target_snr_white": target_snr,
        "exposure_for_target_ms": float(t_s * 1e3),
        "max_line_rate_for_target_hz": float(model.exposure_duty / t_s),
        "saturates_at_target": bool(k > 0 and (k + d) * t_s > model.full_well_e),
    }


def exposure_for_white(model: SensorModel, white_etendue_um2sr: float, fill: float = 0.8) -> float:
    """Exposure (ms) at which white fills ``fill`` of the full well (an auto-exposure)."""
    k = model.electrons_per_um2sr * white_etendue_um2sr / model.exposure_ms  # e- per ms
    rate = k + model.dark_current_e_per_s * 1e-3
    return fill * model.full_well_e / rate if rate > 0 else float("inf")
