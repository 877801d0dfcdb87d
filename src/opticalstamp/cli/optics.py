"""The ``--optics`` option shared by the commands that consume a pixel's responsivity."""

from __future__ import annotations

from typing import Annotated

import typer

OpticsOpt = Annotated[
    str,
    typer.Option(
        "--optics",
        help="ray (geometric optics, exact tracer), wave (scalar diffraction in the "
        "wave engine's band, joined with the traced far ghosts) or auto (wave where the "
        "measured validity rule says ray optics is off by more than its tolerance)",
    ),
]


def optics_line(meta: dict) -> str:
    """One line saying which optics gave the figures, and why."""
    o = meta
    if o["engine"] == "ray":
        return f"optics: ray (geometric; {o['reason']})"
    from ..analysis.responsivity import light_words

    losses = ", Fresnel losses in both" if o.get("fresnel") else ""
    return (
        f"optics: wave {light_words(o)}, band |s| < {o['band']:.3f}, far ghosts "
        f"traced{losses} ({o['reason']})"
    )
