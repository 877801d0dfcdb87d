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
from opticalstamp.analysis.tallies import FoldTally, GhostTally, MapTally, SpotTally
from opticalstamp.design import load_design, with_stack
from opticalstamp.device import DeviceUnavailable, simulated, using_device
from opticalstamp.io.files import provenance
from opticalstamp.raytrace import cuda
from opticalstamp.raytrace.cuda_ray import OPS as DEV
from opticalstamp.raytrace.cuda_ray import cuda as nbcuda
from opticalstamp.raytrace.kernel import OPS as CPU
from opticalstamp.raytrace.kernel import seed_key
from opticalstamp.raytrace.launch import DeviceRayBatch, RayBatch, _kernel_args, launch
from opticalstamp.raytrace.pixel import PixelBatch, PixelTracer, Sampling, pixel_source
from opticalstamp.raytrace.sampling import hole_targets
from opticalstamp.raytrace.stack import reverse_path

#: 2^N samples (the simulator is slow; a GPU takes 20)
N = int(os.environ.get("RAYS_LOG2", "10"))
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
    """The prototype's reverse path with every hole 160 um wide and 800 um tall (beyond
    what a design may hold: the rows' holes overlap in y; in x 9.2-um walls are left
    between neighbours, so the hole test's x edges still stop rays, and width and height
    differ), and its pixel A0: 26 % of plain samples and 40 % of importance-sampled rays
    leave the stack (267 of 1,024 and 204 of 512), own and ghost paths alike (with
    160-um square holes 8 % of plain samples did)."""
    path = reverse_path(paper)
    masks = path.masks.copy()
    masks[:, 1], masks[:, 2] = 80.0, 400.0  # half width and half height (um)
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
    """Plain sampling (1,024 samples) and importance sampling with Fresnel losses (512
    rays): the same survivors (ids), positions, directions and weights (to 1e-12), holes,
    ledger and launched counts as the CPU kernel, for the same seed; hundreds of rays
    survive (267 and 204), own and ghost."""
    path, src = wide
    kw = dict(importance=importance, fresnel=fresnel, chunk=1 << 12, first_id=123)
    cpu = joined(list(launch(path, src, 1 << log2, 7, device="cpu", **kw)))
    own = np.all((cpu["hole_row"] == 0) & (cpu["hole_k"] == 0), axis=1)
    assert cpu["ids"].size > (1 << log2) // 8 and 0 < own.sum() < own.size
    same(cpu, joined(list(launch(path, src, 1 << log2, 7, device="cuda", **kw))))


def test_the_plain_kernels_queued_or_not_give_the_same_rays(wide, monkeypatch):
    """Plain sampling queued per block (the default), per warp (on a GPU) and not at all:
    the same rays, exactly, and the CPU's; with one block, so that each queue fills and
    drains many times (about 53 % of the samples pass the first mask, 26 % all the way)."""
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
    assert passed >= 4 * cuda.THREADS, passed  # the block's queue filled 4 times at least
    a, *others = ({**r.host(), "ledger": r.ledger, "n_launched": r.n_launched} for r in runs)
    assert a["ids"].size > 200, a["ids"].size
    for b in others:
        same(a, b, exact=True)
    kw = dict(importance=False, fresnel=True, chunk=1 << 12, first_id=123, device="cpu")
    same(a, joined(list(launch(path, src, 1 << N, 7, **kw))))


@nbcuda.jit
def ops_kernel(
    key, src, isrc, slabs, n_out, masks, lat, lim, n_pre, tx, ty, tp, ta, tq, res, hr, hk
):
    """Per thread i: ray i's plain draw, its importance draw and the trace of the latter
    with Fresnel losses, by the per-ray functions compiled for the device."""
    i = nbcuda.grid(1)
    if i < res.shape[0]:
        ok, xa, ya, a, c2 = DEV.plain_draw(key, i, src)
        m0 = int(slabs[n_pre - 1, 2])
        x0, y0, sx, sy, w = DEV.importance_draw(
            key, i, isrc, slabs, n_pre, masks[m0, 1], masks[m0, 2], masks[m0, 0] == 1.0, tx,
            ty, tp, ta, tq,
        )  # fmt: skip
        st, pl, xe, ye, we = DEV.trace_one(
            x0, y0, sx, sy, w, slabs, n_out, masks, lat, lim, True, hr, hk, i
        )
        # one store each: a tuple of mixed types cannot be indexed by a loop variable in
        # compiled code (the simulator, plain Python, accepted it; a GPU's compiler not)
        res[i, 0], res[i, 1], res[i, 2], res[i, 3], res[i, 4] = ok, xa, ya, a, c2
        res[i, 5], res[i, 6], res[i, 7], res[i, 8], res[i, 9] = x0, y0, sx, sy, w
        res[i, 10], res[i, 11], res[i, 12], res[i, 13], res[i, 14] = st, pl, xe, ye, we


def test_the_per_ray_functions_are_one_source_on_both_devices(wide):
    """raytrace/rayops.py compiled by numba for the CPU and by numba.cuda for the device,
    run on the same rays (a plain draw, an importance draw through the prototype's hole
    table with the opened stack, its trace with Fresnel losses: positions, directions,
    weights, fates, holes) give the same numbers: exactly under the simulator, to 1e-12 on
    a GPU (libdevice's cos and sin)."""
    path, src = wide
    n = 1 << (N - 3)
    slabs, n_out, masks, lat, lim = _kernel_args(path)
    n0 = float(path.slabs[0, 1])
    tg = hole_targets(path, src)
    d, nn = slabs[: tg.n_pre, 0], slabs[: tg.n_pre, 1]
    n_min = float(nn.min())
    w0 = np.pi * n0 * n0 * src.area
    isrc = np.array([src.x, src.y, src.width, src.height, w0, n0, n_min, (d * n_min / nn).sum()])
    psrc = np.array([src.x, src.y, src.width, src.height, 1.0, n0, n0, 0.0])
    key = seed_key(9)
    table = (tg.x, tg.y, tg.prob, tg.alias, tg.q_per_area)
    nm = masks.shape[0]
    want = np.zeros((n, 15))
    hr, hk = np.full((n, nm), -1, np.int8), np.zeros((n, nm), np.int32)
    for i in range(n):
        p = CPU.plain_draw(key, i, psrc)
        m0 = int(slabs[tg.n_pre - 1, 2])
        hole = (masks[m0, 1], masks[m0, 2], masks[m0, 0] == 1.0)
        q = CPU.importance_draw(key, i, isrc, slabs, tg.n_pre, *hole, *table)
        t = CPU.trace_one(*q, slabs, n_out, masks, lat, lim, True, hr, hk, i)
        want[i] = (*p, *q, *t)
    res = nbcuda.to_device(np.zeros((n, 15)))
    dhr = nbcuda.to_device(np.full((n, nm), -1, np.int8))
    dhk = nbcuda.to_device(np.zeros((n, nm), np.int32))
    args = [nbcuda.to_device(np.ascontiguousarray(a)) for a in (psrc, isrc, slabs, masks, lat)]
    ps, is_, sl, ms, la = args
    ops_kernel[cuda.blocks(n), cuda.THREADS](
        key, ps, is_, sl, n_out, ms, la, nbcuda.to_device(lim), tg.n_pre,
        *(nbcuda.to_device(np.ascontiguousarray(a)) for a in table), res, dhr, dhk,
    )  # fmt: skip
    got = res.copy_to_host()
    fates = want[:, 10]
    assert 0 < want[:, 0].sum() < n and 50 < (fates == 0).sum() < n  # rays and survivors
    assert np.array_equal(got[:, [0, 10, 11]], want[:, [0, 10, 11]])  # draws' fates, planes
    assert np.array_equal(dhr.copy_to_host(), hr) and np.array_equal(dhk.copy_to_host(), hk)
    if simulated():
        assert np.array_equal(got, want)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)


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
    """The prototype with 82-um holes on thin plates: about a quarter of the
    importance-sampled rays leave the stack (263 and 273 of 1,024 for pixels A0 and B0),
    four in five of them through the pixel's own holes."""
    return with_stack(paper, holes_um=(82, 82, 82), thicknesses_um=(200, 150, 200))


@pytest.fixture(scope="module")
def tallied(open_design):
    """The ghost analysis, folded LSFs and maps of two pixels, traced once per device,
    in two chunks (one on a GPU); the pilots on the CPU."""
    d = open_design
    s = Sampling(n_rays=1 << N, seed=5, chunk=1 << (N - 1))  # 1,024 rays: ~270 leave
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


def synthetic_rays(n=600, n_masks=3, seed=11):
    """Rays that no tracer made: positions over +-300 um, directions over the disk
    |s| < 0.98 (some outside the pixel's acceptance), a tenth of the weights 0, holes of
    rows 0/1 and k -2 ... 2 per mask with a third of the rays on the own path (0, 0)."""
    rng = np.random.default_rng(seed)
    rho, phi = 0.98 * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    own = rng.random(n) < 1 / 3
    hole_row = np.where(own[:, None], 0, rng.integers(0, 2, (n, n_masks))).astype(np.int8)
    hole_k = np.where(own[:, None], 0, rng.integers(-2, 3, (n, n_masks))).astype(np.int32)
    w = rng.random(n) * (rng.random(n) > 0.1)
    ledger = np.zeros((5, 4), np.int64)
    ledger[-1, 0] = n
    cols = dict(
        ids=np.sort(rng.choice(10 * n, n, replace=False)).astype(np.int64),
        x=rng.uniform(-300, 300, n), y=rng.uniform(-300, 300, n),
        sx=rho * np.cos(phi), sy=rho * np.sin(phi), w=w, hole_row=hole_row, hole_k=hole_k,
    )  # fmt: skip
    return RayBatch(**cols, ledger=ledger, n_launched=n, n_samples=n), cols


def on_device(cols, ledger, n_samples, seed=12):
    """The rays of ``cols`` kept on the device in a shuffled order (threads append
    survivors in any order), as a GPU's chunk."""
    order = np.random.default_rng(seed).permutation(cols["ids"].size)
    out = np.stack([cols[f][order] for f in ("x", "y", "sx", "sy", "w")], axis=1)
    dev = cuda.DeviceRays(
        order.size, nbcuda.to_device(out), nbcuda.to_device(cols["ids"][order]),
        nbcuda.to_device(cols["hole_row"][order]), nbcuda.to_device(cols["hole_k"][order]),
        ledger, order.size,
    )  # fmt: skip
    return DeviceRayBatch(dev, n_samples)


def test_each_tally_adds_synthetic_rays_alike_on_host_and_device():
    """The four tallies fed the same synthetic rays, once as a host batch and once kept
    on the (simulated) device in another order: folds (all light and own path, two
    batches of ids), maps (two sets of Z), ghost sums (per hole sequence, landings,
    detector, nearest landings, ledger) and spots (all light, the own path, the light
    outside a band: grids, extents, centre cell, total) agree to rounding, counts and
    extents exactly; and each tally is not empty, so the comparison compares something."""
    host, cols = synthetic_rays()
    dev = on_device(cols, host.ledger, host.n_samples)
    pix = dict(row=0, k=0, s2_max=0.6, x0=5.0, y0=-3.0, n_obj=1.0)
    pbs = [PixelBatch(host, **pix), PixelBatch(dev, **pix)]
    assert np.array_equal(pbs[0].w, pbs[1].w) and pbs[0].w.min() == 0.0
    zs, per = [0.0, 0.7], [84.6, 127.0]
    made = []
    for pb in pbs:
        f = FoldTally((True, False), zs, per, 2, pix["x0"], 1.0, host.ids.size)
        m = MapTally(
            [([0.0], -200.0, 8.0, (50, 50)), ([0.3, 1.0], -400.0, 16.0, (50, 50))],
            (-1000.0, -1000.0), 100.0, (20, 20), pix["x0"], pix["y0"], 1.0,
        )  # fmt: skip
        g = GhostTally(3, (0, 0), -4, 4, 1.5, zs, 84.6, 40, 150.0, 5)
        edges = [np.arange(-300.0, 300.5, 6.0), np.arange(-450.0, 450.5, 9.0)]
        sp = [
            SpotTally(zs, edges, [6.0, 9.0], 84.6, ghosts, band)
            for ghosts, band in [(True, None), (False, None), (True, 0.3)]
        ]
        for t in (f, m, g, *sp):
            t.add(pb)
        made.append((f, m, g, sp))
    (fc, mc, gc, sc), (fd, md, gd, sd) = made
    for a, b in zip(sc, sd, strict=True):  # spots: all light, own path, outside a band
        assert b._device is not None and a.total > 0 and np.isfinite(a.lo).all()
        np.testing.assert_allclose(b.total, a.total, rtol=1e-12)
        assert np.array_equal(b.lo, a.lo) and np.array_equal(b.hi, a.hi)
        for u, v in [*zip(a.maps, b.maps, strict=True), (a.inside, b.inside)]:
            assert u.sum() > 0
            np.testing.assert_allclose(v, u, rtol=1e-12, atol=1e-12 * u.max())
    assert sc[1].total < sc[0].total and sc[2].total < sc[0].total  # each tallies its own
    assert fd._device is not None and md._device is not None  # tallied on the device
    for a, b in [*zip(fc.sums, fd.sums, strict=True), *zip(mc.fine, md.fine, strict=True),
                 *zip(mc.coarse, md.coarse, strict=True)]:  # fmt: skip
        assert a.sum() > 0
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12 * a.max())
    assert all(np.isnan(sl).all() for sl in fd.slopes)  # the slopes: host only
    codes = list(gc.sums.keys)  # slots in each tally's own order: compared by code
    assert len(codes) > 20 and sorted(codes) == sorted(gd.sums.keys)
    hs, ds = [gc.sums.keys[c] for c in codes], [gd.sums.keys[c] for c in codes]
    assert np.array_equal(gc.sums.count[hs], gd.sums.count[ds])
    for f in ("s1", "s2", "lo", "hi"):
        a, b = getattr(gc.sums, f)[hs], getattr(gd.sums, f)[ds]
        np.testing.assert_allclose(b, a, rtol=1e-12, err_msg=f)
    for a, b in [(gc.hist, gd.hist), (gc.inside, gd.inside), (gc.inside2, gd.inside2),
                 (gc.nearest[:, hs], gd.nearest[:, ds])]:  # fmt: skip
        fin = np.isfinite(a)
        assert fin.any() and a[fin].max() > 0 and np.array_equal(fin, np.isfinite(b))
        np.testing.assert_allclose(b[fin], a[fin], rtol=1e-12, atol=1e-12 * a[fin].max())
    assert np.array_equal(gc.ledger, gd.ledger) and gc.ledger.sum() == host.ids.size


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
    want = {"accept", "fold", "ghost", "importance", "maps", "plain", "plain_queue", "spot"}
    assert {f"{k}_kernel" for k in want} <= set(recorded), sorted(recorded)
