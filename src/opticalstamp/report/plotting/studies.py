"""Figures of the studies: the paper's unstated parameters, the design search's Pareto
front, the tolerance study."""

from __future__ import annotations

from .axes import REPORT_WIDTH_IN, subplots


def plot_study(res):
    """Parameter study: working F-number against depth of field, per combination."""
    fig, ax = subplots(figsize=(7.5, 4.6))
    marks = {"square": "s", "circle": "o"}
    for r in res.rows:
        col = "C0" if r["gap_medium"] == "air" else "C1"
        face = col if r["fresnel"] else "none"
        size = 60 if r["sensitive_um"] == max(x["sensitive_um"] for x in res.rows) else 25
        ax.scatter(
            r["dof_mm"],
            r["working_f_number"],
            marker=marks.get(r["hole_shape"], "^"),
            edgecolors=col,
            facecolors=face,
            s=size,
        )
    ax.axhline(res.paper["working_f_number"], color="k", lw=0.7, ls=":")
    ax.axvline(res.paper["dof_mm"], color="k", lw=0.7, ls="--")
    ax.text(res.paper["dof_mm"], ax.get_ylim()[1], " paper: DOF 3.5 mm, F 60", fontsize=8, va="top")
    ax.set_xlabel("depth of field at 200 dpi, RMTF >= 0.3 (mm)")
    ax.set_ylabel("equivalent working F-number")
    ax.set_title(
        "square/circle: hole shape; blue: air gap, orange: light guide n=1.49; "
        "filled: Fresnel losses; large: bigger sensitive area",
        fontsize=8,
    )
    return fig


def plot_pareto(res, title: str = ""):
    """Search: every feasible design, the Pareto front, and the base design."""
    fig, ax = subplots(figsize=(7, 4.5))
    key = res.meta.get("objective", "dof_mm")  # the search's depth objective
    feas = [r for r in res.records if r["feasible"]]
    bad = [r for r in res.records if r["ok"] and not r["feasible"]]
    if bad:
        ax.scatter(
            [r[key] for r in bad],
            [r["efficiency_ratio"] for r in bad],
            s=6,
            c="0.8",
            label="infeasible (near ghosts, budget, diffraction)",
        )
    if feas:
        ax.scatter(
            [r[key] for r in feas],
            [r["efficiency_ratio"] for r in feas],
            s=10,
            c="C0",
            alpha=0.6,
            label="feasible",
        )
    if res.pareto:
        # the front as the surrogate ranked it; where it was re-verified, each point's exact
        # figures too, joined to it (the exact ones are the figures of record)
        sur = [r.get("surrogate") or r for r in res.pareto]
        order = sorted(range(len(sur)), key=lambda i: sur[i][key])
        ax.plot(
            [sur[i][key] for i in order],
            [sur[i]["efficiency_ratio"] for i in order],
            "o-",
            c="C3",
            ms=4,
            label="Pareto front (surrogate)",
        )
        ex = [(s, r) for s, r in zip(sur, res.pareto, strict=True) if r.get("exact")]
        if ex:
            for s, r in ex:
                ax.plot([s[key], r[key]], [s["efficiency_ratio"], r["efficiency_ratio"]],
                        c="C3", lw=0.6, ls=":")  # fmt: skip
            ax.plot(
                [r[key] for _, r in ex],
                [r["efficiency_ratio"] for _, r in ex],
                "D",
                mfc="none",
                c="C3",
                ms=6,
                ls="none",
                label="the same points, exact tracer",
            )
    if res.reference:
        ax.plot(
            res.reference[key],
            res.reference["efficiency_ratio"],
            "*",
            c="k",
            ms=14,
            label=f"base design ({res.base})",
        )
    what = "restored depth of field" if key == "restored_dof_mm" else "depth of field"
    ax.set_xlabel(f"{what} at {res.meta['dof_dpi']:g} dpi (mm)")
    ax.set_ylabel("light efficiency, own path (ratio to F10 lens)")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    ax.set_title(
        title or f"design search for {res.dpi:g} dpi ({len(res.records)} designs)", fontsize=9
    )
    return fig


def plot_tolerance(res):
    """Tolerance study: histograms of RMTF, DOF and ghost fraction; sensitivity bars.

    Two by two, :data:`REPORT_WIDTH_IN` wide, every text at least 8 pt: the report shows
    it at its natural size, where 8 pt reads as about 9 pt.
    """
    ok = [s for s in res.samples if s is not None]
    fig, axes = subplots(2, 2, figsize=(REPORT_WIDTH_IN, 6.6), layout="constrained")
    axes = axes.ravel()
    z_show = [z for z in res.z_mm if z in (1.0, 2.0, 3.0)] or res.z_mm[:3]
    for i, z in enumerate(z_show):
        v = [s["rmtf_at"][f"{z:g}"] for s in ok]
        axes[0].hist(v, bins=30, alpha=0.6, color=f"C{i}", label=f"Z = {z:g} mm")
        axes[0].axvline(res.nominal["rmtf_at"][f"{z:g}"], color=f"C{i}", ls="--")
    axes[0].set_xlabel(f"RMTF at {res.dpi:g} dpi (dashed: nominal)", fontsize=9)
    axes[0].legend(fontsize=8)
    for ax, k, lab in (
        (axes[1], "dof_mm", "depth of field (mm; dashed: nominal)"),
        (axes[2], "ghost_fraction", "ghost fraction (dashed: nominal)"),
    ):
        ax.hist([s[k] for s in ok], bins=30, color="C0")
        ax.axvline(res.nominal[k], color="k", ls="--")
        ax.set_xlabel(lab, fontsize=9)
    for ax in axes[:3]:
        ax.set_ylabel("samples", fontsize=9)
        ax.yaxis.get_major_locator().set_params(integer=True)
    rows = res.sensitivity[:10][::-1]
    axes[3].barh([r["error"] for r in rows], [r["d_dof_mm"] for r in rows], color="C3")
    axes[3].set_xlabel("mean |change in DOF| at ±1 σ (mm)", fontsize=9)
    axes[3].set_title("the ten errors the DOF is most sensitive to", fontsize=9)
    for ax in axes:
        ax.tick_params(labelsize=8)
    s = res.sigmas
    fig.suptitle(
        f"{res.design}: {len(res.samples)} samples; 1 σ: misregistration "
        f"{s['misregistration_um']:g} µm, holes {s['hole_um']:g} µm, thickness "
        f"{s['thickness_um']:g} µm, tilt {s['tilt_deg']:g}°"
        + (
            f"\nyield {res.yield_fraction:.1%} for {res.spec}"
            if res.yield_fraction is not None
            else ""
        ),
        fontsize=9,
    )
    return fig


def plot_pareto_variants(results: dict):
    """Pareto fronts of searches over structural variants (layers, stagger), one colour
    each, with the base design."""
    fig, ax = subplots(figsize=(7, 4.5))
    for i, (name, res) in enumerate(results.items()):
        f = sorted(res.pareto, key=lambda r: r["dof_mm"])
        if f:
            ax.plot(
                [r["dof_mm"] for r in f],
                [r["efficiency_ratio"] for r in f],
                "o-",
                c=f"C{i}",
                ms=4,
                label=name,
            )
        if res.reference:
            ax.plot(
                res.reference["dof_mm"], res.reference["efficiency_ratio"], "*", c=f"C{i}", ms=12
            )
    first = next(iter(results.values()))
    ax.set_xlabel(f"depth of field at {first.meta['dof_dpi']:g} dpi (mm)")
    ax.set_ylabel("light efficiency, own path (ratio to F10 lens)")
    ax.set_yscale("log")
    ax.legend(fontsize=7)
    ax.set_title("Pareto fronts by structure (stars: the base of each)", fontsize=9)
    return fig
