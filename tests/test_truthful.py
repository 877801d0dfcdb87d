"""Numbers and plots that do not mislead: a depth of field cut by the Z range is a bound."""

from __future__ import annotations

import json

from edges import run


def test_dof_that_reaches_the_last_z_is_a_lower_bound():
    res = run(["rmtf", "--method", "paraxial", "--z", "0:1:0.25", "--json"])
    d = json.loads(res.stdout)
    assert all(d["dof_open_ended"].values())  # every chart stays above 0.3 up to 1 mm
    assert d["dof_mm"]["200"] == 1.0
    res = run(["rmtf", "--method", "paraxial", "--z", "0:1:0.25"])
    # the figure named with its rule: the chart at 2/3 of the design's resolution
    assert "200-dpi chart (2/3 of the design's 300 dpi)" in res.output
    assert "): ≥ 1.00 mm" in res.output
    res = run(["rmtf", "--method", "paraxial", "--z", "0:4.5:0.25", "--json"])
    d = json.loads(res.stdout)
    assert not d["dof_open_ended"]["200"] and d["dof_mm"]["200"] < 4.5


def test_ghost_plot_labels_the_far_remainder(tmp_path):
    from opticalstamp.analysis.ghosts import analyse_ghosts
    from opticalstamp.design import load_design
    from opticalstamp.report.plotting import plot_ghosts

    g = analyse_ghosts(load_design("paper2016"), z_mm=(4.0,), n_rays=1 << 18)
    fig = plot_ghosts(g)
    labels = [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    land = g.landing["4"]
    far = land["etendue_by_distance_um2sr"][-1] / sum(land["etendue_by_distance_um2sr"])
    assert labels == [f"Z = 4 mm: {far:.0%} beyond 33.8 mm"]
    assert far > 0.1  # at Z = 4 mm a quarter of the ghost light lands farther than 33.8 mm
