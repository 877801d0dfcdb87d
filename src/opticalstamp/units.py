"""Units: micrometres, millimetres and dots per inch, in one place.

Lengths are micrometres in code and design files, object distances Z millimetres at the
interface. A resolution of ``dpi`` dots per inch has a pixel pitch of 25 400 / dpi um; a
``dpi`` bar chart has one black and one white bar of that pitch, so its period is twice
the pitch (508, 339, 254 and 206 um for the paper's 100, 150, 200 and 247 dpi).
"""

from __future__ import annotations

UM_PER_INCH = 25_400.0
UM_PER_MM = 1_000.0


def pitch_of_dpi(dpi: float) -> float:
    """Pixel pitch (um) of a resolution in dots per inch."""
    return UM_PER_INCH / dpi


def dpi_of_pitch(pitch_um: float) -> float:
    """Resolution (dots per inch) of a pixel pitch in um."""
    return UM_PER_INCH / pitch_um


def period_of_dpi(dpi: float) -> float:
    """Period (um) of a ``dpi`` bar chart: one black and one white bar of 25 400 / dpi um."""
    return 2.0 * UM_PER_INCH / dpi


def dpi_of_period(period_um: float) -> float:
    """The ``dpi`` of a bar chart of period ``period_um`` (um)."""
    return 2.0 * UM_PER_INCH / period_um


def mm_to_um(mm: float) -> float:
    return mm * UM_PER_MM


def um_to_mm(um: float) -> float:
    return um / UM_PER_MM
