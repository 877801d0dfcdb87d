"""A design's illumination, exposure and sensor electronics: its optional ``[electronics]``
table (both kinds of design).

A used pixel that sees an etendue-weighted reflectance S (um^2 sr) of a document lit with
illuminance E (lux) receives the luminous flux E/pi * S * 1e-12 (lm); a photon-rate factor
(photons per second per lumen of the LED's light), the quantum efficiency and the exposure
give the mean photo-electrons (:attr:`Electronics.electrons_per_um2sr`). What the sensor
then does with them (shot noise, PRNU, dark signal and DSNU, full well, read noise, an ADC
of ``adc_bits`` over the full well above a black-level pedestal) is
:mod:`opticalstamp.imaging.sensor`'s, where this model is also ``SensorModel``.

Default values are typical orders of magnitude for a contact-image-sensor line, not a
datasheet: 10 klux on the document (CIS light guides deliver 10^4 lux and more), 1 ms
exposure per line, QE 0.5, 60 ke- full well, 30 e- read noise, 1 % PRNU, 20 e- DSNU, 1000
e-/s dark current, 12-bit ADC, 9.1e15 photons/s per lumen (white LED: about 300 lm per
radiometric W, mean photon energy 2.3 eV). Set them from your sensor and LED datasheets.

A design without the table has these defaults, and a table equal to them is left out of
the design's dump: a design's fingerprint changes only when its electronics differ from
the defaults.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator


def _finite(value: object) -> object:
    """Accept int or float, refuse booleans and strings (TOML's `true`, `"42.0"`)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"expected a number (got {type(value).__name__} {value!r})")
    return value


def _whole(value: object) -> object:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"expected an integer (got {type(value).__name__} {value!r})")
    return value


Real = Annotated[float, BeforeValidator(_finite), Field(allow_inf_nan=False)]
#: The least illuminance on the page (lux): starlight. Less makes no image and underflows
#: the signal budget (the exposure for a target SNR grows past any float).
MIN_ILLUMINANCE_LUX = 1e-3
Whole = Annotated[int, BeforeValidator(_whole)]
#: The light a design is lit with (analysis/spectrum.py): "mono" is one wavelength, the
#: design's ``wavelength_um``; the others are typical LED spectra times a silicon QE curve.
ILLUMINATIONS = ("mono", "white", "red", "green", "blue", "rgb")
Illumination = Literal["mono", "white", "red", "green", "blue", "rgb"]
#: How a grey value is made of linear red, green and blue (Rec. 709 luminance weights):
#: colour images read as grey, grey scans of a colour document, and the light of a colour
#: scanner's grey scan (its three LEDs lit together in these proportions,
#: :func:`~opticalstamp.analysis.spectrum.grey_light`).
LUMA = (0.2126, 0.7152, 0.0722)


class Electronics(BaseModel):
    """Illumination, exposure and sensor electronics (all validated, frozen)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    # lux; from starlight up: below 1e-3 lux the signal budget's figures underflow
    illuminance_lux: Annotated[Real, Field(ge=MIN_ILLUMINANCE_LUX, le=1e7)] = 10_000.0
    exposure_ms: Annotated[Real, Field(gt=0, le=1e4)] = 1.0
    photons_per_lumen_s: Annotated[Real, Field(gt=0)] = 9.1e15
    quantum_efficiency: Annotated[Real, Field(gt=0, le=1)] = 0.5
    full_well_e: Annotated[Real, Field(gt=0)] = 60_000.0
    read_noise_e: Annotated[Real, Field(ge=0)] = 30.0
    prnu: Annotated[Real, Field(ge=0, lt=0.5)] = 0.01
    dsnu_e: Annotated[Real, Field(ge=0)] = 20.0
    dark_current_e_per_s: Annotated[Real, Field(ge=0)] = 1000.0
    adc_bits: Annotated[Whole, Field(ge=1, le=24)] = 12
    black_level_dn: Annotated[Whole, Field(ge=0)] = 64  # ADC pedestal: keeps dark noise unclipped
    exposure_duty: Annotated[Real, Field(gt=0, le=1)] = 1.0  # fraction of the line period
    channel_response: tuple[
        Annotated[Real, Field(gt=0)], Annotated[Real, Field(gt=0)], Annotated[Real, Field(gt=0)]
    ] = (0.8, 1.0, 0.6)  # R, G, B relative
    # the light's spectrum for the wave engine: one wavelength (the design's), a white
    # phosphor LED, one colour LED, or R, G and B LEDs lit in turn (three channels)
    illumination: Illumination = "mono"

    @model_validator(mode="after")
    def _pedestal(self) -> Electronics:
        top = 2**self.adc_bits - 1
        if self.black_level_dn >= top:
            raise ValueError(
                f"black_level_dn ({self.black_level_dn}) must be below the ADC's top count "
                f"2^adc_bits - 1 = {top}"
            )
        return self

    @property
    def electrons_per_um2sr(self) -> float:
        """Mean photo-electrons per um^2 sr of etendue-weighted white (reflectance 1)."""
        return (
            self.illuminance_lux
            / math.pi
            * 1e-12
            * self.photons_per_lumen_s
            * self.quantum_efficiency
            * self.exposure_ms
            * 1e-3
        )

    @property
    def gain_e_per_dn(self) -> float:
        return self.full_well_e / (2**self.adc_bits - 1)

    @property
    def dark_e(self) -> float:
        return self.dark_current_e_per_s * self.exposure_ms * 1e-3


def is_default(value: object) -> bool:
    """Whether ``value`` is the default electronics (left out of a design's dump)."""
    return value == Electronics()


def electronics_field():
    """The ``electronics`` field of a design: left out of its dump (and so of its
    fingerprint) while it equals the defaults."""
    return Field(default_factory=Electronics, exclude_if=is_default)
