"""The band tally (analysis/tallies.py: BandTally), which the search's wave estimator
takes its far light from: against the same sums and nearest landing computed at once over
every ray of the trace, from the rays' own positions and directions."""

from __future__ import annotations

import numpy as np
import pytest

from opticalstamp.analysis.tallies import BandTally, run
from opticalstamp.design import load_design
from opticalstamp.raytrace.pixel import PixelTracer, Sampling


@pytest.mark.parametrize(("name", "band"), [("paper2016", 0.2), ("fig1d", 0.35)])
def test_band_tally_is_the_sum_over_every_ray(name, band):
    d = load_design(name)
    tr = PixelTracer(d, Sampling(1 << 16, 4, chunk=1 << 14), replay=True)
    z_mm = (0.0, 1.5, 4.0)
    t = BandTally(band, z_mm)
    run(tr, (0, 0), [t])
    pbs = list(tr.trace((0, 0)))  # the same rays again (replayed), in four batches
    assert len(pbs) == 4
    cat = np.concatenate
    w = cat([pb.w for pb in pbs])
    x, y = cat([pb.rays.x for pb in pbs]), cat([pb.rays.y for pb in pbs])
    sx, sy = cat([pb.rays.sx for pb in pbs]), cat([pb.rays.sy for pb in pbs])
    out = (np.maximum(np.abs(sx), np.abs(sy)) >= band) & (w > 0)
    assert 0 < out.sum() < out.size
    assert t.far == pytest.approx(w[out].sum(), rel=1e-12)
    assert t.inside == pytest.approx(w[~out].sum(), rel=1e-12)
    assert t.far + t.inside == pytest.approx(w.sum(), rel=1e-12)
    # where the far light lands: straight lines through the object medium
    pb = pbs[0]
    n, x0, y0 = pb.n_obj, pb.x0, pb.y0
    c = np.sqrt(n * n - sx[out] ** 2 - sy[out] ** 2)
    near = min(
        np.hypot(x[out] + z * sx[out] / c - x0, y[out] + z * sy[out] / c - y0).min()
        for z in np.asarray(z_mm) * 1000.0
    )
    assert t.nearest == pytest.approx(near, rel=1e-12)
    none = BandTally(n + 1.0, z_mm)  # beyond every direction (|s| < n): no far light
    run(tr, (0, 0), [none])
    assert none.far == 0.0 and none.nearest == np.inf
    assert none.inside == pytest.approx(w.sum(), rel=1e-12)
