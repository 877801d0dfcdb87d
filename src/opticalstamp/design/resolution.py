"""A design's own resolution and the charts that judge it.

The merged output line of a staggered stamp has the pitch ``row_pitch_um / rows``
(84.6 um for the paper's prototype: 300 dpi); a rod-lens scanner's line has its pixel
pitch. Every default that depends on resolution follows from here, so that a 600-dpi
design is judged at 600 dpi and never at the paper's 300:

- :func:`nominal_dpi`: the line's resolution as an engineer names it (300.24 -> 300);
- :func:`dof_chart_dpi`: the chart of the depth of field, 2/3 of the line's resolution
  (the paper judges its 300-dpi scanner on the 200-dpi chart, section 4; 400 dpi for a
  600-dpi design, 800 for 1200);
- :func:`chart_dpis`: the RMTF charts, the paper's 100/150/200/247 dpi scaled with the
  line's resolution (exactly the paper's for a 300-dpi design).
"""

from __future__ import annotations

from ..defaults import PAPER_CHART_DPI
from ..units import UM_PER_INCH

#: the paper's merged line (dpi) against which its charts are scaled
PAPER_LINE_DPI = 300.0
#: the depth of field is judged on the chart at this fraction of the line's resolution
DOF_CHART_FRACTION = 2.0 / 3.0
#: a resolution within this relative distance of a multiple of 25 dpi is named by it
_ROUND_STEP_DPI, _ROUND_TOL = 25.0, 2.5e-3


def output_pitch_um(design) -> float:
    """Pitch (um) of the design's merged output line: the row pitch over the rows for a
    stamp, the pixel pitch for a rod-lens scanner."""
    pitch = getattr(design, "output_pitch_um", None)
    if pitch is not None:
        return float(pitch)
    s = design.sensor
    return s.row_pitch_um / s.rows


def output_dpi(design) -> float:
    """Resolution (dpi) of the merged output line, exactly (300.236 for 84.6 um)."""
    return UM_PER_INCH / output_pitch_um(design)


def nominal_dpi(design) -> float:
    """The output line's resolution as it is named: the nearest multiple of 25 dpi where
    the exact figure lies within 0.25 % of one (84.6 um -> 300, 42.3 um -> 600, 21.15 um
    -> 1200), else the nearest whole dpi (25 um -> 1016)."""
    exact = output_dpi(design)
    near = round(exact / _ROUND_STEP_DPI) * _ROUND_STEP_DPI
    if near > 0 and abs(exact - near) <= _ROUND_TOL * near:
        return float(near)
    return float(round(exact))


def dof_chart_dpi(design) -> float:
    """The chart (dpi) on which the depth of field is judged by default: 2/3 of the
    line's nominal resolution, to a whole dpi (200 for 300 dpi, as paper section 4;
    400 for 600; 800 for 1200)."""
    return float(round(nominal_dpi(design) * DOF_CHART_FRACTION))


def chart_dpis(design) -> tuple[float, ...]:
    """The RMTF charts (dpi) for the design: the paper's 100, 150, 200 and 247 dpi scaled
    by the line's nominal resolution over 300 (the paper's own for a 300-dpi design),
    with the depth-of-field chart among them, ascending."""
    k = nominal_dpi(design) / PAPER_LINE_DPI
    out = {float(round(d * k)) for d in PAPER_CHART_DPI} | {dof_chart_dpi(design)}
    return tuple(sorted(out))
