"""The CUDA backend: its kernels under numba's CUDA simulator give the CPU kernel's rays,
ray for ray; the device switch; the CPU path imports nothing of numba.cuda."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from tests.edges import assert_clean_refusal, run

from opticalstamp.device import DeviceUnavailable, resolve_device

ROOT = Path(__file__).resolve().parents[1]

SIMULATED = """
import os

import numpy as np
from opticalstamp.design import load_design
from opticalstamp.device import DeviceUnavailable
from opticalstamp.raytrace import cuda
from opticalstamp.raytrace.kernel import seed_key
from opticalstamp.raytrace.launch import _kernel_args, launch
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.stack import reverse_path

N = int(os.environ.get("RAYS_LOG2", "12"))  # 2^N samples (the simulator is slow)
d = load_design("paper2016")
path, src = reverse_path(d), pixel_source(d, 0, 0)
FIELDS = ("ids", "x", "y", "sx", "sy", "w", "hole_row", "hole_k")


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


cases = [(False, False, 1 << N), (True, True, 1 << (N - 1))]  # (importance, fresnel, rays)
for importance, fresnel, n in cases:
    kw = dict(importance=importance, fresnel=fresnel, chunk=1 << 12, first_id=123)
    cpu = joined(list(launch(path, src, n, 7, device="cpu", **kw)))
    same(cpu, joined(list(launch(path, src, n, 7, device="cuda", **kw))))
    print(importance, fresnel, cpu["ids"].size, int(cpu["ledger"].sum()))
# plain sampling queued per block, per warp (on a GPU) and not at all: the same rays, exactly
n0 = float(path.slabs[0, 1])
args = np.array([src.x, src.y, src.width, src.height, 4 * n0 * n0 * src.area, n0, n0, 0.0])
n_pre = path.first_mask_slab + 1
simulated = os.environ.get("NUMBA_ENABLE_CUDASIM") == "1"
queues = ("block",) if simulated else ("block", "warp")

runs = [
    cuda.run(123, 1 << N, seed_key(7), args, _kernel_args(path), True, n_pre, None, queue=q)
    for q in ("none", *queues)
]
a, *others = ({**r.host(), "ledger": r.ledger, "n_launched": r.n_launched} for r in runs)
for b in others:
    same(a, b, exact=True)
kw = dict(importance=False, fresnel=True, chunk=1 << 12, first_id=123, device="cpu")
same(a, joined(list(launch(path, src, 1 << N, 7, **kw))))
# each queue filled and drained many times: one block, and a first mask opened so wide
# that most rays from the pixel's centre pass it
cuda.QUEUE_BLOCKS = 1
kargs = list(_kernel_args(path))
kargs[2] = kargs[2].copy()
kargs[2][int(path.slabs[n_pre - 1, 2]), 1:3] = 80.0  # half width and height (um)
point = np.array([src.x, src.y, 1e-3, 1e-3, args[4], n0, n0, 0.0])
runs = [
    cuda.run(5, 1 << 13, seed_key(3), point, tuple(kargs), True, n_pre, None, queue=q)
    for q in ("none", *queues)
]
passed = runs[0].n_launched - int(runs[0].ledger[:n_pre].sum())
assert passed > 8 * cuda.THREADS, passed
a, *others = ({**r.host(), "ledger": r.ledger, "n_launched": r.n_launched} for r in runs)
assert a["ids"].size > 5, a["ids"].size  # survivors through the rest of the stack
for b in others:
    same(a, b, exact=True)
# a stack beyond the kernels' fixed-size arrays: refused, naming the way out
big = list(_kernel_args(path))
big[2] = np.repeat(big[2], 6, axis=0)  # 18 masks
try:
    cuda.run(0, 256, seed_key(1), args, tuple(big), False, n_pre)
    raise SystemExit("18 masks not refused")
except DeviceUnavailable as err:
    assert "--device cpu" in str(err), err
# the device of a run: named, or scoped, in the provenance
from opticalstamp.device import using_device
from opticalstamp.io.files import provenance

assert provenance(d, 0, device="cuda")["device"] == "cuda"
with using_device("cuda"):
    assert provenance(d, 0)["device"] == "cuda"
    assert provenance(load_design("sla-1row-12deg"), 0)["device"] == "cpu"
assert provenance(d, 0)["device"] == "cpu"
print("same")
"""

TALLIES = """
import os
import numpy as np
from opticalstamp.analysis import cuda_tallies as ct
from opticalstamp.analysis.cuda_tallies import ghost_tallies
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.lsf import traced_folded_lsf_pair
from opticalstamp.analysis.maps import traced_map_sets
from opticalstamp.design import load_design
from opticalstamp.raytrace import cuda
from opticalstamp.raytrace.pixel import PixelTracer, Sampling

d = load_design("paper2016")
N = int(os.environ.get("RAYS_LOG2", "12"))  # 2^(N+1) rays (the simulator is slow)
s = Sampling(n_rays=1 << (N + 1), seed=5, chunk=1 << N)  # two chunks (one on a GPU)
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
    res[dev] = (g, f, m)
    if dev == "cuda":  # every tally was taken on the device: no survivor was copied back
        assert tr._replays and all("_host" not in vars(pb.rays) for pb in tr._replays.values())


def same(x, y, where=""):
    if isinstance(x, dict):
        assert x.keys() == y.keys(), where
        for k in x:
            same(x[k], y[k], f"{where}/{k}")
    elif isinstance(x, list | tuple):
        assert len(x) == len(y), where
        for i, (p, q) in enumerate(zip(x, y)):
            same(p, q, f"{where}[{i}]")
    elif isinstance(x, float):
        assert np.isclose(x, y, rtol=1e-12, atol=0), (where, x, y)
    else:
        assert x == y, (where, x, y)


(gc, fc, mc), (gg, fg, mg) = res["cpu"], res["cuda"]
a, b = gc.to_dict(), gg.to_dict()
assert len(gc.paths) > 10
same(a, b)
for u, v in zip(fc, fg, strict=True):
    for hu, hv in zip(u.h, v.h, strict=True):
        np.testing.assert_allclose(hv, hu, rtol=1e-12, atol=1e-12 * hu.max())
for u, v in zip(mc, mg, strict=True):
    assert u.own.sum() > 0 and u.ghost.sum() > 0
    np.testing.assert_allclose(v.own, u.own, rtol=1e-12, atol=1e-12 * u.own.max())
    np.testing.assert_allclose(v.ghost, u.ghost, rtol=1e-12, atol=1e-12 * u.ghost.max())
print("same")
lat = tr.path.lattice
args = (next(tr.trace((0, 0))), lat.k_lo, lat.k_hi, tr.n0, [0.0], 84.6, 400, 500.0)
whole = ghost_tallies(*args)
assert len(whole.sequences) > 10
assert ghost_tallies(*args, capacity=2, max_capacity=2) is None  # full: back to the host
assert ghost_tallies(args[0], -(2**40), 2**40, *args[3:]) is None  # keys beyond int64
grown = ghost_tallies(*args, capacity=2)  # the table doubled until the sequences fit
assert grown.sequences == whole.sequences and np.array_equal(grown.count, whole.count)
np.testing.assert_allclose(grown.s1, whole.s1, rtol=1e-12)
# some chunks handed back to the host (every other one): the CPU's analysis again
calls = []


def every_other(*a, **kw):
    calls.append(1)
    return None if len(calls) % 2 else ghost_tallies(*a, **kw)


ct.ghost_tallies = every_other
same(a, analyse_ghosts(d, z_mm=(0.0, 2.0), sampling=s, tracer=tr).to_dict())
assert calls
print("full")
"""

RECORD = """
import os
import pickle
import sys

import numpy as np
from opticalstamp.analysis import cuda_tallies as ct
from opticalstamp.analysis.ghosts import analyse_ghosts
from opticalstamp.analysis.lsf import traced_folded_lsf_pair
from opticalstamp.analysis.maps import traced_map_sets
from opticalstamp.design import load_design
from opticalstamp.raytrace import cuda as rc
from opticalstamp.raytrace.kernel import seed_key
from opticalstamp.raytrace.launch import _kernel_args
from opticalstamp.raytrace.pixel import PixelTracer, Sampling, pixel_source

seen = {}


class Recorder:  # each kernel's arguments as launched (host copies), then the launch
    def __init__(self, name, kernel):
        self.name, self.kernel = name, kernel

    def __getitem__(self, config):
        def call(*args):
            host = [a.copy_to_host() if hasattr(a, "copy_to_host") else a for a in args]
            seen.setdefault(self.name, host)
            return self.kernel[config](*args)

        return call


for mod in (rc, ct):
    for name in [n for n in dir(mod) if n.endswith("_kernel")]:
        setattr(mod, name, Recorder(name, getattr(mod, name)))
d = load_design("paper2016")
tr = PixelTracer(d, Sampling(n_rays=1 << 12, seed=1, chunk=1 << 12), replay=True, device="cpu")
tr.hole_weights((0, 0))  # the pilot (2^18 rays) on the CPU
tr = tr.with_device("cuda")  # the same pilot, the rays on the (simulated) device
analyse_ghosts(d, z_mm=(0.0,), sampling=tr.sampling, tracer=tr)
traced_map_sets(d, z_sets=[[1.0]], sampling=tr.sampling, tracer=tr)
path, src = tr.path, pixel_source(d, 0, 0)
n0 = float(path.slabs[0, 1])
v = np.array([src.x, src.y, src.width, src.height, 4 * n0 * n0 * src.area, n0, n0, 0.0])
for queue in ("block", "none"):
    rc.run(0, 256, seed_key(1), v, _kernel_args(path), True, path.first_mask_slab + 1, queue=queue)
pb = next(tr.trace((0, 0)))
res = ct.zeros((1, 1, 1, 338))
ct.fold(pb, False, [1000.0], 1.0, [169.3], [338], 1, res)
pickle.dump(seen, open(sys.argv[1], "wb"))
print(sorted(seen))
"""

COMPILE = """
import pickle
import re
import sys

import numba
from numba import cuda
from numba.cuda import dispatcher


class Hopper:  # device functions compile for "the current device": an H100 here
    compute_capability = (9, 0)


dispatcher.get_current_device = lambda: Hopper()
from opticalstamp.analysis import cuda_tallies as ct
from opticalstamp.raytrace import cuda as rc

launched = pickle.load(open(sys.argv[1], "rb"))
launched["plain_warp_kernel"] = launched["plain_queue_kernel"]  # not under the simulator
for name, args in sorted(launched.items()):
    kernel = getattr(rc, name, None) or getattr(ct, name)
    sig = tuple(numba.typeof(a) for a in args)
    ptx, _ = cuda.compile_ptx(kernel.py_func, sig, cc=(9, 0))
    # what ptxas may still fuse: a product not rounded on its own (mul.f64, not mul.rn)
    # whose result (directly or through mov) feeds a sum
    prod = set(re.findall(r"mul\\.f64\\s+(%fd\\d+)", ptx))
    for dst, src in re.findall(r"mov\\.f64\\s+(%fd\\d+),\\s*(%fd\\d+);", ptx):
        if src in prod:
            prod.add(dst)
    sums = re.findall(
        r"^\\s*(?:add|sub)(?:\\.rn)?\\.f64\\s+%fd\\d+,\\s*([^,]+),\\s*([^;]+);", ptx, re.M
    )
    fusable = sum(a.strip() in prod or b.strip() in prod for a, b in sums)
    print(name, ptx.count("fma.rn.f64"), fusable)
"""


def _python(code: str, **env) -> subprocess.CompletedProcess:
    e = os.environ | {"PYTHONPATH": str(ROOT / "src")} | env
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=e, cwd=ROOT, timeout=600
    )


def test_cuda_kernels_under_the_simulator_trace_the_cpu_rays():
    """Plain sampling (4,096 samples) and importance sampling with Fresnel losses (2,048
    rays): the same survivors (ids), positions, directions and weights (to 1e-12), holes,
    ledger and launched counts as the CPU kernel, for the same seed; the plain kernel
    queued per block (the default) and the one-thread-per-ray one give identical rays (and
    the one queued per warp, on a GPU)."""
    res = _python(SIMULATED, NUMBA_ENABLE_CUDASIM="1")
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip().endswith("same")


def test_device_tallies_under_the_simulator_equal_the_cpu_tallies():
    """With the rays kept on the (simulated) device and tallied there: the ghost analysis
    (every etendue, path, angle range, landing histogram and nearest landing, over two
    chunks), the folded LSFs (all light and own path) and the responsivity maps equal the
    CPU's to rounding for the same seed; the hash table of hole sequences grows while it
    fills, and a batch it cannot take goes back to the host, with the same analysis."""
    res = _python(TALLIES, NUMBA_ENABLE_CUDASIM="1")
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.split()[-2:] == ["same", "full"], res.stdout


def _compiler_missing() -> str:
    """Why numba-cuda cannot compile for a GPU here ("" where it can)."""
    if importlib.util.find_spec("numba_cuda") is None:
        return "numba-cuda (the opticalstamp[cuda] extra) is not installed"
    code = (
        "from numba import cuda, float64\n"
        "def k(a):\n    a[0] = 1.0\n"
        "cuda.compile_ptx(k, (float64[:],), cc=(9, 0))\n"
    )
    res = _python(code)
    return "" if res.returncode == 0 else (res.stderr.strip().splitlines() or ["?"])[-1]


def test_every_cuda_kernel_compiles_for_a_gpu_without_fused_products(tmp_path):
    """What the simulator cannot check: each kernel, with the argument types it is
    launched with, compiles to PTX for an H100 (sm_90) with numba-cuda; and the kernels
    free of transcendental functions contain no fused multiply-add, so that their
    products are rounded as on the CPU (the libdevice cos, sin, asin and hypot that the
    importance and ghost kernels call use FMAs of their own). Checked in the PTX: no
    fma, and no product left for the assembler to fuse (a ``mul.f64`` that is not
    ``mul.rn`` feeding an add or a subtraction); in the importance kernel, none of the
    latter either."""
    why = _compiler_missing()
    if why:
        pytest.skip(f"numba-cuda cannot compile for a GPU here: {why}")
    rec = tmp_path / "args.pkl"
    script = tmp_path / "record.py"
    script.write_text(RECORD)
    res = subprocess.run(
        [sys.executable, str(script), str(rec)], capture_output=True, text=True, cwd=ROOT,
        env=os.environ | {"PYTHONPATH": str(ROOT / "src"), "NUMBA_ENABLE_CUDASIM": "1"},
        timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    script = tmp_path / "compile.py"
    script.write_text(COMPILE)
    res = subprocess.run(
        [sys.executable, str(script), str(rec)], capture_output=True, text=True, cwd=ROOT,
        env=os.environ | {"PYTHONPATH": str(ROOT / "src")}, timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    got = {name: (int(f), int(u)) for name, f, u in map(str.split, res.stdout.splitlines())}
    plain = ("plain", "plain_queue", "plain_warp")
    kernels = {"accept", "fold", "ghost", "importance", "maps", *plain}
    assert set(got) == {f"{k}_kernel" for k in kernels}, got
    for k in ("accept", "fold", "maps", *plain):  # (fma, fusable products): none
        assert got[f"{k}_kernel"] == (0, 0), got
    # libdevice's cos and sin hold FMAs, but no product of the kernel's own is fusable
    assert got["importance_kernel"][1] == 0, got


def test_provenance_says_where_the_rays_were_traced():
    """A stamp's results say the device they were traced on (the CPU outside a run that
    chose one; cuda under the simulator: SIMULATED); a rod-lens array's say cpu whatever
    the device (its GRIN tracer has no GPU kernel), e.g. side by side in a comparison."""
    from opticalstamp.design import load_design
    from opticalstamp.device import using_device
    from opticalstamp.io.files import provenance

    stamp, rod = load_design("paper2016"), load_design("sla-1row-12deg")
    assert provenance(stamp, 0)["device"] == "cpu"
    assert provenance(rod, 0, device="cuda")["device"] == "cpu"
    with using_device("cpu"):
        assert provenance(stamp, 0)["device"] == "cpu"
    assert provenance(stamp, None, traced=False)["device"] is None


def test_device_choice():
    assert resolve_device("cpu") == "cpu"
    with pytest.raises(ValueError, match="device"):
        resolve_device("gpu")
    if os.environ.get("NUMBA_ENABLE_CUDASIM") != "1":
        assert resolve_device("auto") in ("cpu", "cuda")


@pytest.mark.skipif(resolve_device("auto") == "cuda", reason="a CUDA GPU is present")
def test_cuda_refused_without_a_gpu(tmp_path, monkeypatch):
    monkeypatch.setenv("OPTICALSTAMP_DEVICE", "auto")  # --device sets it: undone after
    with pytest.raises(DeviceUnavailable, match="device cuda"):
        resolve_device("cuda")
    res = run(["--device", "cuda", "ghosts", "--rays", "100000"])
    assert_clean_refusal(res, ("--device",))
    assert_clean_refusal(run(["--device", "tpu", "ghosts"]), ("--device",))
    for value in ("cuda", "tpu"):  # from the environment: named as such, no traceback
        res = subprocess.run(
            [sys.executable, "-c", "from opticalstamp.cli import main; main()", "ghosts"],
            capture_output=True, text=True, cwd=ROOT, timeout=120,
            env=os.environ | {"OPTICALSTAMP_DEVICE": value, "PYTHONPATH": str(ROOT / "src")},
        )  # fmt: skip
        assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
        assert "OPTICALSTAMP_DEVICE" in res.stderr


@pytest.mark.skipif(resolve_device("auto") == "cuda", reason="a CUDA GPU is present")
def test_cuda_checked_where_rays_are_traced(tmp_path, monkeypatch):
    """``--device cuda`` without a GPU still shows help and runs the commands that trace
    nothing (their provenance has no device); without numba-cuda, the refusal says how to
    install it."""
    import importlib.util

    monkeypatch.setenv("OPTICALSTAMP_DEVICE", "auto")  # --device sets it: undone after
    assert run(["--device", "cuda", "ghosts", "--help"]).exit_code == 0
    assert run(["--device", "cuda", "presets"]).exit_code == 0
    res = run(["--device", "cuda", "show", "paper2016", "--json"])
    assert res.exit_code == 0 and json.loads(res.stdout)["provenance"]["device"] is None
    find = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda n, *a: None if n == "numba_cuda" else find(n, *a)
    )
    with pytest.raises(DeviceUnavailable, match=r"numba-cuda is not installed.*\[cuda\]"):
        resolve_device("cuda")


@pytest.mark.parametrize("device", ["cpu", "auto"])
def test_the_cpu_path_imports_nothing_of_numba_cuda(device):
    """A traced analysis on the CPU (cpu; auto on a machine without an NVIDIA driver, even
    with numba-cuda installed) leaves numba.cuda unimported, and its provenance says where
    the rays were traced."""
    from opticalstamp.device import _driver_found

    if device == "auto" and _driver_found():
        pytest.skip("an NVIDIA driver is installed: auto asks numba.cuda for a GPU")
    code = (
        "import sys, json\n"
        "from typer.testing import CliRunner\n"
        "from opticalstamp.cli import app\n"
        f"args = ['--device', '{device}', 'ghosts', '--rays', '100000', '--json']\n"
        "r = CliRunner().invoke(app, args)\n"
        "assert r.exit_code == 0, r.output\n"
        "print(json.dumps({'cuda': 'numba.cuda' in sys.modules,"
        " 'device': json.loads(r.stdout)['provenance']['device']}))\n"
    )
    res = _python(code)
    assert res.returncode == 0, res.stderr[-2000:]
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert got == {"cuda": False, "device": "cpu"}


@pytest.mark.skipif(resolve_device("auto") != "cuda", reason="needs a CUDA GPU")
@pytest.mark.parametrize("script", ["SIMULATED", "TALLIES"])
def test_on_the_gpu_the_same_rays_and_tallies(script):  # pragma: no cover - GPU machines
    """The simulator tests above on a real GPU, with 2^20 rays: the CPU's survivors ray for
    ray, the queued and per-thread kernels identical, the tallies equal to rounding."""
    res = _python(globals()[script], RAYS_LOG2="20")
    assert res.returncode == 0, res.stderr[-3000:]
    assert "same" in res.stdout.split(), res.stdout


@pytest.mark.skipif(resolve_device("auto") != "cuda", reason="needs a CUDA GPU")
def test_on_the_gpu_the_same_ghost_estimates():  # pragma: no cover - GPU machines only
    """On a real GPU (float64): the ghost analysis gives the CPU's etendues to rounding."""
    from opticalstamp.analysis.ghosts import analyse_ghosts
    from opticalstamp.design import load_design
    from opticalstamp.raytrace.pixel import PixelTracer

    d = load_design("paper2016")
    cpu = analyse_ghosts(d, n_rays=1 << 22, seed=3, tracer=PixelTracer(d, device="cpu"))
    gpu = analyse_ghosts(d, n_rays=1 << 22, seed=3, tracer=PixelTracer(d, device="cuda"))
    assert gpu.etendue_own_um2sr == pytest.approx(cpu.etendue_own_um2sr, rel=1e-12)
    assert gpu.etendue_ghost_um2sr == pytest.approx(cpu.etendue_ghost_um2sr, rel=1e-12)
