"""Figures that say what they show (issue 21): a PSF with its colour bar and all its
light in the frame, an efficiency figure that agrees with the headline and does not
exaggerate, points (not bars) on a log axis, a tolerance figure readable in the report."""

from __future__ import annotations

import io
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image

from opticalstamp.design import load_design
from opticalstamp.io.files import figure_png
from opticalstamp.report import plotting


def _texts(fig):
    from matplotlib.text import Text

    return [t for t in fig.findobj(Text) if t.get_text().strip() and t.get_visible()]


def test_psf_frame_holds_the_ghost_footprints_and_has_a_colour_bar():
    from opticalstamp.analysis.spots import psf

    p = psf(load_design("paper2016"), z_mm=1.0, n_rays=1 << 17, seed=1)
    lit_y, lit_x = np.nonzero(p.fine_map > 0)
    # the prototype's ghost light lands about 100-120 um off the axis, beyond the sensor's
    # three lines (the old map ended at 106.5 um and cut it off)
    assert p.fine_edges_y_um[lit_y.max() + 1] > 115.0
    assert 0.0 <= p.meta["outside_map"] < 1.0
    fig = plotting.plot_psf(p)
    ax, bar = fig.axes
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    assert x0 <= p.fine_edges_x_um[lit_x.min()] and p.fine_edges_x_um[lit_x.max() + 1] <= x1
    assert y0 <= p.fine_edges_y_um[lit_y.min()] and p.fine_edges_y_um[lit_y.max() + 1] <= y1
    assert x1 - x0 < 500.0  # the frame is where the light is, not the +-400 um window
    assert "µm²" in bar.get_ylabel()
    assert "um" not in " ".join(t.get_text() for t in _texts(fig)).replace("µm", "")


def test_efficiency_title_is_the_headline_and_the_axis_starts_at_zero():
    from opticalstamp.analysis.efficiency import efficiency

    r = efficiency(load_design("paper2016"), z_mm=(0.0, 2.0), area_scales=(1.0, 2.0))
    fig = plotting.plot_efficiency(r)
    a1 = fig.axes[0]
    title = a1.get_title()
    head = f"own-path light 1/{1 / r.ratio_own:.1f}"
    assert title.startswith(head) and f"working F {r.working_f_number_own:.1f}" in title
    assert a1.get_ylim()[0] == 0.0
    assert "µm² sr" in a1.get_ylabel()


def test_rod_lens_light_is_points_on_a_log_axis():
    rows = [
        {"name": "stamp", "light_vs_f10": 0.038, "working_f_number": 51.3, "thickness_mm": 2.85},
        {"name": "rod", "light_vs_f10": 3.7, "light_vs_f10_se": 0.02, "thickness_mm": 15.3},
    ]
    fig = plotting.plot_compare_light(rows)
    a1 = fig.axes[0]
    assert a1.get_xscale() == "log"
    assert not a1.patches  # no bars: a bar's length means nothing on a log axis
    xs = sorted(
        float(np.ravel(line.get_xdata())[0]) for line in a1.lines if line.get_marker() == "o"
    )
    assert xs == pytest.approx([0.038, 3.7])


def test_tolerance_figure_is_readable_in_the_report():
    rng = np.random.default_rng(0)
    zs = [0.0, 1.0, 2.0, 3.0]

    def sample():
        return {
            "rmtf_at": {f"{z:g}": float(0.85 - 0.2 * z + rng.normal(0, 0.03)) for z in zs},
            "dof_mm": float(2.4 + rng.normal(0, 0.1)),
            "ghost_fraction": float(0.12 + rng.normal(0, 0.01)),
        }

    errors = [f"{k}{i}" for k in ("dx", "dy", "hole") for i in (1, 2, 3)] + ["tilt"]
    res = SimpleNamespace(
        design="paper2016",
        samples=[sample() for _ in range(64)],
        z_mm=zs,
        nominal=sample(),
        dpi=200.0,
        sensitivity=[{"error": e, "d_dof_mm": 0.1 / (i + 1)} for i, e in enumerate(errors)],
        sigmas={"misregistration_um": 5.0, "hole_um": 2.0, "thickness_um": 10.0, "tilt_deg": 0.05},
        yield_fraction=0.83,
        spec="dof>=2.2",
    )
    fig = plotting.plot_tolerance(res)
    sizes = [t.get_fontsize() for t in _texts(fig)]
    assert min(sizes) >= 8.0
    # shown at its natural size: the report's column is 1,100 px less 2 x 16 px padding
    width, _ = Image.open(io.BytesIO(figure_png(fig))).size
    assert width <= 1068
