"""A fit's model against its measurement (issue 24): measured RMTF points beside the
nominal and the fitted design's curves (paper Fig. 11 with its dots), and residuals."""

from __future__ import annotations

import numpy as np

from ..analysis.responsivity import RAY, Optics, resolve_optics
from ..imaging.measure import measure_rmtf
from .fit import FitResult, Problem, layout_for
from .fitdata import Observation
from .fitmodel import spreads
from .fitwave import WaveModel


def rmtf_comparison(res: FitResult, observations: list[Observation], images: dict) -> dict:
    """Measured RMTF of each bar block (``images``: {name: image array}) and the nominal
    and fitted designs' RMTF curves (by the fit's optics, as its model: the paraxial own
    path, or the wave engine's light in its band, no ghost light) at those periods over 0
    to 1.2 x the highest height; depth of field of each."""
    from ..analysis.rmtf import rmtf

    points = []
    for o in observations:
        if o.kind != "bars" or o.name not in images:
            continue
        for b in measure_rmtf(images[o.name], o.dpi):
            points.append({"z_mm": o.z_mm, "period_um": b["period_um"], "rmtf": b["rmtf"]})
    top = max([o.z_mm for o in observations] + [1.0])
    zs = np.round(np.linspace(0.0, 1.2 * top, 25), 4)
    periods = _chart_periods([p["period_um"] for p in points]) or [254.0]
    dpis = [50800.0 / p for p in periods]
    curves = {}
    opt = fit_optics_of(res)
    how = {"method": "paraxial"} if opt.engine == "ray" else {"optics": opt}
    for key, d in (("nominal", res.design), ("fitted", res.fitted)):
        r = rmtf(d, dpi=dpis, z_mm=zs, ghosts=False, **how)
        curves[key] = {"z_mm": r.z_mm, "rmtf": r.rmtf_max, "dof_mm": r.dof_mm}
    return {"points": points, "curves": curves, "dpi": dpis, "optics": opt.engine}


def fit_optics_of(res: FitResult) -> Optics:
    """The optics a fit used (its ``optics`` record), resolved again for its nominal
    design: the same sampling, a pure function of the design."""
    if res.optics.get("engine") == "wave":
        return resolve_optics(res.design, "wave")
    return RAY


def _chart_periods(measured: list[float], tol: float = 0.03) -> list[float]:
    """The charts' periods from the periods measured on each image: those within ``tol``
    (relative) of each other are one chart's (each image measures its own), given as
    their median."""
    groups: list[list[float]] = []
    for p in sorted(measured):
        if groups and p <= groups[-1][0] * (1 + tol):
            groups[-1].append(p)
        else:
            groups.append([p])
    return [float(np.median(g)) for g in groups]


def residuals(res: FitResult, observations: list[Observation]) -> list[dict]:
    """Per image: its data, the fitted model (the fit's optics: under wave optics the
    wave model itself, one wave run) and the normalised residuals."""
    lay = layout_for(res.design, observations, res.names, res.pinned)
    opt = fit_optics_of(res)
    model = spreads if opt.engine == "ray" else WaveModel(opt.sampling)
    prob = Problem(res.design, observations, lay, model=model)
    r = prob.residuals(res.theta)
    out, at = [], 0
    for i, o in enumerate(observations):
        v, s = prob.data[i]
        n = v.size
        out.append(
            {
                "name": o.name,
                "kind": o.kind,
                "z_mm": o.z_mm,
                "data": v,
                "model": v + r[at : at + n] * s,
                "residual": r[at : at + n],
            }
        )
        at += n
    return out
