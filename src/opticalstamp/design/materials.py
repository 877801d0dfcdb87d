"""Refractive indices of the media a design may name.

A medium is either a plain refractive index (a number) or the name of a material
in :data:`CATALOGUE`, whose index depends on the wavelength through a published
dispersion formula. Wavelengths are in micrometres.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType

import numpy as np


def _sellmeier(b: tuple[float, ...], c: tuple[float, ...]) -> Callable[[float], float]:
    """Sellmeier formula n^2 = 1 + sum B_i l^2 / (l^2 - C_i), C_i in um^2."""

    def index(wavelength_um: float) -> float:
        l2 = wavelength_um**2
        return float(np.sqrt(1.0 + sum(bi * l2 / (l2 - ci) for bi, ci in zip(b, c, strict=True))))

    return index


def _soda_lime(wavelength_um: float) -> float:
    """Soda-lime float glass, M. Rubin, Sol. Energy Mater. 12, 275 (1985)."""
    return 1.5130 - 0.003169 * wavelength_um**2 + 0.003962 / wavelength_um**2


#: Named media. Sources: Schott data sheet (N-BK7); I. H. Malitson, JOSA 55, 1205 (1965)
#: (fused silica); N. Sultanova et al., Acta Phys. Pol. A 116, 585 (2009) (PMMA, the usual
#: light-guide plate material); M. Rubin (1985) (soda-lime glass, n_d ~ 1.52 as in the paper).
CATALOGUE: Mapping[str, Callable[[float], float]] = MappingProxyType(
    {
        "air": lambda wavelength_um: 1.0,
        "vacuum": lambda wavelength_um: 1.0,
        "N-BK7": _sellmeier(
            (1.03961212, 0.231792344, 1.01046945), (0.00600069867, 0.0200179144, 103.560653)
        ),
        "fused-silica": _sellmeier(
            (0.6961663, 0.4079426, 0.8974794), (0.0684043**2, 0.1162414**2, 9.896161**2)
        ),
        "PMMA": _sellmeier((1.1819,), (0.011313,)),
        "soda-lime": _soda_lime,
    }
)

#: Wavelength range (um) over which the catalogue formulas are used.
WAVELENGTH_RANGE_UM = (0.35, 1.1)


def refractive_index(medium: float | str, wavelength_um: float) -> float:
    """Refractive index of ``medium`` at ``wavelength_um``.

    Parameters
    ----------
    medium : float or str
        A refractive index, or a name in :data:`CATALOGUE` (case-insensitive).
    wavelength_um : float
        Vacuum wavelength in micrometres.
    """
    if isinstance(medium, int | float):
        return float(medium)
    key = {k.lower(): k for k in CATALOGUE}.get(medium.lower())
    if key is None:
        raise KeyError(f"unknown medium {medium!r}; known: {', '.join(sorted(CATALOGUE))}")
    return CATALOGUE[key](wavelength_um)
