"""The ray-against-wave figure of one design (issue 23): line-spread functions at each Z
and the RMTF, FWHM and centre-cell share against Z by both engines."""

from __future__ import annotations

import numpy as np

from .axes import REPORT_WIDTH_IN, subplots


def plot_wave_ray(c):
    """Figure of a :class:`~opticalstamp.analysis.wavecompare.WaveRayComparison`: left,
    row A's x line-spread function at each Z (wave solid, ray dashed, µm·sr per µm);
    right, the RMTF on the depth-of-field chart, the FWHM and the central cell's share
    against Z."""
    fig, axes = subplots(1, 2, figsize=(REPORT_WIDTH_IN, 4.0), layout="constrained")
    p = c.profiles
    ax = axes[0]
    for i, z in enumerate(c.z_mm):
        col = f"C{i}"
        ax.plot(p["wave_x_um"], p["wave_lsf"][i], color=col, lw=1.2, label=f"Z = {z:g} mm")
        ax.plot(p["ray_x_um"], p["ray_lsf"][i], color=col, lw=0.9, ls="--")
    half = 1.5 * max(c.wave["fwhm_x_um"] + c.ray["fwhm_x_um"])
    ax.set_xlim(-half, half)
    ax.set_xlabel("X on the object plane (µm)")
    ax.set_ylabel("line-spread function (µm·sr per µm)")
    ax.set_title("x LSF, row A: wave (solid), ray (dashed)", fontsize=9)
    ax.legend(fontsize=8)
    ax = axes[1]
    z = np.asarray(c.z_mm)
    for key, label, mark in (
        ("rmtf", f"RMTF, {c.dof_dpi:g}-dpi chart", "o"),
        ("center_cell_fraction", "share in the central cell", "s"),
    ):
        ax.plot(z, c.wave[key], marker=mark, color="C0", label=f"{label}, wave")
        ax.plot(z, c.ray[key], marker=mark, color="C1", ls="--", label=f"{label}, ray")
    ax.axhline(0.3, color="k", lw=0.6, ls=":")
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("Z above the reference plane (mm)")
    ax.set_ylabel("RMTF, share")
    tw = ax.twinx()
    tw.plot(z, c.wave["fwhm_x_um"], color="C2", marker="^", label="FWHM x, wave")
    tw.plot(z, c.ray["fwhm_x_um"], color="C2", marker="^", ls="--", label="FWHM x, ray")
    tw.set_ylabel("FWHM of the x LSF (µm)")
    tw.set_ylim(0, None)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = tw.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper right")
    d = c.difference
    fig.suptitle(
        f"{c.design}: ray vs wave at {c.sampling['wavelength_um']:g} µm — light in the band "
        f"wave/ray {d['light']:+.1%}; Fresnel numbers "
        f"{min(f['fresnel_number'] for f in c.fresnel):.2f}–"
        f"{max(f['fresnel_number'] for f in c.fresnel):.2f}",
        fontsize=9,
    )
    return fig


#: the traced LSF's bins merged for display (its 1-um bins are noisy at the report's rays)
RAY_DISPLAY_BINS = 4


def lsf_heights(z_mm, n: int = 3) -> list[int]:
    """Indices of ``n`` heights spread over ``z_mm`` (first, last and between) for the
    line-spread panel."""
    idx = np.unique(np.round(np.linspace(0, len(z_mm) - 1, min(n, len(z_mm)))).astype(int))
    return [int(i) for i in idx]


def plot_wave_report(c, verdict: dict):
    """The report's ray-vs-wave figure: left, the RMTF on the depth-of-field chart
    against Z by both engines (wave solid, ray dashed, the tolerance band around the ray
    curve shaded, each depth of field marked); right, row A's x line-spread function at
    a few heights by both engines. ``c``: a
    :class:`~opticalstamp.analysis.wavecompare.WaveRayComparison`; ``verdict``:
    :func:`~opticalstamp.analysis.raywave.judge`'s."""
    fig, (ax, bx) = subplots(1, 2, figsize=(REPORT_WIDTH_IN, 3.8), layout="constrained")
    z = np.asarray(c.z_mm)
    rw, rr = np.asarray(c.wave["rmtf"]), np.asarray(c.ray["rmtf"])
    tol = verdict["tolerances"]["rmtf"]
    ax.fill_between(z, rr - tol, rr + tol, color="C1", alpha=0.15, lw=0,
                    label=f"ray ± {tol:g} (tolerance)")  # fmt: skip
    ax.plot(z, rw, "o-", color="C0", ms=3, label="wave")
    ax.plot(z, rr, "s--", color="C1", ms=3, label="ray (same band)")
    thr = verdict["dof_threshold"]
    ax.axhline(thr, color="k", lw=0.6, ls=":")
    for eng, col, ls in (("wave", "C0", "-"), ("ray", "C1", "--")):
        v = verdict["dof_mm"][eng]
        ax.axvline(v, color=col, lw=0.8, ls=ls)
        ax.annotate(
            f"DOF {eng} {'≥ ' if verdict['dof_open_ended'][eng] else ''}{v:.2f} mm",
            (v, thr), xytext=(3, 6) if eng == "wave" else (-3, -12),
            textcoords="offset points", fontsize=7, color=col,
            ha="left" if eng == "wave" else "right",
        )  # fmt: skip
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("Z above the reference plane (mm)")
    ax.set_ylabel(f"RMTF, {c.dof_dpi:g}-dpi chart")
    ax.set_title("RMTF of the own path and near crosstalk", fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    p = c.profiles
    idx = lsf_heights(c.z_mm)
    k = RAY_DISPLAY_BINS
    n = len(p["ray_x_um"]) // k * k  # the traced LSF on k-times coarser bins (less noise)
    ray_x = np.asarray(p["ray_x_um"][:n]).reshape(-1, k).mean(axis=1)
    for j, i in enumerate(idx):
        col = f"C{j + 2}"
        bx.plot(p["wave_x_um"], p["wave_lsf"][i], color=col, lw=1.2, label=f"Z = {z[i]:g} mm")
        ray = np.asarray(p["ray_lsf"][i][:n]).reshape(-1, k).mean(axis=1)
        bx.plot(ray_x, ray, color=col, lw=0.9, ls="--")
    half = 1.3 * max(max(c.wave["fwhm_x_um"][i], c.ray["fwhm_x_um"][i]) for i in idx)
    bx.set_xlim(-half, half)
    bx.set_ylim(0, None)
    bx.set_xlabel("X on the object plane (µm)")
    bx.set_ylabel("line-spread function (µm·sr per µm)")
    width = k * float(p["ray_x_um"][1] - p["ray_x_um"][0])
    bx.set_title(f"row A's x LSF: wave (solid), ray (dashed, {width:g}-µm bins)", fontsize=9)
    bx.legend(fontsize=7)
    holds = "ray optics holds" if verdict["holds"] == "ray" else "diffraction dominates"
    light = verdict["light_difference"]
    lams = (c.meta.get("spectrum") or {}).get("wavelengths_um") or []
    light_name = (
        f"under {c.meta['spectrum'].get('name', '')} light ({len(lams)} wavelengths)"
        if len(lams) > 1
        else f"at {c.sampling['wavelength_um']:g} µm"
    )
    fig.suptitle(
        f"{c.design} {light_name}: {holds} (light wave/ray "
        + ("n/a" if light is None else f"{light * 100:+.1f} %")
        + f"; Fresnel numbers from {verdict['fresnel_min']:.2f})",
        fontsize=9,
    )
    return fig
