"""The CUDA backend's kernels and tallies against the CPU's, as test functions of one
session under numba's CUDA simulator (tests/test_cuda.py runs this module in a process of
its own with ``NUMBA_ENABLE_CUDASIM=1``; on a machine with a GPU, without it and with
``RAYS_LOG2=20``). Not collected by the main run (its name is not ``test_*``).

The rays go through stacks opened so that hundreds of them leave the stack: the ray
arithmetic is compared ray for ray on survivors, not only on the ledger of fates. The
arguments of every kernel as launched are recorded on the way, for the PTX compilation
test (``OPTICALSTAMP_TEST_RECORD``: where to write them).
"""

from __future__ import annotations

import dataclasses
import os
import pickle

import numpy as np
import pytest

from opticalstamp.analysis import cuda_tallies as ct
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.lsf import traced_folded_lsf_pair
from opticalstamp.analysis.maps import traced_map_sets
from opticalstamp.design import load_design, with_stack
from opticalstamp.device import DeviceUnavailable, simulated, using_device
from opticalstamp.io.files import provenance
from opticalstamp.raytrace import cuda
from opticalstamp.raytrace.kernel import seed_key
from opticalstamp.raytrace.launch import _kernel_args, launch
from opticalstamp.raytrace.pixel import PixelTracer, Sampling, pixel_source
from opticalstamp.raytrace.stack import reverse_path

#: 2^N samples (the simulator is slow; a GPU takes 20)
N = int(os.environ.get("RAYS_LOG2", "12"))
FIELDS = ("ids", "x", "y", "sx", "sy", "w", "hole_row", "hole_k")
#: the plain kernels compared: queued per block (the default) and not at all; per warp too
#: on a GPU (the simulator has no warp intrinsics)
QUEUES = ("none", "block") if simulated() else ("none", "block", "warp")
SEEN: dict = {}


class Recorder:  # a kernel's arguments as first launched (host copies), then the launch
    def __init__(self, name, kernel):
        self.name, self.kernel = name, kernel

    def __getitem__(self, config):
        def call(*args):
            if self.name not in SEEN:
                SEEN[self.name] = [
                    a.copy_to_host() if hasattr(a, "copy_to_host") else a for a in args
                ]
            return self.kernel[config](*args)

        return call


@pytest.fixture(scope="module", autouse=True)
def recorded():
    """Every kernel launched through a Recorder; the arguments written at the end."""
    with pytest.MonkeyPatch.context() as mp:
        for mod in (cuda, ct):
            for name in [n for n in dir(mod) if n.endswith("_kernel")]:
                mp.setattr(mod, name, Recorder(name, getattr(mod, name)))
        yield SEEN
    out = os.environ.get("OPTICALSTAMP_TEST_RECORD")
    if out:
        with open(out, "wb") as f:
            pickle.dump(SEEN, f)


@pytest.fixture(scope="module")
def paper():
    return load_design("paper2016")


@pytest.fixture(scope="module")
def wide(paper):
    """The prototype's reverse path with every hole 160 um wide (beyond what a design may
    hold: the neighbours' holes overlap), and its pixel A0: about 8 % of plain samples and
    45 % of importance-sampled rays leave the stack, own and ghost paths alike."""
    path = reverse_path(paper)
    masks = path.masks.copy()
    masks[:, 1:3] = 80.0  # half width and height (um)
    return dataclasses.replace(path, masks=masks), pixel_source(paper, 0, 0)


def joined(batches):  # the chunks as one (a GPU deals rays into larger chunks)
    out = {f: np.concatenate([getattr(b, f) for b in batches]) for f in FIELDS}
    out["ledger"] = sum(b.ledger for b in batches)
    out["n_launched"] = sum(b.n_launched for b in batches)
    return out


def same(a, b, exact=False):
    assert np.array_equal(a["ids"], b["ids"]), (a["ids"].size, b["ids"].size)
    for f in ("x", "y", "sx", "sy", "w"):
        if exact:
            assert np.array_equal(a[f], b[f]), f
        np.testing.assert_allclose(a[f], b[f], rtol=1e-12, atol=1e-9)
    for f in ("hole_row", "hole_k", "ledger"):
        assert np.array_equal(a[f], b[f]), f
    assert a["n_launched"] == b["n_launched"]


@pytest.mark.parametrize(
    ("importance", "fresnel", "log2"), [(False, False, N), (True, True, N - 1)]
)
def test_launch_on_the_device_gives_the_cpus_rays(wide, importance, fresnel, log2):
    """Plain sampling (4,096 samples) and importance sampling with Fresnel losses (2,048
    rays): the same survivors (ids), positions, directions and weights (to 1e-12), holes,
    ledger and launched counts as the CPU kernel, for the same seed; hundreds of rays
    survive, own and ghost."""
    path, src = wide
    kw = dict(importance=importance, fresnel=fresnel, chunk=1 << 12, first_id=123)
    cpu = joined(list(launch(path, src, 1 << log2, 7, device="cpu", **kw)))
    own = np.all((cpu["hole_row"] == 0) & (cpu["hole_k"] == 0), axis=1)
    assert cpu["ids"].size > (150 << log2 >> 12) and 0 < own.sum() < own.size
    same(cpu, joined(list(launch(path, src, 1 << log2, 7, device="cuda", **kw))))


def test_the_plain_kernels_queued_or_not_give_the_same_rays(wide, monkeypatch):
    """Plain sampling queued per block (the default), per warp (on a GPU) and not at all:
    the same rays, exactly, and the CPU's; with one block, so that each queue fills and
    drains many times (a fifth of the samples pass the first mask, 8 % all the way)."""
    path, src = wide
    monkeypatch.setattr(cuda, "QUEUE_BLOCKS", 1)
    n0 = float(path.slabs[0, 1])
    args = np.array([src.x, src.y, src.width, src.height, 4 * n0 * n0 * src.area, n0, n0, 0.0])
    n_pre = path.first_mask_slab + 1
    runs = [
        cuda.run(123, 1 << N, seed_key(7), args, _kernel_args(path), True, n_pre, None, queue=q)
        for q in QUEUES
    ]
    passed = runs[0].n_launched - int(runs[0].ledger[:n_pre].sum())
    assert passed >= 6 * cuda.THREADS, passed  # the block's queue filled 6 times at least
    a, *others = ({**r.host(), "ledger": r.ledger, "n_launched": r.n_launched} for r in runs)
    assert a["ids"].size > 250, a["ids"].size
    for b in others:
        same(a, b, exact=True)
    kw = dict(importance=False, fresnel=True, chunk=1 << 12, first_id=123, device="cpu")
    same(a, joined(list(launch(path, src, 1 << N, 7, **kw))))


def test_a_stack_beyond_the_kernels_arrays_is_refused(paper):
    path = reverse_path(paper)
    big = list(_kernel_args(path))
    big[2] = np.repeat(big[2], 6, axis=0)  # 18 masks
    args = np.zeros(8)
    with pytest.raises(DeviceUnavailable, match="--device cpu"):
        cuda.run(0, 256, seed_key(1), args, tuple(big), False, path.first_mask_slab + 1)


def test_the_provenance_names_the_device(paper):
    assert provenance(paper, 0, device="cuda")["device"] == "cuda"
    with using_device("cuda"):
        assert provenance(paper, 0)["device"] == "cuda"
        assert provenance(load_design("sla-1row-12deg"), 0)["device"] == "cpu"
    assert provenance(paper, 0)["device"] == "cpu"


# -- tallies on the device ----------------------------------------------------------------
def _same(x, y, where=""):
    if isinstance(x, dict):
        assert x.keys() == y.keys(), where
        for k in x:
            _same(x[k], y[k], f"{where}/{k}")
    elif isinstance(x, list | tuple):
        assert len(x) == len(y), where
        for i, (p, q) in enumerate(zip(x, y, strict=True)):
            _same(p, q, f"{where}[{i}]")
    elif isinstance(x, float):
        assert np.isclose(x, y, rtol=1e-12, atol=0), (where, x, y)
    else:
        assert x == y, (where, x, y)


@pytest.fixture(scope="module")
def open_design(paper):
    """The prototype with 82-um holes on thin plates: a tenth of the importance-sampled
    rays leave the stack, 60 % of them through the pixel's own holes."""
    return with_stack(paper, holes_um=(82, 82, 82), thicknesses_um=(200, 150, 200))


@pytest.fixture(scope="module")
def tallied(open_design):
    """The ghost analysis, folded LSFs and maps of two pixels, traced once per device,
    in two chunks (one on a GPU); the pilots on the CPU."""
    d = open_design
    s = Sampling(n_rays=1 << (N - 1), seed=5, chunk=1 << (N - 2))
    res = {}
    for dev in ("cpu", "cuda"):
        tr = PixelTracer(d, s, replay=True, device="cpu")  # each chunk traced once
        for px in [(0, 0), (1, 0)]:
            tr.hole_weights(px)  # the pilots (2^18 rays) on the CPU
        tr = tr.with_device(dev)  # the same pilots; the rays, tallied by all three, on dev
        g = analyse_ghosts(d, z_mm=(0.0, 2.0), sampling=s, tracer=tr)
        f = traced_folded_lsf_pair(
            d, z_mm=[0.5, 3.0], periods_um=[169.3, 254.0], sampling=s, tracer=tr, n_batches=4
        )
        m = traced_map_sets(d, z_sets=[[0.5], [1.0, 2.5]], sampling=s, tracer=tr)
        res[dev] = (tr, g, f, m)
    return res


def test_device_tallies_equal_the_cpu_tallies(tallied):
    """With the rays kept on the (simulated) device and tallied there: the ghost analysis
    (every etendue, path, angle range, landing histogram and nearest landing, over two
    chunks), the folded LSFs (all light and own path) and the responsivity maps equal the
    CPU's to rounding for the same seed; no survivor was copied back to the host."""
    (_, gc, fc, mc), (tr, gg, fg, mg) = tallied["cpu"], tallied["cuda"]
    assert tr._replays and all("_host" not in vars(pb.rays) for pb in tr._replays.values())
    assert len(gc.paths) > 10
    _same(gc.to_dict(), gg.to_dict())
    for u, v in zip(fc, fg, strict=True):
        for hu, hv in zip(u.h, v.h, strict=True):
            assert hu.max() > 0
            np.testing.assert_allclose(hv, hu, rtol=1e-12, atol=1e-12 * hu.max())
    for u, v in zip(mc, mg, strict=True):
        assert u.own.sum() > 0 and u.ghost.sum() > 0
        np.testing.assert_allclose(v.own, u.own, rtol=1e-12, atol=1e-12 * u.own.max())
        np.testing.assert_allclose(v.ghost, u.ghost, rtol=1e-12, atol=1e-12 * u.ghost.max())


def test_the_ghost_table_grows_and_hands_back_what_it_cannot_take(open_design, tallied):
    """The hash table of hole sequences doubles until the sequences fit; a batch it cannot
    take (full, or keys beyond int64) goes back to the host, with the same analysis."""
    tr, g, _, _ = tallied["cuda"]
    lat = tr.path.lattice
    args = (next(tr.trace((0, 0))), lat.k_lo, lat.k_hi, tr.n0, [0.0], 84.6, 400, 500.0)
    whole = ct.ghost_tallies(*args)
    assert len(whole.sequences) > 10
    assert ct.ghost_tallies(*args, capacity=2, max_capacity=2) is None  # full: to the host
    assert ct.ghost_tallies(args[0], -(2**40), 2**40, *args[3:]) is None  # beyond int64
    grown = ct.ghost_tallies(*args, capacity=2)  # the table doubled until they fit
    assert grown.sequences == whole.sequences and np.array_equal(grown.count, whole.count)
    np.testing.assert_allclose(grown.s1, whole.s1, rtol=1e-12)
    calls = []
    tally = ct.ghost_tallies

    def every_other(*a, **kw):  # some chunks handed back to the host: the CPU's analysis
        calls.append(1)
        return None if len(calls) % 2 else tally(*a, **kw)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ct, "ghost_tallies", every_other)
        again = analyse_ghosts(open_design, z_mm=(0.0, 2.0), sampling=tr.sampling, tracer=tr)
    assert calls
    _same(g.to_dict(), again.to_dict())


def test_every_kernel_was_launched(recorded):
    """What the compilation test needs: each kernel's arguments as launched (the tests
    above launch them all; this one runs last)."""
    want = {"accept", "fold", "ghost", "importance", "maps", "plain", "plain_queue"}
    assert {f"{k}_kernel" for k in want} <= set(recorded), sorted(recorded)
