"""Figures of the stamp against rod-lens arrays (`compare` and the report's rod-lens
section): contrast against height, light and thickness, a rod-lens array's ripple and
details."""

from __future__ import annotations

import numpy as np

from .axes import subplots


def plot_compare_contrast(rows: list[dict], dof_dpi: float | None = None, threshold: float = 0.3):
    """Contrast vs object height from the document reference, every design on one axis.

    One panel per chart resolution; stamps solid, rod-lens arrays dashed. ``dof_dpi``:
    the depth-of-field chart (default: the rows' own, ``dof_dpi`` of the first).
    """
    dof_dpi = rows[0].get("dof_dpi", 200.0) if dof_dpi is None else dof_dpi
    keys = [
        k for k in rows[0]["contrast"]["by_dpi"] if all(k in r["contrast"]["by_dpi"] for r in rows)
    ]
    fig, axes = subplots(1, len(keys), figsize=(4.0 * len(keys), 3.6), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, key in zip(axes, keys, strict=True):
        for i, r in enumerate(rows):
            ls = "--" if r["kind"] == "rod-lens-array" else "-"
            c = r["contrast"]
            ax.plot(c["heights_mm"], c["by_dpi"][key], ls, color=f"C{i}", label=r["name"])
        ax.axhline(threshold, color="k", lw=0.6, ls=":")
        ax.axvline(0.0, color="0.5", lw=0.6)
        ax.set_title(f"{key} dpi", fontsize=9)
        ax.set_ylim(0, 1.02)
    fig.supxlabel("object height from the document reference (mm)", fontsize=9)
    axes[0].set_ylabel("contrast (RMTF, max over chart shift)")
    axes[0].legend(fontsize=7, loc="upper right")
    fig.suptitle(
        f"contrast vs height (dashed: rod-lens arrays; dotted: {threshold:g} = DOF at "
        f"{dof_dpi:g} dpi)",
        fontsize=10,
    )
    return fig


def plot_compare_light(rows: list[dict]):
    """Light relative to the paper's F/10 reference, as points on a log axis (a bar's
    length means nothing on a log axis), with its working F-number; and the thickness
    (bars: a linear axis)."""
    fig, (a1, a2) = subplots(
        1, 2, figsize=(9.6, 0.9 + 0.45 * len(rows)), layout="constrained", sharey=True
    )
    names = [r["name"] for r in rows]
    y = np.arange(len(rows))
    light = np.array([r["light_vs_f10"] for r in rows])
    se = np.array([r.get("light_vs_f10_se", 0.0) or 0.0 for r in rows])
    colours = [f"C{i}" for i in range(len(rows))]
    for yi, v, e, c in zip(y, light, se, colours, strict=True):
        a1.errorbar(v, yi, xerr=e if e > 0 else None, fmt="o", color=c, ms=7, capsize=3)
    a1.set_xscale("log")
    a1.axvline(1.0, color="k", lw=0.6, ls=":")
    for yi, r in zip(y, rows, strict=True):
        f = r.get("working_f_number")
        tag = f"{r['light_vs_f10']:.3g}" + (f" (F {f:.1f})" if f else "")
        a1.annotate(tag, (r["light_vs_f10"], yi), xytext=(7, 5), textcoords="offset points",
                    fontsize=8, va="bottom")  # fmt: skip
    lo, hi = light[light > 0].min(initial=1.0), light.max(initial=1.0)
    a1.set_xlim(min(lo, 1.0) / 3, max(hi, 1.0) * 6)
    a1.set_ylim(len(rows) - 0.4, -0.6)
    a1.set_yticks(y, names, fontsize=8)
    a1.grid(axis="x", which="major", lw=0.4, alpha=0.5)
    a1.set_xlabel("light vs F/10 1:1 lens (own path; log axis; dotted: equal)")
    a2.barh(y, [r["thickness_mm"] for r in rows], color=colours, height=0.5)
    a2.set_xlabel("sensor to document reference (mm)")
    a2.tick_params(labelleft=False)
    fig.suptitle("light and thickness", fontsize=10)
    return fig


def _ripple_axes(ax, positions_um, relative, ripple: float, noise: float, name: str = ""):
    """A rod-lens pixel's etendue / mean along one rod period, on ``ax``."""
    ax.plot(positions_um, relative, "o-", ms=3)
    ax.set_xlabel("pixel centre from a rod axis (µm), one rod period")
    ax.set_ylabel("etendue / mean")
    ax.set_title(f"{name}ripple {ripple:.3f} (noise alone ~{noise:.3f})", fontsize=9)


def plot_rod_ripple(eff):
    """A rod-lens pixel's etendue along one rod period (efficiency ripple)."""
    fig, ax = subplots(figsize=(6.0, 3.2))
    g = np.asarray(eff.etendue_by_position_um2sr)
    _ripple_axes(
        ax, eff.positions_um, g / g.mean(), eff.ripple, eff.ripple_noise, f"{eff.design}: "
    )
    return fig


def plot_rod_details(row: dict, psf: dict):
    """A rod-lens array: ripple along one rod period, LSF and MTF vs height, point PSFs."""
    fig, axes = subplots(1, 5, figsize=(17, 3.3), layout="constrained")
    rp = row["ripple_profile"]
    _ripple_axes(axes[0], rp["positions_um"], rp["relative"], row["ripple"], row["ripple_noise"])
    lsf = row["lsf"]
    hs = np.asarray(lsf["heights_mm"])
    for h in (0.0, 0.5, 1.0):
        i = int(np.argmin(np.abs(hs - h)))
        axes[1].plot(lsf["x_um"], lsf["per_um"][i], label=f"{hs[i]:g} mm")
    axes[1].set_xlabel("x from the pixel centre (µm)")
    axes[1].set_ylabel("LSF (1/µm, pixel included)")
    axes[1].legend(fontsize=7)
    m = row["mtf"]
    for key, vals in m["by_dpi"].items():
        axes[2].plot(m["heights_mm"], vals, label=f"{key} dpi")
    axes[2].set_xlabel("height from focus (mm)")
    axes[2].set_ylabel("MTF at the chart fundamental")
    axes[2].legend(fontsize=7)
    edges = np.asarray(psf["x_edges_um"])
    ext = [edges[0], edges[-1], edges[0], edges[-1]]
    k = len(psf["heights_mm"]) - 1
    for ax, (name, at) in zip(axes[3:], psf["at"].items(), strict=False):
        img = np.asarray(at["by_height"][k]["image"])
        ax.imshow(img, extent=ext, origin="lower", cmap="magma", interpolation="nearest")
        ax.set_title(
            f"point {name} (x = {at['x_um']:.0f} µm), {psf['heights_mm'][k]:g} mm: "
            f"rms {at['by_height'][k]['rms_um']:.0f} µm",
            fontsize=8,
        )
        ax.set_xlabel("x (µm)")
        half = max(150.0, 4 * at["by_height"][k]["rms_um"])
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
    fig.suptitle(f"{row['name']}: rod-lens array details", fontsize=10)
    return fig
