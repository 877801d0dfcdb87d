"""Compile numba's CPU kernels into their caches before the test workers start
(tests/conftest.py runs this in two processes at the start of a run with workers).

In a fresh clone no kernel is cached yet: every worker, and every background process a
test starts, that reaches a kernel before its cache is written compiles it again (the
full report's test starts four such processes at once). Compiled once here, they load.
Which kernels are warmed changes no result: one missed is compiled where it is first
used, as without this. Run as ``python tests/warm_numba.py rays|rest``."""

from __future__ import annotations

import sys

import numpy as np


def rays() -> None:
    """The ray kernels (one ray's arithmetic inlined) and the tally kernels."""
    from opticalstamp.analysis.ghosts import analyse_ghosts
    from opticalstamp.analysis.lsf import traced_folded_lsf_pair
    from opticalstamp.analysis.maps import traced_map_sets
    from opticalstamp.design import load_design
    from opticalstamp.raytrace.launch import launch, trace_rays
    from opticalstamp.raytrace.pixel import pixel_source
    from opticalstamp.raytrace.stack import reverse_path

    d = load_design("paper2016")
    path, src = reverse_path(d), pixel_source(d, 0, 0)
    for importance, fresnel in ((False, False), (True, True)):
        list(launch(path, src, 1 << 12, 1, importance=importance, fresnel=fresnel))
    z = np.zeros(4)
    trace_rays(path, z, z, z, z)
    analyse_ghosts(d, z_mm=[0.5], n_rays=1 << 12, seed=1)
    traced_folded_lsf_pair(d, z_mm=[0.5], periods_um=[127.0], n_rays=1 << 12, seed=1)
    traced_map_sets(d, z_sets=[[0.5]], n_rays=1 << 12, seed=2)


def rest() -> None:
    """The rod-lens tracer, the scans' separable passes and the fit's chart sums."""
    from opticalstamp.design import load_design
    from opticalstamp.imaging.scan import simulate_scan
    from opticalstamp.raytrace.rodlens import trace_rods
    from opticalstamp.studies import fitmodel

    trace_rods(load_design("sla-1row-12deg"), [0.0], n_rays=256)
    simulate_scan(np.ones((96, 96)), 1200.0, load_design("paper2016"), z_mm=1.0, seed=0)
    u = np.linspace(-50.0, 50.0, 64)
    c = np.linspace(0.0, 1.0, 64)
    x = np.linspace(-20.0, 20.0, 8)
    fitmodel._bar_sum(u, c, x, 30.0, 0.0, 8)
    fitmodel._edge_sum(u, c, x, x[:4].copy(), np.full(4, 0.25))


if __name__ == "__main__":
    {"rays": rays, "rest": rest}[sys.argv[1]]()
