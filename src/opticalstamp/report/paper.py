"""The paper's statements on its prototype (Kawano 2016) and the model's figures beside them.

Computed from report.json's numbers, not written as prose: each row names the paper's
section, its statement, the paper's figure, the model's figure and their ratio. Where they
differ the reasons are the paper's unstated parameters (hole shape, the light-guide gap,
Fresnel losses, the size of its virtual detector), examined in docs/paper-comparison.md;
the model is not tuned to the paper.
"""

from __future__ import annotations

import math

import numpy as np

from .section import section
from .summary import PAPER, headline_figures


def _interp(xs: list, ys: list, x: float) -> float | None:
    """``ys`` at ``x`` by linear interpolation; None outside ``xs``."""
    if not xs or x < xs[0] - 1e-9 or x > xs[-1] + 1e-9:
        return None
    return float(np.interp(x, xs, ys))


def _row(
    section: str,
    statement: str,
    paper: float | None,
    model: float | None,
    unit: str,
    fmt: str = "{:.3g}",
    note: str = "",
) -> dict:
    ratio = None
    if paper not in (None, 0) and model is not None and math.isfinite(model):
        ratio = model / paper
    return {
        "section": section,
        "statement": statement,
        "paper": paper,
        "model": model,
        "unit": unit,
        "paper_text": "-" if paper is None else _text(fmt, paper),
        "model_text": "not computed" if model is None else _text(fmt, model),
        "ratio": ratio,
        "note": note,
    }


def one_in(v: float) -> str:
    """A small ratio as 1/N (0.0379 -> "1/26")."""
    return f"1/{1 / v:.0f}" if v > 0 else "0"


def _text(fmt: str, v: float) -> str:
    """``fmt`` applied to ``v``; ``"1/N"`` writes the ratio as :func:`one_in` does."""
    return one_in(v) if fmt == "1/N" else fmt.format(v)


def paper_vs_model(data: dict) -> list[dict]:
    """One row per statement of the paper that the report's numbers test (report.json's
    ``paper_vs_model``); a row whose figure the report did not compute (or whose section
    was not measurable) says so."""
    rows = []
    fig = headline_figures(data)
    diff = section(data, "diffraction") or {}
    edge = diff.get("geometric_edge_um")
    outside = (diff.get("fraction_outside") or {}).get("0.4")
    rows.append(
        _row(
            "§3, Fig. 6",
            "geometric edge of the 48 µm hole's shadow at Z = 1 mm",
            32.0,
            edge,
            "um",
            "{:.1f}",
        )
    )
    rows.append(
        _row(
            "§3, Fig. 6", "light diffracted outside that edge (0.4 µm)", 0.07, outside, "", "{:.3f}"
        )
    )
    sp = section(data, "spots") or {}
    zs, fwhm, ext = sp.get("z_mm", []), sp.get("fwhm_x_um", []), sp.get("extent_x_um", [])
    cell = (sp.get("meta") or {}).get("cell_um")
    at0 = _interp(zs, fwhm, 0.0)
    at3 = _interp(zs, ext, 3.0)
    rows.append(
        _row(
            "§3, Fig. 5",
            "spot at Z = 0 about one pixel (FWHM, in pixels)",
            1.0,
            None if at0 is None or not cell else at0 / cell,
            "pixel",
            "{:.2f}",
        )
    )
    rows.append(
        _row(
            "§3, Fig. 5",
            "spot at Z = 3 mm about 3 pixels edge to edge",
            3.0,
            None if at3 is None or not cell else at3 / cell,
            "pixel",
            "{:.2f}",
            "the model's edge is the exact support, faint penumbra included",
        )
    )
    land = (section(data, "ghosts") or {}).get("landing") or {}
    within = [v["within_detector_um2sr"] for v in land.values()]
    rows.append(
        _row(
            "§3",
            "no ghost light on the virtual detector (ghost etendue, µm²·sr)",
            0.0,
            max(within) if within else None,
            "µm²·sr",
            "{:.3g}",
            "the paper's detector size is unstated; ghost light lands further away",
        )
    )
    key = f"{(section(data, 'rmtf') or {}).get('dof_dpi', 200.0):g}"
    rows.append(
        _row(
            "§5, Fig. 11",
            f"depth of field, RMTF >= 0.3 at {key} dpi (measured)",
            PAPER["dof"],
            fig["dof"],
            "mm",
            "{:.2f}",
            "unstated: hole shape and the light-guide gap (docs/metrics.md)",
        )
    )
    eff = section(data, "efficiency") or {}
    rows.append(
        _row(
            "§5, Fig. 13",
            "light vs the F/10 lens (own path)",
            PAPER["light"],
            fig["light"],
            "",
            "1/N",
            "1/36 with circular holes and Fresnel losses (docs/metrics.md)",
        )
    )
    rows.append(
        _row(
            "§5, Fig. 13",
            "working F-number",
            PAPER["f_number"],
            fig["f_number"],
            "",
            "{:.0f}",
        )
    )
    area = eff.get("sensitive_area") or []
    gains = [a["gain_own_vs_design"] for a in area if a["area_scale"] == 4.0]
    rows.append(
        _row(
            "§5",
            "4x the sensitive area gives 4x the light",
            4.0,
            gains[0] if gains else None,
            "x",
            "{:.2f}",
            "the holes, not the pixel, limit the beam",
        )
    )
    rod_rows = (section(data, "rodlens") or {}).get("rows") or []
    rows.append(
        _row(
            "§4",
            "light vs a rod-lens array",
            PAPER["vs_rod_lens"],
            fig["vs_rod_lens"],
            "",
            "1/N",
            "against the 1-row 12-degree preset (docs/rodlens.md)",
        )
    )
    rows.append(
        _row(
            "§4",
            "a rod-lens array is at least 15 mm thick",
            PAPER["rod_lens_thickness_min"],
            rod_rows[1]["thickness_mm"] if len(rod_rows) > 1 else None,
            "mm",
            "{:.1f}",
            "sensor to document, no cover glass",
        )
    )
    rows.append(
        _row(
            "§5",
            "module thickness",
            PAPER["thickness"],
            fig["thickness"],
            "mm",
            "{:.2f}",
            "the model: sensor to document reference, without a housing",
        )
    )
    ocr = (section(data, "scans") or {}).get("ocr") or []
    cer = max((o["cer"] for o in ocr if o.get("points", 8.0) == 8.0), default=None)
    rows.append(
        _row(
            "§4, Fig. 8",
            "8-pt text clear at 0.5, 1.5 and 2.5 mm (worst OCR character error rate)",
            0.0,
            cer,
            "",
            "{:.3f}",
        )
    )
    return rows
