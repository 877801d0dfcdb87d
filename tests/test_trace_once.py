"""Each pixel traced once: the tracer's pass count (raytrace/passes.py), the replay that
hands out rays traced already (whole chunks, or cut on a block edge), and the report and
the quick report on the prototype, whose every traced analysis of a used pixel draws its
rays from one tracer: no ray of a pixel's stream is traced twice, and a pixel's stream
holds as many rays as the analysis that asks for the most (not their sum)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from opticalstamp.defaults import RAYS_LSF
from opticalstamp.design import load_design
from opticalstamp.raytrace import pixel as pixel_module
from opticalstamp.raytrace.launch import BLOCK
from opticalstamp.raytrace.passes import StreamKey, TracePasses
from opticalstamp.raytrace.pixel import PILOT_RAYS, PixelTracer, Sampling
from opticalstamp.report import build


def _key(stream: int = 0) -> StreamKey:
    return StreamKey("d", 0, 0, stream, 0, False, 1e-3, 1e-2)


def test_passes_are_the_most_times_one_ray_was_traced():
    """Against a brute-force count of every ray of random spans."""
    rng = np.random.default_rng(5)
    for _ in range(50):
        p, seen = TracePasses(), np.zeros(200, int)
        for _ in range(rng.integers(1, 6)):
            a, n = int(rng.integers(0, 150)), int(rng.integers(1, 50))
            p.add(_key(), a, n)
            seen[a : a + n] += 1
        assert p.passes(_key()) == seen.max()
        assert p.rays(_key()) == np.count_nonzero(seen)
    assert p.passes(_key(1)) == 0 and p.rays(_key(1)) == 0
    assert p.passes() == {_key(): p.passes(_key())}


def _arrays(batches) -> dict:
    out = {}
    for name in ("ids", "x", "y", "sx", "sy", "w", "hole_row", "hole_k"):
        out[name] = np.concatenate([getattr(b.rays, name) for b in batches])
    out["w_acc"] = np.concatenate([b.w for b in batches])
    out["own"] = np.concatenate([b.own for b in batches])
    out["ledger"] = sum(b.rays.ledger for b in batches)
    out["n"] = sum(b.rays.n_samples for b in batches)
    return out


def _same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(a[k], b[k]), k


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


def test_replay_hands_out_the_rays_a_fresh_trace_gives(paper):
    """Spans inside, across and beyond the chunks traced already: the rays, accepted
    weights, own-path flags, ledgers and sample counts of a tracer with replay are those
    of one without; every ray is traced once, and the count says so."""
    s = Sampling(seed=2, chunk=8 * BLOCK)
    tr = PixelTracer(paper, s, replay=True)
    fresh = PixelTracer(paper, s)
    asks = [(0, 12 * BLOCK), (4 * BLOCK, 4 * BLOCK), (2 * BLOCK, 20 * BLOCK), (0, 24 * BLOCK)]
    for first, n in asks:
        got = list(tr.trace((0, 0), n, first_id=first))
        assert sum(b.rays.n_samples for b in got) == n
        _same(_arrays(got), _arrays(list(fresh.trace((0, 0), n, first_id=first))))
    key = tr._stream_key((0, 0), 0)
    assert tr.passes.passes(key) == 1 and tr.passes.rays(key) == 24 * BLOCK
    # launched: the first ask in two chunks, then only what was not traced yet
    spans = [(0, 8), (8, 4), (12, 8), (20, 2), (22, 2)]
    assert tr.passes.spans(key) == [(a * BLOCK, n * BLOCK) for a, n in spans]
    assert tr.passes.spans(tr._stream_key((0, 0), 1)) == [(0, PILOT_RAYS)]  # one pilot
    # the fresh tracer traced rays 0 ... 4 blocks four times
    assert fresh.passes.passes(key) == 4
    # a cut off a block edge cannot carry its ledger: traced again, and counted; kept
    # apart, so that asking for exactly those rays again traces nothing
    for _ in range(2):
        _same(
            _arrays(list(tr.trace((0, 0), 1000, first_id=100))),
            _arrays(list(fresh.trace((0, 0), 1000, first_id=100))),
        )
        assert tr.passes.passes(key) == 2 and tr.passes.rays(key) == 24 * BLOCK


def _small(quick: bool):
    """The report's work with few rays (every section still runs); the full report's
    shape (its heights, RMTF grid, both sensitive areas, the concepts reusing the ghost
    analysis) without its background studies and OCR, which trace other designs in
    other processes."""
    real = build.report_work

    def work(*args, **kwargs):
        w = real(*args, **kwargs)
        w = replace(
            w,
            ghost_rays=1 << 16,
            map_rays=1 << 14,
            concept_rays=1 << 14 if quick else 1 << 16,
            lsf_rays=1 << 15,
            kernel_rays=1 << 14,
            wave_rays=1 << 15,
        )
        return w if quick else replace(w, studies=False, ocr=False, scan_dpi=600.0)

    return work


def _spy(monkeypatch) -> list:
    """Every launch from a pixel source in this process, however it is reached."""
    seen, real = [], pixel_module.launch

    def launch(path, src, n, seed, **kw):
        seen.append((path, src, kw.get("stream", 0), kw.get("first_id", 0), n))
        return real(path, src, n, seed, **kw)

    monkeypatch.setattr(pixel_module, "launch", launch)
    return seen


@pytest.mark.parametrize("quick", [True, False], ids=["quick", "report"])
def test_the_report_traces_each_pixel_once(paper, quick, tmp_path, monkeypatch):
    """The figures are not drawn (a third of the quick report's time, profiled): they
    plot the sections' results and trace nothing (report/plotting imports no tracer),
    and the report's pages and figures are tested in test_report.py and
    test_report_presets.py."""
    monkeypatch.setattr(build, "report_work", _small(quick))
    monkeypatch.setattr(build, "png", lambda plot, *args: b"")
    seen = _spy(monkeypatch)
    passes = TracePasses()
    data = build.build_report(paper, tmp_path / "r", quick=quick, passes=passes)
    assert data["optics"]["engine"] == "wave"  # the wave sections' traced light included
    work = _small(quick)(quick)
    mine = [k for k in passes.keys() if k.design == paper.fingerprint()]
    rows = {(r, 0) for r in range(paper.sensor.rows)}
    # every stream of every used pixel traced once: the analyses' rays (0), the hole
    # pilot (1) and the spots' own sizing pilot (2, pixel A only), under one sampling
    assert {k: passes.passes(k) for k in mine} == {k: 1 for k in mine}
    assert {(k.pixel, k.stream) for k in mine} == {(p, s) for p in rows for s in (0, 1)} | {
        ((0, 0), 2)
    }
    assert {(k.seed, k.fresnel) for k in mine} == {(0, False)}
    got = {(k.pixel, k.stream): passes.rays(k) for k in mine}
    # a stream holds as many rays as its most demanding analysis asks for: pixel A's the
    # ghost analysis, spots, LSFs, scan kernels, ray-vs-wave and the wave light (RAYS_LSF),
    # pixel B's the LSFs, kernels and ray-vs-wave
    asked_a = (work.ghost_rays, work.map_rays, work.concept_rays, work.lsf_rays)
    assert got[(0, 0), 0] == max(*asked_a, work.kernel_rays, work.wave_rays, RAYS_LSF)
    assert got[(1, 0), 0] == max(work.lsf_rays, work.kernel_rays, work.wave_rays)
    assert got[(0, 0), 1] == got[(1, 0), 1] == got[(0, 0), 2] == PILOT_RAYS
    # the count is complete: every launch of the prototype's pixels in this process went
    # through the report's tracer (the spy sees the rest too: other designs, among them
    # the single-row concept on the same stack, and the larger sensitive area), and none
    # of them overlaps another of its stream
    proto = PixelTracer(paper).path

    def is_proto(path, src) -> bool:
        return (
            np.array_equal(path.slabs, proto.slabs)
            and np.array_equal(path.masks, proto.masks)
            and np.array_equal(path.lattice.as_array(), proto.lattice.as_array())
            and src.width == paper.sensor.sensitive_width_um
            and src.height == paper.sensor.sensitive_height_um
        )

    spans: dict = {}
    for path, src, stream, first, n in seen:
        if is_proto(path, src):
            spans.setdefault((round(src.x, 6), round(src.y, 6), stream), []).append((first, n))
    assert sum(n for v in spans.values() for _, n in v) == sum(passes.rays(k) for k in mine), (
        spans,
        {(k.pixel, k.stream): passes.spans(k) for k in mine},
    )
    for v in spans.values():
        v.sort()
        assert all(a + n <= b for (a, n), (b, _) in zip(v, v[1:], strict=False)), v
