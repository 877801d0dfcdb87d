"""The one reverse-pixel tracer: its pilot is shared, the analyses built on it agree, and
its sampling is checked."""

from __future__ import annotations

import math

import numpy as np
import pytest

import opticalstamp.raytrace.pixel as pixel_mod
from helpers import assert_agree
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.lsf import traced_folded_lsf
from opticalstamp.analysis.maps import traced_maps
from opticalstamp.analysis.spots import spots
from opticalstamp.design import load_design
from opticalstamp.raytrace.launch import launch
from opticalstamp.raytrace.pixel import (
    PixelTracer,
    Sampling,
    acceptance,
    allocate_holes,
    pixel_source,
    tracer_for,
)
from opticalstamp.raytrace.stack import reverse_path
from opticalstamp.raytrace.tally import is_own_path
from opticalstamp.validate import InputError

N = 1 << 18


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


@pytest.fixture
def pilots(monkeypatch):
    """Counts the pilot runs (calls of allocate_holes through the tracer)."""
    calls = []

    def counting(design, path, src, row, k, *args, **kw):
        calls.append((row, k, *args))
        return allocate_holes(design, path, src, row, k, *args, **kw)

    monkeypatch.setattr(pixel_mod, "allocate_holes", counting)
    return calls


# -- the pilot is computed once ----------------------------------------------------------
def test_analyses_sharing_a_tracer_run_each_pilot_once(paper, pilots):
    tracer = PixelTracer(paper)
    analyse_ghosts(paper, n_rays=N, seed=3, tracer=tracer)
    spots(paper, z_mm=(0.0,), n_rays=N, seed=3, tracer=tracer)
    traced_maps(paper, z_mm=[0.0], n_rays=N, seed=3, tracer=tracer)
    assert len(pilots) == 1  # pixel A0, seed 3: one pilot for three analyses
    traced_folded_lsf(paper, z_mm=[0.0], periods_um=[254.0], n_rays=N, seed=3, tracer=tracer)
    assert [c[:2] for c in pilots] == [(0, 0), (1, 0)]  # only row B's pilot is new
    # another seed, Fresnel option or precision target is another pilot
    analyse_ghosts(paper, n_rays=N, seed=4, tracer=tracer)
    analyse_ghosts(paper, n_rays=N, seed=3, fresnel=True, tracer=tracer)
    analyse_ghosts(paper, n_rays=N, seed=3, rse_ghost=0.05, tracer=tracer)
    assert len(pilots) == 5
    # the ray count, the chunk size and the precision-driven stop do not enter it
    analyse_ghosts(paper, n_rays=2 * N, seed=3, chunk=1 << 16, tracer=tracer)
    assert len(pilots) == 5


def test_analyses_without_a_tracer_run_their_own_pilots(paper, pilots):
    analyse_ghosts(paper, n_rays=N, seed=3)
    spots(paper, z_mm=(0.0,), n_rays=N, seed=3)
    assert len(pilots) == 2


def test_tracers_made_from_one_another_share_the_weights(paper, pilots):
    a = PixelTracer(paper, Sampling(seed=7))
    b = a.with_sampling(Sampling(n_rays=1000, seed=7, chunk=4096))
    c = tracer_for(paper, Sampling(seed=7), b)
    w = a.hole_weights((0, 0))
    assert b.hole_weights((0, 0)) is w and c.hole_weights((0, 0)) is w
    assert not w.flags.writeable  # shared: nobody may change it
    assert len(pilots) == 1
    assert PixelTracer(paper, Sampling(seed=7)).hole_weights((0, 0)) is not w
    assert len(pilots) == 2


def test_sharing_a_tracer_changes_no_number(paper):
    tracer = PixelTracer(paper)
    kw = dict(n_rays=N, seed=5, z_mm=(0.0, 1.0))
    spots(paper, tracer=tracer, **kw)  # computes the pilot
    a = analyse_ghosts(paper, tracer=tracer, **kw)
    b = analyse_ghosts(paper, **kw)
    assert a.to_dict() == b.to_dict()


def test_sampling_value_replaces_the_keywords(paper):
    s = Sampling(n_rays=N, seed=2, fresnel=True, rse_ghost=0.02)
    a = analyse_ghosts(paper, sampling=s, n_rays=123, seed=9)
    b = analyse_ghosts(paper, n_rays=N, seed=2, fresnel=True, rse_ghost=0.02)
    assert a.to_dict() == b.to_dict()
    # a sampling without a ray count takes the analysis's
    sp = spots(paper, z_mm=(0.0,), n_rays=N, sampling=Sampling(seed=2))
    assert sp.n_rays == N and sp.seed == 2


# -- the batches ---------------------------------------------------------------------------
def test_batches_are_the_launch_with_acceptance_and_own_path(paper):
    s = Sampling(n_rays=N, seed=11, chunk=1 << 16)
    tracer = PixelTracer(paper, s)
    path, src = reverse_path(paper), pixel_source(paper, 1, 0)
    weights = allocate_holes(paper, path, src, 1, 0, 11, False)
    got = list(tracer.trace((1, 0)))
    want = list(launch(path, src, N, 11, chunk=1 << 16, hole_weights=weights))
    assert len(got) == len(want) == 4
    for pb, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(pb.rays.ids, b.ids)
        np.testing.assert_array_equal(pb.w, b.w * acceptance(paper, path.slabs[0, 1], b.sx, b.sy))
        np.testing.assert_array_equal(pb.own, is_own_path(b, 1, 0))
        dx, dy = pb.offsets(1000.0)
        c = np.sqrt(pb.n_obj**2 - b.sx**2 - b.sy**2)
        np.testing.assert_allclose(dx, b.x + 1000.0 * b.sx / c - src.x, atol=1e-9)
        np.testing.assert_allclose(dy, b.y + 1000.0 * b.sy / c - src.y, atol=1e-9)


def test_a_run_continued_in_steps_is_one_stream(paper):
    tracer = PixelTracer(paper, Sampling(seed=1))
    whole = np.concatenate([pb.rays.ids for pb in tracer.trace((0, 0), 2 * N)])
    first = [pb.rays.ids for pb in tracer.trace((0, 0), N)]
    rest = [pb.rays.ids for pb in tracer.trace((0, 0), N, first_id=N)]
    np.testing.assert_array_equal(whole, np.concatenate(first + rest))


# -- the analyses agree where they overlap -------------------------------------------------
@pytest.fixture(scope="module")
def shared(paper):
    """The four analyses of pixel A0 from one tracer, one seed and one ray count."""
    tracer = PixelTracer(paper)
    kw = dict(n_rays=1 << 19, seed=21, tracer=tracer)
    g = analyse_ghosts(paper, z_mm=(0.0,), detector_half_um=5000.0, **kw)
    lsf = {
        gh: traced_folded_lsf(paper, z_mm=[0.0, 2.0], periods_um=[508.0], ghosts=gh, **kw)
        for gh in (True, False)
    }
    maps = traced_maps(paper, z_mm=[0.0, 2.0], **kw)
    sp = spots(paper, z_mm=(0.0, 2.0), ghosts=False, **kw)
    return g, lsf, maps, sp


def test_lsf_totals_are_the_ghost_analysis_etendues(shared):
    # the same rays, the same weights: the folded LSF's total is the etendue, at every Z
    g, lsf, _, _ = shared
    own = lsf[False].h[0][0].sum(axis=(0, 2))  # row A, per Z
    both = lsf[True].h[0][0].sum(axis=(0, 2))
    np.testing.assert_allclose(own, g.etendue_own_um2sr, rtol=1e-9)
    np.testing.assert_allclose(both - own, g.etendue_ghost_um2sr, rtol=1e-9)


def test_maps_hold_the_own_and_ghost_etendue(shared):
    g, _, maps, _ = shared
    for iz in range(2):
        # the fine grid encloses the own-path spot; the coarse grid, ghost light this near
        assert_agree(maps.own[iz].sum(), g.etendue_own_se, g.etendue_own_um2sr, 0.0)
        assert maps.ghost[iz].sum() <= g.etendue_ghost_um2sr * (1 + 1e-9)
    inside = g.landing["0"]["within_detector_um2sr"]  # ghost light within +-5 mm at Z = 0
    assert maps.ghost[0].sum() >= inside * (1 - 1e-9)


def test_spot_maps_hold_the_own_etendue(shared):
    g, _, _, sp = shared
    for s in sp.spots:
        db = s.x_edges_um[1] - s.x_edges_um[0]
        assert_agree(s.map_sr.sum() * db * db, g.etendue_own_se, g.etendue_own_um2sr, 0.0)


def test_independent_seeds_agree_within_their_errors(paper):
    g = analyse_ghosts(paper, n_rays=1 << 19, seed=31)
    lsf = traced_folded_lsf(
        paper, z_mm=[1.0], periods_um=[254.0], n_rays=1 << 19, seed=32, ghosts=False
    )
    per_batch = lsf.h[0][0, :, 0].sum(axis=1) * lsf.n_batches  # batch means of the total
    se = per_batch.std(ddof=1) / math.sqrt(lsf.n_batches)
    assert_agree(per_batch.mean(), se, g.etendue_own_um2sr, g.etendue_own_se)


# -- checks ----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kw",
    [
        {"n_rays": 0},
        {"n_rays": -5},
        {"n_rays": 1.5},
        {"n_rays": "1000"},
        {"n_rays": True},
        {"seed": -1},
        {"seed": 2**63},
        {"seed": 1.0},
        {"fresnel": "yes"},
        {"fresnel": 1},
        {"chunk": 0},
        {"chunk": 2.0},
        {"rse_own": 0.0},
        {"rse_own": 1.0},
        {"rse_own": float("nan")},
        {"rse_ghost": -0.1},
        {"rse_ghost": "0.01"},
        {"max_rays": 0},
    ],
)
def test_sampling_rejects_bad_values(kw):
    field = next(iter(kw))
    with pytest.raises(InputError, match=field):
        Sampling(**kw)


def test_sampling_takes_numpy_scalars_as_plain_values():
    s = Sampling(n_rays=np.int64(4096), seed=np.uint32(3), fresnel=np.bool_(True))
    assert s == Sampling(n_rays=4096, seed=3, fresnel=True)
    assert type(s.n_rays) is int and type(s.seed) is int and type(s.fresnel) is bool
    assert Sampling(rse_own=np.float32(0.5)).rse_own == 0.5


def test_analyses_check_their_sampling(paper):
    with pytest.raises(InputError, match="seed"):
        spots(paper, seed=-1)
    with pytest.raises(InputError, match="n_rays"):
        traced_folded_lsf(paper, z_mm=[0.0], periods_um=[254.0], n_rays=0)
    with pytest.raises(InputError, match="rse_own"):
        analyse_ghosts(paper, rse_own=2.0)


def test_a_tracer_serves_only_its_design_and_pixels(paper):
    other = load_design("fig1d")
    with pytest.raises(InputError, match="tracer"):
        analyse_ghosts(other, n_rays=N, tracer=PixelTracer(paper))
    with pytest.raises(InputError, match="pixel"):
        PixelTracer(paper).source((2, 0))
    with pytest.raises(InputError, match="pixel"):
        analyse_ghosts(paper, pixel=(0, 10**9), n_rays=N)
