"""The report's "model vs measurement" section (issue 24): the fit of a design to a
prototype's scans of the project's charts, as ``opticalstamp fit --report DIR`` wrote it
(``DIR/fit.json``), shown beside the design the report is about.

The section reads the fit; it computes nothing of its own: the estimates with their
errors (or the words :data:`~opticalstamp.studies.fitresult.HELD` where the images did not
determine a parameter and the fitted design holds its nominal value), the degeneracies
named, the fit's chi2, the measured RMTF points with the nominal and fitted designs'
curves (paper Fig. 11 with its dots) and each image's normalised residuals.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..design import Design
from ..studies.fitresult import optics_words
from ..validate import InputError

#: What the RMTF curves of each optics are (the fit's model's).
CURVES = (("ray", "paraxial own path"), ("wave", "the wave engine's light in its band"))
#: What a fit.json must hold for the section.
FIT_KEYS = ("design", "design_fingerprint", "fitted_fingerprint", "parameters", "chi2", "dof")


def load_fit(path: str | Path) -> dict:
    """A fit's JSON from ``path``: a folder ``opticalstamp fit --report`` wrote (its
    fit.json) or the JSON file itself.

    Raises
    ------
    InputError
        No such file, not JSON, or not a fit's JSON (the message names ``--fit``).
    """
    p = Path(path)
    f = p / "fit.json" if p.is_dir() else p
    if not f.is_file():
        raise InputError(
            f"--fit {path}: no fit.json there (write one with opticalstamp fit --report DIR)"
        )
    try:
        data = json.loads(f.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(f"--fit {path}: not a fit's JSON ({err})") from None
    missing = [k for k in FIT_KEYS if not isinstance(data, dict) or k not in data]
    if missing:
        raise InputError(
            f"--fit {path}: not a fit's JSON (opticalstamp fit --json / --report): "
            f"missing {', '.join(missing)}"
        )
    return data


def fit_section(fit: dict, design: Design) -> dict:
    """The section's numbers from a fit's JSON (:func:`load_fit`) and the report's design.

    Returns
    -------
    dict
        ``rows`` (parameter, nominal, fitted, error or the held words), ``held``,
        ``degeneracies``, ``reduced_chi2``, ``error_scale``, ``this_design`` ("fitted": the
        report is of the fitted design, "nominal": of the design fitted, None: another),
        ``rmtf`` (measured points, nominal and fitted curves), ``residuals`` (per
        image: name, kind, height, rms and the normalised residuals), ``optics`` (the
        fit's record), ``optics_text`` (it in words) and ``curves`` (what the curves are).
    """
    optics = fit.get("optics") or {}
    fp = design.fingerprint()
    this = {fit["fitted_fingerprint"]: "fitted", fit["design_fingerprint"]: "nominal"}.get(fp)
    rows = []
    for name, p in fit["parameters"].items():
        held = p.get("held")
        err = held if held else ("undetermined" if p["error"] is None else p["error"])
        rows.append([name, p["nominal"], p["value"], err])
    for name, v in fit.get("pinned", {}).items():
        rows.append([name, None, v, "pinned (--pin)"])
    residuals = []
    for r in fit.get("residuals", []):
        res = [float(v) for v in r["residual"]]
        rms = (sum(v * v for v in res) / max(len(res), 1)) ** 0.5
        residuals.append(
            {"name": r["name"], "kind": r["kind"], "z_mm": r["z_mm"], "rms": rms, "residual": res}
        )
    return {
        "design": fit["design"],
        "this_design": this,
        "images": fit.get("images", []),
        "rows": rows,
        "held": fit.get("held", {}),
        "degeneracies": list(fit.get("degeneracies", [])),
        "chi2": fit["chi2"],
        "dof": fit["dof"],
        "reduced_chi2": fit["chi2"] / max(fit["dof"], 1),
        "error_scale": fit.get("error_scale"),
        "rmtf": fit.get("rmtf"),
        "residuals": residuals,
        "optics": optics,
        "optics_text": optics_words(optics)
        + "."
        + (f" Warning: {optics['warning']}" if optics.get("warning") else ""),
        "curves": dict(CURVES)[optics.get("engine", "ray")],
    }


def fit_figures(section: dict) -> dict:
    """The section's figures, file name -> (plot, its arguments): the RMTF against height
    (where the fit's images held bar blocks) and the residuals (where fit.json has them)."""
    from .plotting.fit import plot_fit_residuals, plot_fit_rmtf

    out = {}
    if section.get("rmtf") and section["rmtf"].get("points"):
        out["fit_rmtf.png"] = (plot_fit_rmtf, section["rmtf"])
    if section.get("residuals"):
        out["fit_residuals.png"] = (plot_fit_residuals, section["residuals"])
    return out
