"""Each pixel traced once: the tracer's pass count (raytrace/passes.py), the replay that
hands out rays traced already (whole chunks, or cut on a block edge), and the report and
the quick report on the prototype, whose every traced analysis of a used pixel draws its
rays from one tracer: no ray of a pixel's stream is traced twice, and a pixel's stream
holds as many rays as the analysis that asks for the most (not their sum): that check runs on
the reports the suite makes anyway (tests/passcount.py, used by tests/test_report.py and
tests/test_report_speed_paths.py)."""

from __future__ import annotations

import numpy as np
import pytest

from opticalstamp.design import load_design
from opticalstamp.raytrace.launch import BLOCK
from opticalstamp.raytrace.passes import StreamKey, TracePasses
from opticalstamp.raytrace.pixel import PILOT_RAYS, PixelTracer, Sampling


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
