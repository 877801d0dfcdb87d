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
