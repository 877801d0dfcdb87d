"""The library's defaults, one named constant each (the command line's options read them).

Cheap to import: the CLI builds its options from these without loading numba or optuna.
The paper's own figures (chart resolutions, the DOF criterion) are named as such.
"""

from __future__ import annotations

from types import MappingProxyType

# RMTF and depth of field (paper Eq. 1, Fig. 11)
PAPER_CHART_DPI = (100.0, 150.0, 200.0, 247.0)  # the paper's bar charts
DOF_THRESHOLD = 0.3  # depth of field: first Z where RMTF falls below 0.3 on the chart at
# 2/3 of the design's own resolution (200 dpi for 300 dpi; design/resolution.py)
Z_GRID_MM = "0:4.5:0.25"  # object distances of the RMTF curves (START:STOP:STEP)
WINDOW_UM = 5000.0  # chart window over which Imax and Imin are taken
SHIFT_STEP_UM = 1.0  # chart shift step (the maximum over shifts suppresses Moire)

# Monte Carlo
RAYS_LSF = 1 << 21  # rays per pixel row for the folded line-spread functions (RMTF)
RAYS_MAP = 1 << 22  # rays for maps: spots, PSFs, the report's spots
MAP_MAX_BINS = 1024  # the most bins a side of a pixel's map has: a spot wider than that
# many bins (a stack too thin to confine the light) is mapped on coarser bins
RSE_OWN = 1e-3  # ghost analysis: run until the own-path etendue has this relative SE ...
RSE_GHOST = 1e-2  # ... and the ghost etendue this one
DETECTOR_HALF_UM = 500.0  # half width of the virtual detector of paper Fig. 4

# design search (paper section 3) and tolerancing (section 5)
SEARCH_POPULATION = 32  # designs per NSGA-II generation ...
SEARCH_GENERATIONS = 15  # ... times generations: 480 designs
SEARCH_BUDGET_MM = 2.5  # total stack thickness budget
SEARCH_NEAR_MM = 1.0  # no ghost light within this distance of the pixel's axis
TOLERANCE_SAMPLES = 1000
TOLERANCE_SIGMAS = MappingProxyType(  # 1-sigma assembly errors (the paper: ~3 um, section 5)
    {"misregistration_um": 3.0, "hole_um": 1.0, "thickness_um": 10.0, "tilt_deg": 0.02}
)
