"""One ray's arithmetic (raytrace/rayops.py), compiled for the CPU: the Newton solve for
the direction that joins two points across layered slabs against its closed form and the
sampling tables' vectorised solve, and the CPU kernels built on the one source. The same
source compiled for CUDA is compared with this one in tests/cuda/sim_device.py."""

from __future__ import annotations

import numpy as np
import pytest

from opticalstamp.design import load_design
from opticalstamp.raytrace import sampling
from opticalstamp.raytrace.kernel import OPS
from opticalstamp.raytrace.stack import reverse_path


def _solve_all(r, slabs, n_pre):
    d, n = slabs[:n_pre, 0], slabs[:n_pre, 1]
    n_min = float(n.min())
    d_eq = float((d * n_min / n).sum())
    return np.array([OPS.solve_rho(float(v), slabs, n_pre, n_min, d_eq) for v in r])


def test_one_slab_has_the_closed_form():
    """Across one slab of thickness d and index n, |s| = n r / sqrt(d^2 + r^2)."""
    slabs = np.array([[700.0, 1.52, -1.0]])
    r = np.array([0.0, 1e-3, 3.0, 80.0, 700.0, 5e3, 1e5])
    want = 1.52 * r / np.hypot(700.0, r)
    np.testing.assert_allclose(_solve_all(r, slabs, 1), want, rtol=1e-14, atol=0)


@pytest.mark.parametrize("design", ["paper2016", "fig1d", "three-layer-single-row"])
def test_the_kernel_solve_and_the_tables_solve_agree_and_reach_r(design):
    """The compiled per-ray solve and the sampling tables' vectorised solve give the same
    |s| (to 1e-14) over lateral distances from 0 to 50 slab thicknesses, and that |s|
    carries the ray exactly r across the slabs before the first mask."""
    path = reverse_path(load_design(design))
    n_pre = path.first_mask_slab + 1
    slabs = np.ascontiguousarray(path.slabs)
    d, n = slabs[:n_pre, 0], slabs[:n_pre, 1]
    r = np.concatenate([[0.0], np.geomspace(1e-3, 50 * d.sum(), 200)])
    got = _solve_all(r, slabs, n_pre)
    np.testing.assert_allclose(got, sampling.solve_rho(r, d, n), rtol=1e-14, atol=1e-300)
    assert np.all((got >= 0) & (got < n.min()))
    reach = np.array([OPS.reach(g, slabs, n_pre)[0] for g in got])
    np.testing.assert_allclose(reach, r, rtol=1e-12, atol=1e-9)


def test_trace_one_through_one_slab_lands_where_snell_says():
    """A ray through one glass slab into air: lands at x + d s / sqrt(n^2 - s^2); with
    Fresnel losses its weight is the closed-form unpolarised transmittance."""
    slabs = np.array([[1000.0, 1.5, -1.0]])
    hrow = np.zeros((1, 1), np.int8)
    hk = np.zeros((1, 1), np.int32)
    lim = np.array([1e9, 1e9])
    masks = np.zeros((1, 5))
    lat = np.zeros(8)
    sx = 0.6
    st, pl, x, y, w = OPS.trace_one(
        0.0, 0.0, sx, 0.0, 1.0, slabs, 1.0, masks, lat, lim, True, hrow, hk, 0
    )
    c1 = np.sqrt(1.5**2 - sx**2) / 1.5
    c2 = np.sqrt(1.0 - sx**2)
    rs = (1.5 * c1 - c2) / (1.5 * c1 + c2)
    rp = (c1 - 1.5 * c2) / (c1 + 1.5 * c2)
    assert st == 0 and pl == 0 and y == 0.0
    assert x == pytest.approx(1000.0 * sx / np.sqrt(1.5**2 - sx**2), rel=1e-15)
    assert w == pytest.approx(0.5 * ((1 - rs**2) + (1 - rp**2)), rel=1e-15)


def test_the_cached_kernels_name_the_per_ray_source_they_inline():
    """numba caches kernel.py's and cuda.py's kernels by their own files' timestamps, not
    by rayops.py's, whose functions they inline: each names rayops.py's hash, so that an
    edit of rayops.py must edit them too (and their cached kernels are compiled again)."""
    import hashlib
    from pathlib import Path

    from opticalstamp.raytrace import kernel

    src = Path(kernel.__file__).parent
    sha = hashlib.sha256((src / "rayops.py").read_bytes()).hexdigest()[:16]
    assert kernel.RAYOPS_SHA == sha, "rayops.py changed: update RAYOPS_SHA in kernel.py"
    cuda_text = (src / "cuda.py").read_text()
    assert f'RAYOPS_SHA = "{sha}"' in cuda_text, "rayops.py changed: update it in cuda.py"
