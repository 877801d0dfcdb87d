"""Figures (matplotlib imported lazily, object-oriented: no pyplot, no backend switch).
Each returns a :class:`matplotlib.figure.Figure`."""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from ...analysis.efficiency import ratio_text
from ...analysis.ghosts import GhostResult
from ...analysis.spots import PSF, SpotResult
from .axes import REPORT_WIDTH_IN, subplots
from .rodlens import plot_compare_contrast, plot_compare_light, plot_rod_details, plot_rod_ripple
from .studies import plot_pareto, plot_pareto_variants, plot_study, plot_tolerance

__all__ = [
    "REPORT_WIDTH_IN",
    "plot_chart_profiles",
    "plot_compare_contrast",
    "plot_compare_light",
    "plot_diffraction",
    "plot_efficiency",
    "plot_ghosts",
    "plot_pareto",
    "plot_pareto_variants",
    "plot_psf",
    "plot_restoration",
    "plot_rmtf",
    "plot_rod_details",
    "plot_rod_ripple",
    "plot_scan_panels",
    "plot_scan_profiles",
    "plot_sfr",
    "plot_spots",
    "plot_study",
    "plot_tolerance",
]


def plot_spots(res: SpotResult):
    """Responsivity maps on the output pixel grid (84.6 µm for the paper's prototype), one
    panel per Z (paper Fig. 5)."""
    cell = res.meta["cell_um"]
    n = len(res.spots)
    fig, axes = subplots(1, n, figsize=(2.6 * n, 3.0), squeeze=False)
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
        grid = np.arange(-np.ceil(half / cell) - 0.5, np.ceil(half / cell) + 1) * cell
        for g in grid:
            ax.axvline(g, color="tab:red", lw=0.4, alpha=0.7)
            ax.axhline(g, color="tab:red", lw=0.4, alpha=0.7)
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_title(
            f"Z = {s.z_mm:g} mm\nFWHM {s.fwhm_x_um:.0f} µm, edge {s.extent_x_um:.0f} µm", fontsize=8
        )
        ax.set_xlabel("x (µm)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0][0].set_ylabel("y (µm)", fontsize=8)
    fig.suptitle(
        f"{res.design}: spots of pixel {res.pixel['row']}{res.pixel['k']} on the "
        f"object plane (grid {cell:.1f} µm)",
        fontsize=9,
    )
    return fig


def plot_psf(p: PSF):
    """Landing density on the sensor, 600-dpi grid, used pixels outlined (paper Fig. 10).

    The frame is where the light lands (the nonzero part of the landing map, one pixel
    pitch around it, and the own pixel), not a fixed window: the prototype's ghost light
    lands about 100 µm off the axis, beyond the sensor's lines. The colour bar gives the
    density in fraction of the point's emitted power per µm² (log scale, four decades).
    """
    from matplotlib import colormaps
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    ex, ey = p.fine_edges_x_um, p.fine_edges_y_um
    pitch = p.grid_pitch_um
    sw, sh = p.sensitive_um
    ox, oy = p.own_pixel_id["x_um"], p.own_pixel_id["y_um"]
    lit_y, lit_x = np.nonzero(p.fine_map > 0)
    if lit_x.size:
        x0, x1 = ex[lit_x.min()] - pitch, ex[lit_x.max() + 1] + pitch
        y0, y1 = ey[lit_y.min()] - pitch, ey[lit_y.max() + 1] + pitch
    else:
        x0, x1, y0, y1 = p.x_obj_um - pitch, p.x_obj_um + pitch, oy - pitch, oy + pitch
    x0, x1 = max(min(x0, ox - sw), ex[0]), min(max(x1, ox + sw), ex[-1])
    y0, y1 = max(min(y0, oy - sh), ey[0]), min(max(y1, oy + sh), ey[-1])
    width, plot_w = 7.5, 5.6  # inches: the figure, and the frame (the rest: bar, labels)
    fig, ax = subplots(
        figsize=(width, min(max(plot_w * (y1 - y0) / (x1 - x0), 1.6), 6.0) + 1.1),
        layout="constrained",
    )
    vmax = p.fine_map.max()
    im = ax.imshow(
        np.ma.masked_less_equal(p.fine_map, 0.0),
        extent=(ex[0], ex[-1], ey[0], ey[-1]),
        origin="lower",
        cmap=colormaps["magma"].with_extremes(bad="black", under="black"),
        norm=LogNorm(vmin=vmax * 1e-4, vmax=vmax) if vmax > 0 else None,
        aspect="equal",
        interpolation="nearest",
    )
    ax.set_facecolor("black")
    bar = fig.colorbar(im, ax=ax, shrink=0.9, pad=0.02, extend="min")
    bar.set_label("landing power density\n(fraction of emitted power per µm²)", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    for g in np.arange(np.floor(x0 / pitch) - 0.5, np.ceil(x1 / pitch) + 1) * pitch:
        ax.axvline(g, color="0.6", lw=0.4)
    for g in np.arange(-0.5, p.grid_power.shape[0] + 0.5) * pitch:  # the sensor's lines
        ax.axhline(g, color="0.6", lw=0.4)
    for cx, cy in p.used_pixels:
        own = abs(cx - ox) < 1e-6 and abs(cy - oy) < 1e-6
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
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_xlabel("x on sensor (µm)")
    ax.set_ylabel("y (µm)")
    out = p.meta.get("outside_map", 0.0)
    half = min(p.x_obj_um - ex[0], ex[-1] - p.x_obj_um, p.y_obj_um - ey[0], ey[-1] - p.y_obj_um)
    ax.set_title(
        f"{p.design}: PSF of a point at X = {p.x_obj_um:g} µm, Z = {p.z_mm:g} mm\n"
        f"own {p.own_pixel:.1%}, blur {p.neighbour_own_path:.1%}, "
        f"ghost {p.neighbour_ghost:.1%}, insensitive {p.insensitive:.1%}"
        + (f"; {out:.1%} lands beyond this map (> {half:g} µm away)" if out > 5e-4 else ""),
        fontsize=8,
    )
    return fig


def plot_ghosts(res: GhostResult, top: int = 12):
    """Etendue of the strongest ghost paths and where ghost light lands (per Z)."""
    fig, (a1, a2) = subplots(1, 2, figsize=(11, 3.4))
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
    a1.set_xlabel("etendue (µm² sr)")
    names = " / ".join(h["mask"] for h in paths[0].holes) if paths else ""
    found = (
        f"ghost {res.etendue_ghost_um2sr:.3g} µm² sr, fraction {res.ghost_fraction:.3g}"
        if res.ghost_ratio_bound is None
        else f"no ghost light found: ghost/own < {res.ghost_ratio_bound:.2g} (95 % bound)"
    )
    own = f"own {res.etendue_own_um2sr:.3f} µm² sr"
    dark = res.own_etendue_bound is not None and res.etendue_ghost_um2sr == 0
    if res.own_etendue_bound is not None:
        own = f"no own-path light found: own < {res.own_etendue_bound:.2g} µm² sr (95 % bound)"
    if dark:  # no light at all: one statement, not a row of zeros
        own, found = own.replace("own-path light", "light") + " and the same bound on ghost", ""
    a1.set_title(
        f"ghost paths: hole offset per mask ({names}; o = other row)\n" * bool(paths)
        + ", ".join(t for t in (own, found) if t),
        fontsize=8,
    )
    if res.ghost_ratio_bound is not None or dark:
        for ax in (a1, a2):
            ax.set_xticks([])
            ax.set_yticks([])
            ax.text(0.5, 0.5, "no light found" if dark else "no ghost light found",
                    ha="center", va="center", transform=ax.transAxes, fontsize=9,
                    color="0.4")  # fmt: skip
    for i, (z, land) in enumerate(res.landing.items()):
        h = np.asarray(land["etendue_by_distance_um2sr"])  # the last bin: all farther light
        total = h.sum()
        if total <= 0:
            continue
        edges = (np.arange(h.size) + 1.0) * land["bin_um"] / 1000  # upper edges (mm)
        share = np.cumsum(h[:-1]) / total
        far = h[-1] / total
        a2.step(np.r_[0.0, edges[:-1]], np.r_[0.0, share], where="post", color=f"C{i}",
                label=f"Z = {z} mm: {far:.0%} beyond {edges[-2]:.1f} mm")  # fmt: skip
        if far > 0:
            a2.plot([edges[-2]], [share[-1]], ">", color=f"C{i}", ms=5)
    a2.set_ylim(0, 1.02)
    a2.set_xlabel("distance from the pixel's axis on the object plane (mm)")
    a2.set_ylabel("share of the ghost light landing within")
    a2.set_title("where ghost light lands (cumulative; arrow: the rest lies farther)", fontsize=8)
    if a2.get_legend_handles_labels()[0]:
        a2.legend(fontsize=7)
    fig.suptitle(
        f"{res.design}: ghost analysis of pixel {res.pixel['row']}{res.pixel['k']}", fontsize=9
    )
    fig.tight_layout()
    return fig


def plot_rmtf(res, paper_points: dict | None = None):
    """RMTF versus object distance, one line per chart dpi (paper Fig. 11).

    Solid: maximum over chart shifts (the paper's RMTF), through the grid's samples and
    the finer ones taken where the curve crosses, nears the threshold or jumps (dots);
    band: minimum to maximum on the grid. ``paper_points`` ({dpi: [(z, rmtf), ...]}) are
    drawn as circles when given.
    """
    from ...analysis.rmtf import merged_samples

    head = res.meta.get("headline", {}).get("channel") if res.meta.get("channels") else None
    fig, ax = (
        subplots(figsize=(6.4, 5.4), layout="constrained") if head else subplots(figsize=(6.4, 4.2))
    )
    z = np.asarray(res.z_mm)
    fine = set(res.meta.get("refined", {}).get("z_mm", []))
    # a colour scanner's channels are drawn red, green and blue: the charts in others
    colours = ["C1", "C4", "C5", "C7", "C8", "C9"] if head else [f"C{i}" for i in range(10)]
    for i, (key, vals) in enumerate(res.rmtf_max.items()):
        c = colours[i % len(colours)]
        zm, rm, _ = merged_samples(res, key)
        ax.plot(zm, rm, "-", color=c, lw=1.2, label=f"{key} dpi ({res.periods_um[i]:.0f} µm)")
        extra = np.isin(zm, list(fine))
        ax.plot(zm[extra], rm[extra], ".", color=c, ms=2.5)
        ax.fill_between(z, res.rmtf_min[key], vals, color=c, alpha=0.12, lw=0)
        if paper_points and key in paper_points:
            pz, pv = zip(*paper_points[key], strict=True)
            ax.plot(pz, pv, "o", color=c)
    _channel_curves(ax, res)
    ax.axhline(res.dof_threshold, color="k", lw=0.6, ls=":")
    dof = res.dof_mm.get(f"{res.dof_dpi:g}")
    if dof is not None:
        ax.axvline(dof, color="k", lw=0.6, ls="--")
        ax.text(dof, 0.95, f" DOF {res.dof_text(f'{res.dof_dpi:g}')}", fontsize=8, va="top")
    ax.set_xlabel("object distance Z (mm)")
    ax.set_ylabel("RMTF")
    ax.set_ylim(0, 1.02)
    ax.set_xlim(z[0], z[-1])
    what = "own + ghost light" if res.ghosts else "own path only"
    title = (
        f"{res.design}: RMTF vs Z ({res.method}, {what}; band = min..max over chart shifts;"
        f"\ndots: finer samples; DOF on the {res.dof_dpi:g}-dpi chart)"
    )
    if head:  # the legend below the axes, clear of the curves
        ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2)
        title += (
            f"\nsolid: the {head} channel's charts (the headline: the worst); dashed: each channel"
        )
    else:
        ax.legend(fontsize=8, loc="lower left")
    ax.set_title(title, fontsize=9)
    return fig


#: the lines of a colour scanner's channels
CHANNEL_COLOURS = MappingProxyType({"red": "#d62728", "green": "#2ca02c", "blue": "#1f77b4"})


def _channel_curves(ax, res) -> None:
    """A colour scanner's channels (``meta["channels"]``): each channel's RMTF on the
    depth-of-field chart against Z (grid and refined samples), dashed in its colour,
    with its depth of field in the legend; nothing for one light."""
    from types import SimpleNamespace

    from ...analysis.rmtf import merged_samples

    chans = res.meta.get("channels")
    if not chans:
        return
    key = f"{res.dof_dpi:g}"
    head = res.meta["headline"]["channel"]
    for name, c in chans.items():
        one = SimpleNamespace(
            z_mm=res.z_mm,
            rmtf_max=c["rmtf_max"],
            rmtf_max_se=c["rmtf_max_se"],
            meta={"refined": c.get("refined") or {}},
        )
        zm, rm, _ = merged_samples(one, key)
        mark = ", the headline" if name == head else ""
        dof = f"{'≥ ' if c['dof_open_ended'].get(key) else ''}{c['dof_mm'][key]:.2f} mm"
        ax.plot(
            zm,
            rm,
            "--",
            color=CHANNEL_COLOURS.get(name, "0.4"),
            lw=1.0,
            label=f"{name} channel, {key} dpi: DOF {dof}{mark}",
        )


def plot_efficiency(res):
    """Collected etendue vs Z for finite uniform objects, and the sensitive-area effect.

    The title gives the headline figures: the own-path light (the signal) against the
    paper's F/10 reference lens and its working F-number (``ratio_own``,
    ``working_f_number_own``), then those with the ghost light. The etendue axis starts
    at 0, so that the few per cent between the curves look as small as they are.
    """
    fig, (a1, a2) = subplots(1, 2, figsize=(9.6, 3.8), layout="constrained")
    zs = sorted(res.by_object_radius, key=float)
    radii = list(res.by_object_radius[zs[0]])
    top = 0.0
    for i, r in enumerate(radii):
        vals = [res.by_object_radius[z][r] for z in zs]
        top = max(top, *vals)
        lab = "infinite object" if r == "inf" else f"object radius {r} mm"
        a1.plot([float(z) for z in zs], vals, "o-", color=f"C{i}", label=lab, ms=4)
    # the object-radius curves are ray optics (the ghost landings): under wave optics
    # the line beside them is the rays' own path too, and the axis says so
    optics = res.meta.get("optics") or {}
    wave = optics.get("engine") == "wave"
    own = optics["ray_etendue_own_um2sr"] if wave else res.etendue_own_um2sr
    a1.axhline(own, color="k", lw=0.6, ls=":", label="own path")
    a1.set_ylim(0, 1.15 * max(top, own) or 1.0)  # no light: an axis still
    a1.set_xlabel("object distance Z (mm)" + ("; curves by ray optics" if wave else ""))
    a1.set_ylabel("etendue collected (µm² sr)")
    a1.set_title(
        f"own-path light {ratio_text(res.ratio_own)} of the F/{res.reference_f_number:g} "
        f"lens, working F {res.working_f_number_own:.1f}\n"
        f"with the ghost light {ratio_text(res.ratio)}, F {res.working_f_number:.1f}",
        fontsize=9,
    )
    a1.legend(fontsize=8, loc="lower right")
    areas = res.sensitive_area
    x = np.arange(len(areas))
    a2.bar(x - 0.2, [a["gain_own_vs_design"] for a in areas], 0.4, label="own path")
    a2.bar(x + 0.2, [a["gain_vs_design"] for a in areas], 0.4, label="own + ghost")
    a2.hlines([a["area_scale"] for a in areas], x - 0.4, x + 0.4, color="k", label="area ratio")
    a2.set_ylim(0, 1.15 * max(max(a["area_scale"], a["gain_vs_design"]) for a in areas))
    a2.set_xticks(x, [f"{a['sensitive_um'][0]:.1f} µm" for a in areas])
    a2.set_xlabel("side of the sensitive area")
    a2.set_ylabel("light relative to the design")
    a2.set_title("sensitive-area size (paper: 4× area → 4× light)", fontsize=9)
    a2.legend(fontsize=8, loc="center left")
    fig.suptitle(f"{res.design}: light efficiency (paper Fig. 13)", fontsize=10)
    return fig


def plot_diffraction(res):
    """Slit diffraction at the next layer, per wavelength (paper Fig. 6b)."""
    fig, ax = subplots(figsize=(6.4, 3.8))
    for i, (k, v) in enumerate(res.intensity.items()):
        ax.plot(res.x_um, v, color=f"C{i}", label=f"{k} µm: {res.fraction_outside[k]:.1%} outside")
    for s in (-1, 1):
        ax.axvline(s * res.geometric_edge_um, color="k", lw=0.7, ls="--")
    ax.set_xlabel("X at the next layer (µm)")
    ax.set_ylabel("I / I0")
    ax.set_title(
        f"slit {res.slit_um:g} µm, Z = {res.z_mm:g} mm (R1 {res.r1_um:.0f} µm, "
        f"R2 {res.r2_um:.0f} µm); geometric edge {res.geometric_edge_um:.1f} µm",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    return fig


def _mtf50_text(res: dict, unit: str = " cy/mm") -> str:
    """The MTF50 in a label: "MTF50 4.54 cy/mm", or "MTF50 not reached" where the SFR
    stays above 0.5 up to the sampling frequency."""
    f = res["mtf50_cy_per_mm"]
    return f"MTF50 {f:.2f}{unit}" if np.isfinite(f) else "MTF50 not reached"


def plot_sfr(res: dict, title: str = "", extra: dict | None = None):
    """SFR curve of a slanted edge with MTF50 and the 100/200-dpi values (``extra``: a
    second curve, e.g. along y)."""
    fig, ax = subplots(figsize=(6, 3.6))
    ax.plot(res["freq_cy_per_mm"], res["sfr"], "-", label=f"along {res['direction']}")
    if extra is not None:
        ax.plot(
            extra["freq_cy_per_mm"],
            extra["sfr"],
            "-",
            label=f"along {extra['direction']}: {_mtf50_text(extra, unit='')}",
        )
    ax.axhline(0.5, color="k", lw=0.5, ls=":")
    for k, v in res["sfr_at_dpi"].items():
        ax.plot(float(k) / 50.8, v, "o", label=f"{k} dpi: {v:.3f}")
    ax.axvline(res["nyquist_cy_per_mm"], color="k", lw=0.5, ls="--")
    ax.set_xlim(0, 2 * res["nyquist_cy_per_mm"])
    ax.set_ylim(0, 1.1)
    ax.set_xlabel("spatial frequency (cycles/mm)")
    ax.set_ylabel("SFR")
    ax.set_title(
        f"{title} slanted-edge SFR along {res['direction']}: {_mtf50_text(res)}",
        fontsize=9,
    )
    ax.legend(fontsize=8)
    return fig


def plot_chart_profiles(profiles: list[dict]):
    """Merged-line signals across a bar chart at two distances (paper Fig. 12 c, d)."""
    fig, axes = subplots(1, len(profiles), figsize=(5 * len(profiles), 3), squeeze=False)
    for ax, p in zip(axes[0], profiles, strict=True):
        x = np.asarray(p["x_um"]) / 1000
        ax.step(x, p["signal"], where="mid")
        ax.set_ylim(0, 1.05)
        ax.set_xlim(0, min(x[-1], 2.0))
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("pixel signal (max = 1)")
        ax.set_title(
            f"{p['dpi']:g} dpi chart, Z = {p['z_mm']:g} mm: RMTF {p['rmtf_computed']:.2f}",
            fontsize=9,
        )
    return fig


def plot_scan_panels(
    panels: list[tuple[str, np.ndarray]], title: str, cols: int = 1, interpolation="nearest"
):
    """Simulated scans side by side or stacked (paper Figs. 8, 9, 12 a-b), display-encoded.

    ``interpolation``: "nearest" shows the pixels; "antialiased" for panels drawn smaller
    than their pixel count (nearest would drop pixels)."""
    from ...io.files import linear_to_srgb

    rows = int(np.ceil(len(panels) / cols))
    h, w = panels[0][1].shape[:2]
    fig, axes = subplots(
        rows,
        cols,
        figsize=(min(12, 3 + 9 * w / max(w, h)), 0.6 + rows * max(1.2, 9 * h / w / cols)),
        squeeze=False,
    )
    for ax, (name, img) in zip(axes.ravel(), panels, strict=False):
        ax.imshow(linear_to_srgb(img), cmap="gray", vmin=0, vmax=1, interpolation=interpolation)
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    for ax in axes.ravel()[len(panels) :]:
        ax.axis("off")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_restoration(res: dict):
    """Restoration against height: the fundamental's amplitude (of the band-limited
    ideal's) raw and per method with the restored-DOF threshold, contrast to noise with its
    floor, and the own path's transfer at the chart's frequency (the ceiling)."""
    z = np.asarray(res["z_mm"])
    fig, axes = subplots(1, 3, figsize=(13, 3.6))
    for name, s in res["series"].items():
        dof = res["dof"][name]
        label = f"{name}: DOF {'>= ' if dof['open_ended'] else ''}{dof['dof_mm']:.2f} mm"
        style = "k-o" if name == "raw" else "-o"
        axes[0].plot(z, s["amplitude_rel"], style, ms=3, label=label)
        axes[1].semilogy(z, np.maximum(s["cnr"], 1e-2), style, ms=3, label=name)
    axes[0].axhline(res["threshold"], color="grey", ls="--", lw=1)
    axes[0].set_ylabel(f"{res['dpi']:g}-dpi amplitude / ideal")
    axes[0].legend(fontsize=7)
    axes[1].axhline(res["cnr_floor"], color="grey", ls="--", lw=1)
    axes[1].set_ylabel("contrast to noise")
    axes[2].plot(res["transfer_z_mm"], res["transfer_fine"], "k-", lw=1.2)
    axes[2].plot(z, res["transfer"], "ko", ms=3)
    axes[2].axhline(0, color="grey", lw=0.8)
    zero = res.get("transfer_zero_mm")
    axes[2].set_title(
        f"own transfer at {res['dpi']:g} dpi"
        + (f": zero at {zero:.2f} mm" if zero is not None else ": no zero in range"),
        fontsize=9,
    )
    for ax in axes:
        ax.set_xlabel("Z (mm)")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def plot_scan_profiles(profiles: list[dict]):
    """Profiles across the simulated 200-dpi chart scans (paper Fig. 12 c, d)."""
    fig, axes = subplots(1, len(profiles), figsize=(5 * len(profiles), 3), squeeze=False)
    for ax, p in zip(axes[0], profiles, strict=True):
        x = np.asarray(p["x_mm"])
        ax.plot(x, p["profile"], "-", lw=1)
        ax.set_ylim(0, 1.1)
        ax.set_xlabel("x (mm)")
        ax.set_ylabel("output (white = 1)")
        ax.set_title(
            f"Z = {p['z_mm']:g} mm: RMTF measured {p['rmtf_measured']:.2f}, computed "
            f"{p['rmtf_computed_min']:.2f}-{p['rmtf_computed_max']:.2f}",
            fontsize=9,
        )
    return fig
