"""The CUDA backend: its kernels under numba's CUDA simulator give the CPU kernel's rays,
ray for ray; the device switch; the CPU path imports nothing of numba.cuda."""

from __future__ import annotations

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
import numpy as np
from opticalstamp.design import load_design
from opticalstamp.raytrace.launch import launch
from opticalstamp.raytrace.pixel import pixel_source
from opticalstamp.raytrace.stack import reverse_path

d = load_design("paper2016")
path, src = reverse_path(d), pixel_source(d, 0, 0)
cases = [(False, False, 1 << 12), (True, True, 1 << 11)]  # (importance, fresnel, rays)
for importance, fresnel, n in cases:
    kw = dict(importance=importance, fresnel=fresnel, chunk=1 << 12, first_id=123)
    cpu = list(launch(path, src, n, 7, device="cpu", **kw))
    gpu = list(launch(path, src, n, 7, device="cuda", **kw))
    assert len(cpu) == len(gpu)
    for a, b in zip(cpu, gpu):
        assert np.array_equal(a.ids, b.ids), (a.ids.size, b.ids.size)
        for f in ("x", "y", "sx", "sy", "w"):
            np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=1e-12, atol=1e-9)
        assert np.array_equal(a.hole_row, b.hole_row) and np.array_equal(a.hole_k, b.hole_k)
        assert np.array_equal(a.ledger, b.ledger)
        assert (a.n_launched, a.n_samples) == (b.n_launched, b.n_samples)
    print(importance, fresnel, sum(b.ids.size for b in cpu), int(cpu[0].ledger.sum()))
print("same")
"""


def _python(code: str, **env) -> subprocess.CompletedProcess:
    e = os.environ | {"PYTHONPATH": str(ROOT / "src")} | env
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=e, cwd=ROOT, timeout=600
    )


def test_cuda_kernels_under_the_simulator_trace_the_cpu_rays():
    """Plain sampling (4,096 samples) and importance sampling with Fresnel losses (2,048
    rays): the same survivors (ids), positions, directions and weights (to 1e-12), holes,
    ledger and launched counts as the CPU kernel, for the same seed."""
    res = _python(SIMULATED, NUMBA_ENABLE_CUDASIM="1")
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.strip().endswith("same")


def test_device_choice():
    assert resolve_device("cpu") == "cpu"
    with pytest.raises(ValueError, match="device"):
        resolve_device("gpu")
    if os.environ.get("NUMBA_ENABLE_CUDASIM") != "1":
        assert resolve_device("auto") in ("cpu", "cuda")


@pytest.mark.skipif(resolve_device("auto") == "cuda", reason="a CUDA GPU is present")
def test_cuda_refused_without_a_gpu(tmp_path):
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


def test_the_cpu_path_imports_nothing_of_numba_cuda():
    """A traced analysis on the CPU (auto without numba-cuda, or cpu) leaves numba.cuda
    unimported, and its provenance says where the rays were traced."""
    code = (
        "import sys, json\n"
        "from typer.testing import CliRunner\n"
        "from opticalstamp.cli import app\n"
        "r = CliRunner().invoke(app, ['--device', 'cpu', 'ghosts', '--rays', '100000', '--json'])\n"
        "assert r.exit_code == 0, r.output\n"
        "print(json.dumps({'cuda': 'numba.cuda' in sys.modules,"
        " 'device': json.loads(r.stdout)['provenance']['device']}))\n"
    )
    res = _python(code)
    assert res.returncode == 0, res.stderr[-2000:]
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert got == {"cuda": False, "device": "cpu"}


@pytest.mark.skipif(resolve_device("auto") != "cuda", reason="needs a CUDA GPU")
def test_on_the_gpu_the_same_ghost_estimates():  # pragma: no cover - GPU machines only
    """On a real GPU (float64): the ghost analysis gives the CPU's etendues to rounding."""
    from opticalstamp.analysis.ghosts import analyse_ghosts
    from opticalstamp.design import load_design

    d = load_design("paper2016")
    os.environ["OPTICALSTAMP_DEVICE"] = "cpu"
    try:
        cpu = analyse_ghosts(d, n_rays=1 << 22, seed=3)
        os.environ["OPTICALSTAMP_DEVICE"] = "cuda"
        gpu = analyse_ghosts(d, n_rays=1 << 22, seed=3)
    finally:
        os.environ.pop("OPTICALSTAMP_DEVICE", None)
    assert gpu.etendue_own_um2sr == pytest.approx(cpu.etendue_own_um2sr, rel=1e-12)
    assert gpu.etendue_ghost_um2sr == pytest.approx(cpu.etendue_ghost_um2sr, rel=1e-12)
