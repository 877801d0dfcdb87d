"""Figures (matplotlib imported lazily, Agg backend). Each returns a Figure."""

from __future__ import annotations

import numpy as np

from .ghosts import GhostResult
from .response import CELL_UM, PSF, SpotResult


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_spots(res: SpotResult):
    """Responsivity maps on the 84.6 um grid, one panel per Z (paper Fig. 5)."""
    plt = _plt()
    n = len(res.spots)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n, 3.0), squeeze=False)
    half = max(s.x_edges_um[-1] for s in res.spots)
    for ax, s in zip(axes[0], res.spots, strict=True):
        e = s.x_edges_um
        ax.imshow(
            s.map_sr,
            extent=(e[0], e[-1], s.y_edges_um[0], s.y_edges_um[-1]),
            origin="lower",
            cmap="gray",
            interpolation="nearest",
        )
        ax.set_facecolor("black")
        grid = np.arange(-np.ceil(half / CELL_UM) - 0.5, np.ceil(half / CELL_UM) + 1) * CELL_UM
        for g in grid:
            ax.axvline(g, color="tab:red", lw=0.4, alpha=0.7)
            ax.axhline(g, color="tab:red", lw=0.4, alpha=0.7)
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_title(
            f"Z = {s.z_mm:g} mm\nFWHM {s.fwhm_x_um:.0f} um, edge {s.extent_x_um:.0f} um", fontsize=8
        )
        ax.set_xlabel("x (um)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0][0].set_ylabel("y (um)", fontsize=8)
    fig.suptitle(
        f"{res.design}: spots of pixel {res.pixel['row']}{res.pixel['k']} on the "
        f"object plane (grid {CELL_UM} um)",
        fontsize=9,
    )
    return fig


def plot_psf(p: PSF):
    """Landing density on the sensor, 600-dpi grid, used pixels outlined (paper Fig. 10)."""
    plt = _plt()
    from matplotlib.patches import Rectangle

    fig, ax = plt.subplots(figsize=(9, 2.6))
    ex, ey = p.fine_edges_x_um, p.fine_edges_y_um
    img = np.log10(p.fine_map + p.fine_map.max() * 1e-4) if p.fine_map.max() > 0 else p.fine_map
    ax.imshow(
        img,
        extent=(ex[0], ex[-1], ey[0], ey[-1]),
        origin="lower",
        cmap="magma",
        aspect="equal",
        interpolation="nearest",
    )
    pitch = p.grid_pitch_um
    for g in np.arange(np.floor(ex[0] / pitch) - 0.5, np.ceil(ex[-1] / pitch) + 1) * pitch:
        ax.axvline(g, color="0.6", lw=0.4)
    for g in np.arange(-0.5, p.grid_power.shape[0] + 0.5) * pitch:
        ax.axhline(g, color="0.6", lw=0.4)
    sw, sh = p.sensitive_um
    for cx, cy in p.used_pixels:
        own = abs(cx - p.own_pixel_id["x_um"]) < 1e-6 and abs(cy - p.own_pixel_id["y_um"]) < 1e-6
        ax.add_patch(
            Rectangle(
                (cx - sw / 2, cy - sh / 2),
                sw,
                sh,
                fill=False,
                ec="cyan" if own else "white",
                lw=1.4 if own else 0.9,
            )
        )
    ax.plot([p.x_obj_um], [p.y_obj_um], "+", color="lime", ms=8)
    ax.set_xlim(ex[0], ex[-1])
    ax.set_ylim(ey[0], ey[-1])
    ax.set_xlabel("x on sensor (um)")
    ax.set_ylabel("y (um)")
    ax.set_title(
        f"{p.design}: PSF of a point at X = {p.x_obj_um:g} um, Z = {p.z_mm:g} mm "
        f"(log density; own {p.own_pixel:.1%}, blur {p.neighbour_own_path:.1%}, "
        f"ghost {p.neighbour_ghost:.1%}, insensitive {p.insensitive:.1%})",
        fontsize=8,
    )
    return fig


def plot_ghosts(res: GhostResult, top: int = 12):
    """Etendue of the strongest ghost paths and where ghost light lands (per Z)."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.4))
    paths = res.paths[:top]
    labels = [
        " / ".join(f"{'o' if h['row'] == 'other' else ''}{h['dk']:+d}" for h in p.holes)
        for p in paths
    ]
    a1.barh(
        range(len(paths)),
        [p.etendue_um2sr for p in paths],
        xerr=[p.etendue_se for p in paths],
        color="tab:red",
    )
    a1.set_yticks(range(len(paths)), labels, fontsize=7)
    a1.invert_yaxis()
    a1.set_xlabel("etendue (um^2 sr)")
    names = " / ".join(h["mask"] for h in paths[0].holes) if paths else ""
    a1.set_title(
        f"ghost paths: hole offset per mask ({names}; o = other row)\n"
        f"own {res.etendue_own_um2sr:.3f}, ghost {res.etendue_ghost_um2sr:.3g} um^2 sr,"
        f" fraction {res.ghost_fraction:.3g}",
        fontsize=8,
    )
    for z, land in res.landing.items():
        h = np.asarray(land["etendue_by_distance_um2sr"])
        r = (np.arange(h.size) + 0.5) * land["bin_um"] / 1000
        a2.step(r, h, where="mid", label=f"Z = {z} mm")
    a2.set_yscale("symlog", linthresh=1e-6)
    a2.set_xlabel("distance of ghost light from the pixel's axis on the object plane (mm)")
    a2.set_ylabel("etendue per bin (um^2 sr)")
    a2.legend(fontsize=7)
    fig.suptitle(
        f"{res.design}: ghost analysis of pixel {res.pixel['row']}{res.pixel['k']}", fontsize=9
    )
    fig.tight_layout()
    return fig
