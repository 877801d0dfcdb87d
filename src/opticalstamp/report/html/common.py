"""What every section of the report's page uses: tables, numbers, and the block of a
section that is not measurable."""

from __future__ import annotations

import html
import math

from ..section import not_measurable


def table(rows: list[list], head: list[str]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(fmt(c))}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><tr>{th}</tr>{body}</table>"


def fmt(v) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "-" if v is None else str(v)


def percent(v: float) -> str:
    """A percentage to two significant digits, never in exponent form (4.2, 17, 171)."""
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    return f"{v:.{max(0, 1 - math.floor(math.log10(abs(v))))}f}"


def dof_cell(res: dict, key: str) -> str:
    """A depth of field from an RMTF result's JSON: "2.48 mm", or ">= 4.50 mm" where the
    RMTF never fell below the threshold in the Z range."""
    v = res["dof_mm"][key]
    return f"≥ {v:.2f} mm" if res.get("dof_open_ended", {}).get(key) else f"{v:.2f} mm"


def unmeasured(heading: str, *values, level: int = 2) -> str | None:
    """The block of a section that could not be computed: its heading and "not
    measurable: reason" (the first of report.json's ``values`` that holds a reason); None
    where every value was computed."""
    for value in values:
        reason = not_measurable(value)
        if reason is not None:
            return f"<h{level}>{heading}</h{level}>\n<p>not measurable: {html.escape(reason)}</p>\n"
    return None
