"""The stack drawn to scale: sections through both rows of used pixels."""

from __future__ import annotations

import numpy as np

from ...design import Design
from ...design.describe import stack_rows
from .axes import subplots

#: Half width of the drawn window, in hole pitches.
WINDOW_PITCHES = 3.5


def plot_stack(design: Design):
    """Cross-sections x-z through row A (y = 0) and row B (y = b_y), to scale: plates,
    masks with their holes (designed offsets applied), the sensor's used pixels, the
    reference plane (Z = 0, where the object distance is measured from)."""
    from matplotlib.patches import Rectangle

    s = design.sensor
    rows = [("row A", 0.0, 0.0)]
    if s.rows == 2:
        rows.append(("row B", s.row_b_offset_x_um, s.row_b_offset_y_um))
    half = WINDOW_PITCHES * s.row_pitch_um
    top = design.reference_plane_um
    fig, axes = subplots(
        1,
        len(rows),
        figsize=(4.2 * len(rows), 0.6 + 3.3 * top / (2 * half)),
        squeeze=False,
        layout="constrained",
    )
    k = np.arange(-int(WINDOW_PITCHES) - 1, int(WINDOW_PITCHES) + 2)
    table = stack_rows(design)
    for ax, (name, bx, by) in zip(axes[0], rows, strict=True):
        for r in table:
            glass = r["index"] > 1.0001
            ax.add_patch(
                Rectangle(
                    (-half, r["z_bottom_um"]),
                    2 * half,
                    r["thickness_um"],
                    facecolor="#cfe8f7" if glass else "white",
                    edgecolor="0.6",
                    lw=0.5,
                )
            )
            m = r["mask"]
            if m is None:
                continue
            z = r["z_top_um"]
            cut = abs(by + m["offset_y_um"] - by) <= m["height_um"] / 2  # the section's holes
            centres = bx + m["offset_x_um"] + k * s.row_pitch_um
            edges = [-half]
            if cut:
                for c in centres:
                    edges += [c - m["width_um"] / 2, c + m["width_um"] / 2]
            edges.append(half)
            for a, b in zip(edges[::2], edges[1::2], strict=True):
                if b > a:
                    ax.plot([max(a, -half), min(b, half)], [z, z], "k-", lw=2.5)
            ax.text(
                half * 1.02, z, f"layer {r['layer']}: {m['width_um']:g} µm", fontsize=7, va="center"
            )
        for c in bx + k * s.row_pitch_um:  # the used pixels' sensitive areas
            ax.plot(
                [c - s.sensitive_width_um / 2, c + s.sensitive_width_um / 2],
                [0, 0],
                color="C2",
                lw=5,
            )
        ax.axhline(top, color="C3", ls="--", lw=0.8)
        ax.text(-half, top, " reference plane Z = 0 (document above)", fontsize=7, va="bottom")
        ax.set_xlim(-half, half)
        ax.set_ylim(-0.03 * top, top * 1.08)
        ax.set_aspect("equal")
        ax.set_xlabel("x along the sensor line (µm)")
        ax.set_title(f"section through {name} (y = {by:g} µm)", fontsize=9)
    axes[0][0].set_ylabel("z from the sensor (µm)")
    fig.suptitle(f"{design.name}: the stack to scale (green: used pixels)", fontsize=10)
    return fig
