"""Importance sampling is unbiased; launches are reproducible and chunk-independent."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import Tally, assert_agree, run_python
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.design import design_from_dict, load_design
from opticalstamp.raytrace.kernel import ESCAPED, TIR
from opticalstamp.raytrace.launch import launch
from opticalstamp.raytrace.pixel import allocate_holes, pixel_source
from opticalstamp.raytrace.sampling import Source
from opticalstamp.raytrace.stack import forward_path, reverse_path
from opticalstamp.raytrace.tally import is_own_path


def _etendues(path, src, n_rays, seed, **kw):
    """(total, own path of pixel A0) etendue tallies over all rays reaching the end."""
    total, own_t = Tally(), Tally()
    for b in launch(path, src, n_rays, seed, **kw):
        total.add(b.w, b.n_samples)
        own_t.add(b.w[is_own_path(b, 0, 0)], b.n_samples)
    return total, own_t


@pytest.mark.parametrize("name", ["paper2016", "fig1b", "fig1d"])
def test_importance_sampling_is_unbiased(name):
    design = load_design(name)
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    imp_total, imp_own = _etendues(path, src, 1 << 21, 1, importance=True)
    pl_total, pl_own = _etendues(path, src, 1 << 25, 2, importance=False, chunk=1 << 22)
    assert imp_own.value > 0 and imp_total.value > imp_own.value
    assert_agree(imp_total.value, imp_total.se, pl_total.value, pl_total.se)
    assert_agree(imp_own.value, imp_own.se, pl_own.value, pl_own.se)


def test_importance_sampling_is_unbiased_with_fresnel():
    # Fresnel losses multiply the weights ray by ray; both estimators see the same losses
    design = load_design("paper2016")
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    imp_total, imp_own = _etendues(path, src, 1 << 21, 1, fresnel=True)
    pl_total, pl_own = _etendues(path, src, 1 << 25, 2, importance=False, fresnel=True)
    assert_agree(imp_total.value, imp_total.se, pl_total.value, pl_total.se)
    assert_agree(imp_own.value, imp_own.se, pl_own.value, pl_own.se)
    # two index steps on the own path (air/glass at z = 450 um, glass/air at 1850 um), crossed
    # within ~10 degrees of the normal: just under (1 - 0.0426)^2 of the lossless etendue
    _, lossless_own = _etendues(path, src, 1 << 21, 1)
    ratio = imp_own.value / lossless_own.value
    assert 0.90 < ratio < (1 - ((1.52 - 1) / (1.52 + 1)) ** 2) ** 2 + 1e-3


def test_importance_sampling_is_unbiased_from_inside_glass():
    # a pixel under a glass cover: directions with |s| > 1 are totally reflected at the
    # glass/air interface before the first mask; importance sampling never draws them.
    data = {
        "slabs": [
            {"medium": 1.52, "thickness_um": 300.0},
            {"medium": "air", "thickness_um": 200.0, "mask_top": {"size_um": 40.0}},
        ],
        "reference_gap": {"thickness_um": 500.0},
    }
    design = design_from_dict(data)
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    imp, _ = _etendues(path, src, 1 << 21, 1)
    plain = Tally()
    led = np.zeros((path.slabs.shape[0], 4), np.int64)
    for b in launch(path, src, 1 << 25, 2, importance=False, chunk=1 << 22):
        plain.add(b.w, b.n_samples)
        led += b.ledger
    assert_agree(imp.value, imp.se, plain.value, plain.se)
    # the TIR share of a Lambertian emitter in glass is 1 - 1/n^2 (the most grazing of those
    # rays leave the plate's edge inside the glass first and are counted as escaped)
    p = 1 - 1 / 1.52**2
    n = led.sum()
    assert led[0, TIR] > 0.99 * (led[0, TIR] + led[0, ESCAPED])
    assert abs((led[0, TIR] + led[0, ESCAPED]) / n - p) < 4 * np.sqrt(p * (1 - p) / n)


def test_steered_importance_sampling_is_unbiased():
    # the pilot-driven hole allocation (with its defensive share) leaves the estimates unbiased
    design = load_design("paper2016")
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    weights = allocate_holes(design, path, src, 0, 0, seed=5, fresnel=False)
    st_total, st_own = _etendues(path, src, 1 << 21, 6, hole_weights=weights)
    pl_total, pl_own = _etendues(path, src, 1 << 25, 7, importance=False, chunk=1 << 22)
    assert_agree(st_total.value, st_total.se, pl_total.value, pl_total.se)
    assert_agree(st_own.value, st_own.se, pl_own.value, pl_own.se)
    # and analyse_ghosts, which uses it, reports the same own-path etendue
    g = analyse_ghosts(design, n_rays=1 << 20, seed=8)
    assert_agree(g.etendue_own_um2sr, g.etendue_own_se, pl_own.value, pl_own.se)
    assert_agree(
        g.etendue_own_um2sr + g.etendue_ghost_um2sr,
        np.hypot(g.etendue_own_se, g.etendue_ghost_se),
        pl_total.value,
        pl_total.se,
    )


def test_importance_sampling_is_unbiased_forward():
    # an object area emitting down the stack (paper Fig. 10's direction of travel)
    path = forward_path(load_design("paper2016"), 1000.0)
    src = Source(40.0, 0.0, 100.0, 100.0)
    imp = Tally()
    for b in launch(path, src, 1 << 21, 1):
        imp.add(b.w, b.n_samples)
    plain = Tally()
    for b in launch(path, src, 1 << 25, 2, importance=False, chunk=1 << 22):
        plain.add(b.w, b.n_samples)
    assert imp.value > 0
    assert_agree(imp.value, imp.se, plain.value, plain.se)


def _collect(path, src, n_rays, seed, **kw):
    ids, w, x, sx, holes = [], [], [], [], []
    n_samples = 0
    for b in launch(path, src, n_rays, seed, **kw):
        ids.append(b.ids)
        w.append(b.w)
        x.append(b.x)
        sx.append(b.sx)
        holes.append(b.hole_k)
        n_samples += b.n_samples
    cat = np.concatenate
    return cat(ids), cat(w), cat(x), cat(sx), cat(holes), n_samples


@pytest.mark.parametrize("importance", [True, False])
def test_chunk_size_does_not_change_results(importance):
    design = load_design("paper2016")
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    n = 1 << 20
    a = _collect(path, src, n, 42, importance=importance, chunk=4096 * 8)
    b = _collect(path, src, n, 42, importance=importance, chunk=4096 * 64)
    assert a[0].size > 0
    for u, v in zip(a[:5], b[:5], strict=True):
        np.testing.assert_array_equal(u, v)
    assert a[5] == b[5] == n
    assert np.all(np.diff(a[0]) > 0)  # survivors come in launch order
    # the tally (sum in ray order) is bit-identical
    assert a[1].sum() == b[1].sum()
    # different seeds give different rays
    c = _collect(path, src, n, 43, importance=importance, chunk=4096 * 8)
    assert a[1].sum() != c[1].sum()
    assert not np.array_equal(a[0][: min(a[0].size, c[0].size)], c[0][: min(a[0].size, c[0].size)])


#: the comparison of thread counts, in a process of its own with up to 4 numba threads (the
#: suite's workers run one thread each: tests/conftest.py)
THREADS = """
import numba, numpy as np
from opticalstamp.design import load_design
from opticalstamp.raytrace.launch import launch
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.stack import reverse_path

design = load_design("paper2016")
path, src = reverse_path(design), pixel_source(design, 0, 0)
assert numba.config.NUMBA_NUM_THREADS == 4
for imp in (True, False):
    got = []
    for threads in (1, 4):
        numba.set_num_threads(threads)
        bs = list(launch(path, src, 1 << 19, 9, importance=imp))
        fields = ("ids", "w", "x", "sx", "hole_k")
        got.append([np.concatenate([getattr(b, f) for b in bs]) for f in fields])
    for u, v in zip(*got, strict=True):
        np.testing.assert_array_equal(u, v)
# the parallel tally kernels (folds over Z, maps) and the rod-lens tracer
from opticalstamp.analysis.lsf import traced_folded_lsf_pair
from opticalstamp.analysis.maps import traced_map_sets
from opticalstamp.raytrace.rodlens import trace_rods

rods = load_design("sla-2row-20deg")
got = []
for threads in (1, 4):
    numba.set_num_threads(threads)
    a, b = traced_folded_lsf_pair(
        design, z_mm=[0.5, 1.0, 2.0, 3.0], periods_um=[127.0, 84.6], n_rays=1 << 17, seed=1
    )
    (m,) = traced_map_sets(design, z_sets=[[0.5, 1.0, 2.0]], n_rays=1 << 17, seed=2)
    r = trace_rods(rods, [0.0, 100.0, 250.0], n_rays=50_000, seed=5)
    got.append([*a.h, *b.h, m.own, m.ghost, r.ids, r.x])
for u, v in zip(*got, strict=True):
    assert u.size and np.array_equal(u, v)
print("same")
"""


def test_thread_count_does_not_change_results():
    """One thread and four give the same rays, bit for bit (plain and importance
    sampling), the same folded LSFs and maps (the tally kernels' parallel loops) and the
    same rod-lens rays."""
    res = run_python(THREADS, NUMBA_NUM_THREADS="4")
    assert res.returncode == 0 and res.stdout.strip() == "same", res.stderr[-3000:]


def test_first_id_continues_the_sequence():
    # rays 0..N-1 in one launch equal rays 0..N/2-1 and N/2..N-1 from two launches
    design = load_design("paper2016")
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    n = 1 << 19
    whole = _collect(path, src, n, 3)
    first = _collect(path, src, n // 2, 3)
    second = _collect(path, src, n // 2, 3, first_id=n // 2)
    for u, v, t in zip(whole[:5], first[:5], second[:5], strict=True):
        np.testing.assert_array_equal(u, np.concatenate([v, t]))


def test_streams_are_independent():
    design = load_design("paper2016")
    path = reverse_path(design)
    src = pixel_source(design, 0, 0)
    a = _collect(path, src, 1 << 18, 3, stream=0)
    b = _collect(path, src, 1 << 18, 3, stream=1)
    assert a[1].sum() != b[1].sum()
