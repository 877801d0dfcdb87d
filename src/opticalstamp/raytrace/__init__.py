"""Exact 3-D ray tracing: the compiled stack, sampling (the pixel as a source), the numba
kernel and its driver, Monte Carlo tallies. Imports ``design`` only."""
