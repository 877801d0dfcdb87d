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
from tests.helpers import run_python, source_env

from opticalstamp.device import DeviceUnavailable, resolve_device

ROOT = Path(__file__).resolve().parents[1]

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


#: the simulator's tests: one module, one session (tests/cuda/sim_device.py)
SIM = ROOT / "tests" / "cuda"


def _session(**env) -> subprocess.CompletedProcess:
    """tests/cuda/sim_device.py run by pytest in a process of its own."""
    args = ["-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:warnings"]
    return subprocess.run(
        [sys.executable, *args, "-o", "python_files=sim_*.py", str(SIM)],
        capture_output=True, text=True, cwd=ROOT, timeout=900,
        env=source_env(**env),
    )  # fmt: skip


@pytest.fixture(scope="module")
def simulated_session(tmp_path_factory):
    """The simulator's session, run once: its result and the kernels' arguments it
    recorded."""
    rec = tmp_path_factory.mktemp("cuda") / "args.pkl"
    res = _session(NUMBA_ENABLE_CUDASIM="1", OPTICALSTAMP_TEST_RECORD=str(rec))
    return res, rec


def test_cuda_kernels_and_tallies_under_the_simulator(simulated_session):
    """tests/cuda/sim_device.py under numba's CUDA simulator, in one session: the device
    kernels give the CPU kernel's rays ray for ray (plain and importance sampling, with
    Fresnel losses; hundreds of survivors through opened stacks), the plain kernels queued
    per block or not at all give identical rays, the tallies on the device (ghost
    analysis, folded LSFs, maps) equal the CPU's to rounding, the ghost hash table grows
    and hands back what it cannot take, and provenance names the device."""
    res, _ = simulated_session
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]
    assert " passed" in res.stdout and "failed" not in res.stdout, res.stdout[-2000:]


def _compiler_missing() -> str:
    """Why numba-cuda cannot compile for a GPU here ("" where it can)."""
    if importlib.util.find_spec("numba_cuda") is None:
        return "numba-cuda (the opticalstamp[cuda] extra) is not installed"
    code = (
        "from numba import cuda, float64\n"
        "def k(a):\n    a[0] = 1.0\n"
        "cuda.compile_ptx(k, (float64[:],), cc=(9, 0))\n"
    )
    res = run_python(code)
    return "" if res.returncode == 0 else (res.stderr.strip().splitlines() or ["?"])[-1]


def test_every_cuda_kernel_compiles_for_a_gpu_without_fused_products(tmp_path, simulated_session):
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
    res, rec = simulated_session  # the kernels' arguments, as the simulator launched them
    assert res.returncode == 0 and rec.exists(), res.stdout[-3000:]
    script = tmp_path / "compile.py"
    script.write_text(COMPILE)
    res = subprocess.run(
        [sys.executable, str(script), str(rec)], capture_output=True, text=True, cwd=ROOT,
        env=source_env(), timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    got = {name: (int(f), int(u)) for name, f, u in map(str.split, res.stdout.splitlines())}
    plain = ("plain", "plain_queue", "plain_warp")
    kernels = {"accept", "fold", "ghost", "importance", "maps", "spot", *plain}
    assert set(got) == {f"{k}_kernel" for k in kernels}, got
    for k in ("accept", "fold", "maps", "spot", *plain):  # (fma, fusable products): none
        assert got[f"{k}_kernel"] == (0, 0), got
    # libdevice's cos and sin hold FMAs, but no product of the kernel's own is fusable
    assert got["importance_kernel"][1] == 0, got


#: the simulator session's own kernel (sim_device.ops_kernel), compiled for an H100 with
#: the argument types it is launched with
COMPILE_OPS = """
import sys

import numba
import numpy as np
from numba import cuda
from numba.cuda import dispatcher


class Hopper:
    compute_capability = (9, 0)


dispatcher.get_current_device = lambda: Hopper()
sys.path.insert(0, sys.argv[1])
from opticalstamp.design import load_design
from opticalstamp.raytrace.kernel import seed_key
from opticalstamp.raytrace.launch import _kernel_args
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.sampling import hole_targets
from opticalstamp.raytrace.stack import reverse_path
from tests.cuda import sim_device

d = load_design("paper2016")
path = reverse_path(d)
slabs, n_out, masks, lat, lim = _kernel_args(path)
tg = hole_targets(path, pixel_source(d, 0, 0))
n, nm = 64, masks.shape[0]
args = (seed_key(9), np.zeros(8), np.zeros(8), slabs, n_out, masks, lat, lim, tg.n_pre,
        tg.x, tg.y, tg.prob, tg.alias, tg.q_per_area, np.zeros((n, 15)),
        np.full((n, nm), -1, np.int8), np.zeros((n, nm), np.int32))
sig = tuple(numba.typeof(np.ascontiguousarray(a) if isinstance(a, np.ndarray) else a)
            for a in args)
cuda.compile_ptx(sim_device.ops_kernel.py_func, sig, cc=(9, 0))
print("compiled")
"""


def test_the_simulator_sessions_own_kernel_compiles_for_a_gpu(tmp_path):
    """The session's kernel of per-ray functions (tests/cuda/sim_device.py) compiles for a
    GPU too, not only in the simulator (plain Python): a GPU's compiler refused its first
    version, which indexed a tuple of mixed types with a loop variable (found on an
    H100)."""
    why = _compiler_missing()
    if why:
        pytest.skip(f"numba-cuda cannot compile for a GPU here: {why}")
    script = tmp_path / "compile_ops.py"
    script.write_text(COMPILE_OPS)
    res = subprocess.run(
        [sys.executable, str(script), str(ROOT)], capture_output=True, text=True, cwd=ROOT,
        env=source_env(), timeout=600,
    )  # fmt: skip
    assert res.returncode == 0 and "compiled" in res.stdout, res.stderr[-3000:]


def test_provenance_says_where_the_rays_were_traced():
    """A stamp's results say the device they were traced on (the CPU outside a run that
    chose one; cuda under the simulator: tests/cuda/sim_device.py); a rod-lens array's
    say cpu whatever the device (its GRIN tracer has no GPU kernel), e.g. side by side in a
    comparison."""
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
            env=source_env(OPTICALSTAMP_DEVICE=value),
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
    res = run_python(code)
    assert res.returncode == 0, res.stderr[-2000:]
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert got == {"cuda": False, "device": "cpu"}


@pytest.mark.skipif(resolve_device("auto") != "cuda", reason="needs a CUDA GPU")
def test_on_the_gpu_the_same_rays_and_tallies():  # pragma: no cover - GPU machines
    """The simulator's session on a real GPU, with 2^20 rays: the CPU's survivors ray for
    ray, the queued (per block and per warp) and per-thread kernels identical, the
    tallies equal to rounding."""
    res = _session(RAYS_LOG2="20")
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]


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
