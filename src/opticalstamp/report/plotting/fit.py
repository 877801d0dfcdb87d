"""Figures of `opticalstamp fit` (issue 24): RMTF against height, measured and modelled;
the residuals of each image."""

from __future__ import annotations

import numpy as np

from .axes import subplots


def plot_fit_rmtf(comp: dict):
    """Measured RMTF points and the nominal (dashed) and fitted (solid) curves."""
    fig, ax = subplots(figsize=(6.4, 4.2))
    colours = ["C0", "C1", "C2", "C3", "C4", "C5"]
    keys = list(comp["curves"]["fitted"]["rmtf"])
    for i, dpi in enumerate(comp["dpi"]):
        key = min(keys, key=lambda k: abs(float(k) - dpi))  # the curve of this chart
        c = colours[i % len(colours)]
        for name, style in (("nominal", "--"), ("fitted", "-")):
            cur = comp["curves"][name]
            ax.plot(cur["z_mm"], cur["rmtf"][key], style, color=c, label=f"{dpi:.0f} dpi {name}")
        pts = [p for p in comp["points"] if abs(50800.0 / p["period_um"] - dpi) < 0.05 * dpi]
        ax.plot([p["z_mm"] for p in pts], [p["rmtf"] for p in pts], "o", color=c)
    ax.set_xlabel("Z (mm)")
    ax.set_ylabel("RMTF")
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("measured (dots), nominal (dashed), fitted (solid)")
    return fig


def plot_fit_residuals(items: list[dict]):
    """Normalised residuals of each image against the datum's index."""
    n = len(items)
    fig, axes = subplots(n, 1, figsize=(6.4, 1.3 * n + 0.6), squeeze=False)
    for ax, it in zip(axes[:, 0], items, strict=True):
        r = np.asarray(it["residual"])
        ax.plot(r, ".", ms=2)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel("res / sigma", fontsize=7)
        ax.set_title(
            f"{it['name']} ({it['kind']}, Z = {it['z_mm']:g} mm): rms {np.sqrt(np.mean(r**2)):.2f}",
            fontsize=8,
        )
    return fig
