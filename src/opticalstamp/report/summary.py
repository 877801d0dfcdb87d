"""The report's verdict: the figures an engineer decides with, checked against a spec.

From report.json's numbers (no new computation): the ghost-free radius (the nearest ghost
light on the object plane over the heights analysed) and where ghost light goes, the
depth of field at the RMTF section's chart ("≥" where the Z range ended first), the light
against the paper's F/10 lens (own path: ghost light is crosstalk) and against the
single-row rod-lens array, the working F-number, the thickness, the tolerance yield. A
spec such as ``dof>=2.2,ghost_radius>=5`` marks each figure pass or fail; for the paper's
prototype the paper's own figure stands beside the model's.
"""

from __future__ import annotations

import math
import re
from types import MappingProxyType

from ..analysis.dof import dof_text
from ..validate import InputError
from .section import not_measurable, section

#: Figures a spec may name: key -> (what, unit).
FIGURES = MappingProxyType(
    {
        "ghost_radius": ("ghost-free radius on the object plane", "mm"),
        "dof": ("depth of field (RMTF rule: first Z where the RMTF falls below 0.3)", "mm"),
        "raw_dof": (
            "depth of field of the raw scan by the restoration's rule (fundamental "
            "amplitude and contrast to noise)",
            "mm",
        ),
        "restored_dof": (
            "depth of field restored with the known blur (Wiener, height known), by the "
            "same rule as the raw scan's above",
            "mm",
        ),
        "light": ("light vs the F/10 lens (own path; by wave optics: the light in its band)", ""),
        "f_number": ("working F-number", ""),
        "vs_rod_lens": ("light vs a 1-row 12-degree rod-lens array", ""),
        "thickness": ("sensor to document reference", "mm"),
        "yield": ("tolerance yield", ""),
    }
)
#: The paper's statements on its prototype (§4 measured depth of field, §5 light efficiency
#: 1/36 and working F 60, module 5 mm thick, ~1/100 of a rod-lens array's light and 1/25
#: with a sensor of 4x the sensitive area, a rod-lens array at least 15 mm thick); the
#: verdict shows those named as in :data:`FIGURES`.
PAPER = MappingProxyType(
    {
        "dof": 3.5,
        "light": 1 / 36,
        "f_number": 60.0,
        "vs_rod_lens": 1 / 100,
        "vs_rod_lens_4x_area": 1 / 25,
        "thickness": 5.0,
        "rod_lens_thickness_min": 15.0,
    }
)
#: the restoration study's depth-of-field figures -> its name for the version
_RESTORED = MappingProxyType({"raw_dof": "raw", "restored_dof": "wiener"})
_SPEC_RE = re.compile(r"^([a-z_]+)(>=|<=)([-+0-9.eE]+)$")


def parse_report_spec(text: str | None) -> list[tuple[str, str, float]]:
    """'dof>=2.2,ghost_radius>=5' -> [(figure, op, value)]; InputError naming the part."""
    if not text:
        return []
    out = []
    for part in text.replace(" ", "").split(","):
        m = _SPEC_RE.match(part)
        if not m or m.group(1) not in FIGURES:
            raise InputError(
                f"--spec: cannot read {part!r}; use figure>=number or figure<=number with "
                f"the figures {', '.join(FIGURES)}, comma-separated"
            )
        try:
            value = float(m.group(3))
        except ValueError:
            raise InputError(f"--spec: {part!r}: {m.group(3)!r} is not a number") from None
        out.append((m.group(1), m.group(2), value))
    return out


def _nearest_mm(data: dict) -> dict:
    """The nearest ghost light on the object plane (mm) at each Z where any lands (none
    where the ghost analysis is not measurable)."""
    land = (section(data, "ghosts") or {}).get("landing") or {}
    return {z: v["nearest_um"] / 1000 for z, v in land.items() if v["nearest_um"] is not None}


def headline_figures(data: dict) -> dict:
    """The figures of :data:`FIGURES` from report.json's numbers (None: not computed, or
    its section not measurable)."""
    nearest = _nearest_mm(data)
    r = section(data, "rmtf")
    eff = section(data, "efficiency")
    values = {
        "ghost_radius": (min(nearest.values()) if nearest else math.inf)
        if section(data, "ghosts")
        else None,
        "dof": r["dof_mm"][f"{r['dof_dpi']:g}"] if r else None,
        "light": eff["ratio_own"] if eff else None,
        "f_number": eff["working_f_number_own"] if eff else None,
        "thickness": data["stack"][0]["z_top_um"] / 1000 if data.get("stack") else None,
        "vs_rod_lens": None,
        "yield": None,
        "raw_dof": None,
        "restored_dof": None,
    }
    rest = section(data, "restoration")
    if rest and "wiener" in rest["study"]["dof"]:
        values["raw_dof"] = rest["study"]["dof"]["raw"]["dof_mm"]
        values["restored_dof"] = rest["study"]["dof"]["wiener"]["dof_mm"]
    rod = section(data, "rodlens")
    if rod and len(rod["rows"]) > 1:
        values["vs_rod_lens"] = rod["rows"][0]["light_vs_f10"] / rod["rows"][1]["light_vs_f10"]
    tol = section(data, "tolerance")
    if tol and tol.get("spec") and not _yield_doubt(tol):
        values["yield"] = tol["yield"]
    return values


def _optics_line(data: dict) -> str | None:
    """The ray-vs-wave section's verdict in one line; "not measurable: reason" where it
    was not computed; None where the report has no such section."""
    reason = not_measurable(data.get("ray_vs_wave"))
    if reason is not None:
        return f"not measurable: {reason}"
    w = section(data, "ray_vs_wave") or {}
    text = w.get("verdict", {}).get("text")
    if text and (data.get("design") or {}).get("electronics", {}).get("illumination") == "rgb":
        name = (w.get("meta") or {}).get("spectrum", {}).get("name")
        text = f"(the {name} channel, the one that diffracts most) {text}"
    return text


def _yield_doubt(tol: dict) -> str | None:
    """Why a tolerance yield is no headline: the study's estimator disagrees with the exact
    tracer on the nominal design beyond its stated accuracy (None: no doubt)."""
    off = (tol.get("meta") or {}).get("nominal_disagrees") or []
    if not off:
        return None
    return (
        f"the tolerance yield is left out: its estimator ({tol['meta'].get('estimator', '')}) "
        f"is off beyond its stated accuracy on the nominal design in {', '.join(off)} "
        "(tolerance --estimator trace evaluates every sample exactly: by the exact tracer, "
        "or by wave optics the exact wave figures)"
    )


def summary(data: dict, spec=(), paper: bool = False) -> dict:
    """The verdict from report.json's numbers; ``spec`` from :func:`parse_report_spec`;
    ``paper``: show the paper's figures (the design is the paper's prototype)."""
    values = headline_figures(data)
    nearest = _nearest_mm(data)
    g = section(data, "ghosts")
    within = {z: v["within_detector_um2sr"] for z, v in (g["landing"] if g else {}).items()}
    r = section(data, "rmtf")
    key = f"{r['dof_dpi']:g}" if r else None
    tol = section(data, "tolerance")
    rest = section(data, "restoration")
    checks = {}
    for name, op, v in spec:
        got = values.get(name)
        ok = None if got is None else bool(got >= v if op == ">=" else got <= v)
        checks[name] = {"spec": f"{op} {v:g}", "pass": ok}
    chans = _headline_channels(r, eff=section(data, "efficiency"))
    said = {}  # a colour scanner: which channel gives the figure
    if chans and chans["dof"] and r:
        said["dof"] = f"{dof_text(r)} ({chans['dof']} channel, the worst)"
    if chans and chans["light"] and values["light"]:
        said["light"] = f"1/{1 / values['light']:.0f} ({chans['light']} channel, the weakest)"
    rows = []
    for name, (what, unit) in FIGURES.items():
        rows.append(
            {
                "figure": name,
                "what": what,
                "value": values[name],
                "unit": unit,
                "bound": (name == "dof" and bool(r and r.get("dof_open_ended", {}).get(key)))
                or (
                    name in _RESTORED
                    and bool(rest)
                    and bool(rest["study"]["dof"][_RESTORED[name]]["open_ended"])
                ),
                "check": checks.get(name),
                "paper": PAPER.get(name) if paper else None,
                "text": said.get(name) or (dof_text(r) if name == "dof" and r else None),
            }
        )
    return {
        "figures": rows,
        "ghost_nearest_mm_by_z": nearest,
        "ghost_within_detector_um2sr_by_z": within,
        "ghost_fraction": g["ghost_fraction"] if g else None,
        "dof_dpi": r["dof_dpi"] if r else None,
        "tolerance_spec": tol.get("spec") if tol else None,
        "yield_note": _yield_doubt(tol) if tol and tol.get("spec") else None,
        "spec": [f"{n}{op}{v:g}" for n, op, v in spec],
        "meets_spec": all(c["pass"] for c in checks.values()) if checks else None,
        # the ray-vs-wave section's verdict in one line, or why it has none (None: not run)
        "optics": _optics_line(data),
        # which engine gave the headline RMTF, depth of field and light, and why
        "headline_optics": data.get("optics"),
        # a colour scanner: the channels of the headline figures, and the optics of the
        # analyses of one light where it differs (None: one light)
        "headline_channels": chans,
        "optics_one_light": data.get("optics_one_light"),
        # the engine each analysis of one light ran by, as its section records it
        "one_light_engines": one_light_engines(data),
    }


def one_light_engines(data: dict) -> dict[str, str]:
    """The engine ("ray" or "wave") that each analysis of one light ran by, as its section
    of report.json records it: the spots' ``meta.optics.engine``, the scans' and the
    restoration's ``optics``; a section not computed is left out (one without the record,
    as written before it was kept: ray optics, as all were then)."""
    out = {}
    spots = section(data, "spots")
    if spots:
        out["spots"] = ((spots.get("meta") or {}).get("optics") or {}).get("engine", "ray")
    for name in ("scans", "restoration"):
        sec = section(data, name)
        if sec:
            out[name] = sec.get("optics", "ray")
    return out


def _headline_channels(r: dict | None, eff: dict | None) -> dict | None:
    """Which channel of a colour scanner gives the verdict's depth of field (the worst)
    and its light (the weakest signal), {"dof": name, "light": name, "channels": [...]};
    None for one light."""
    chans = ((r or {}).get("meta") or {}).get("channels")
    light = ((eff or {}).get("meta") or {}).get("optics", {}).get("channels")
    if not chans and not light:
        return None
    return {
        "dof": r["meta"]["headline"]["channel"] if chans else None,
        "light": eff["meta"]["optics"]["headline"]["channel"] if light else None,
        "channels": list(chans or light),
    }
