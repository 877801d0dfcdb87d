"""The 2-D path's stack operator (issue 23's speed): its own coarser grid over the same
period, its transforms in batches in reused memory, the range finder's Gram-Schmidt and
the marginal's Gram product (:mod:`opticalstamp.analysis.wave2d`,
:mod:`opticalstamp.analysis.arrays`)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest

from opticalstamp.analysis import arrays, wave2d, wavebase
from opticalstamp.analysis.wave2dlsf import lsf_source_2d
from test_wave import _stack

ZS = (0.0, 0.4)


@pytest.fixture(scope="module")
def circles():
    d = _stack((10.0, 10.0, 12.0), shape="circle", offsets=[(1.5, -1.0), (0, 0), (-2.0, 0.7)])
    return d, wavebase.wave_sampling(d, band=0.2).refined(margin=0.5)


def _lsfs(src):
    x, lsf, light, _ = src.lsf_x(ZS)
    return lsf, light


@pytest.mark.parametrize("propagator", ["exact", "paraxial"])
def test_operator_grid_gives_the_sampling_grids_figures(circles, monkeypatch, propagator):
    """The operator on its coarser grid (the fewest points that keep the in-band part of
    a field times a mask free of aliases) gives the figures of the operator on the
    sampling's grid: in double precision to 1e-11 of the peak with the exact propagator
    (the same in-band sources: measured 2e-13), to 1e-7 with the paraxial one (whose
    sources are the closed forms sampled on each grid: their tails alias differently,
    measured 2e-8)."""
    d, smp = circles
    lam, b = smp.wavelength_um, smp.band
    st, _ = wave2d._stack(d, (0, 0), smp, propagator)
    assert st.gx.size < 0.75 * st.x.size and st.gy.size < 0.75 * st.y.size
    assert st.gx.size * (st.gx[1] - st.gx[0]) == pytest.approx(st.x.size * (st.x[1] - st.x[0]))
    kw = {"sampling": smp, "propagator": propagator, "fresnel": True, "precision": "double"}
    coarse_src = lsf_source_2d(d, max(ZS), **kw)
    coarse = _lsfs(coarse_src)
    monkeypatch.setattr(wave2d, "operator_grid", lambda x, lam, band: x)
    fine_src = lsf_source_2d(d, max(ZS), **kw)
    fine = _lsfs(fine_src)
    tol = 1e-11 if propagator == "exact" else 1e-7
    assert np.abs(coarse[0] - fine[0]).max() < tol * fine[0].max()
    assert coarse[1] == pytest.approx(fine[1], rel=tol)
    for key in ("in_band", "lost_to_band"):  # the power sums on the coarser grid too
        assert coarse_src.meta[key] == pytest.approx(fine_src.meta[key], rel=tol), key
    # a grid well short of the rule (2m + M / 2: the mask's upper half of frequencies
    # folds into the band) aliases the in-band part: the comparison can fail (at the
    # rule's edge itself the aliased terms are the band edge's weakest, too weak to show)
    m, _, big = _rule(st.x, lam, b)
    n = 2 * m + big // 2

    def short_grid(g, lam, band):
        return g[0] + np.arange(n) * (g.size * (g[1] - g[0]) / n)

    monkeypatch.setattr(wave2d, "operator_grid", short_grid)
    short = _lsfs(lsf_source_2d(d, max(ZS), **kw))
    assert np.abs(short[0] - fine[0]).max() > 100 * tol * fine[0].max()


def _rule(x, lam, b) -> tuple[int, int, int]:
    """2m + M + 1 as (m, m, M + 1) from the grid's bins, independently of the code."""
    n, dx = x.size, x[1] - x[0]
    f = np.abs(np.fft.fftfreq(n, dx))
    m = round(f[np.abs(lam * f) < b * (1 - 1e-9)].max() * n * dx)
    big = round(f[np.abs(lam * f) <= 2 * b].max() * n * dx)
    return m, m, big + 1


def test_operator_grid_rule():
    """n > 2m + M and n > 2M (m the largest in-band bin, M the mask's): the 5-smooth
    length at or above it, and never more points than the sampling's grid."""
    x = np.arange(1650) * 0.46312458382627697
    lam, b = 0.55, 0.19793090211132439
    n, dx = x.size, x[1] - x[0]
    m, _, big = _rule(x, lam, b)
    big -= 1
    g = wave2d.operator_grid(x, lam, b)
    assert max(2 * m + big, 2 * big) < g.size <= 1.05 * max(2 * m + big + 1, 2 * big + 1)
    assert g[0] == x[0] and g.size * (g[1] - g[0]) == pytest.approx(n * dx)
    few = np.arange(g.size - 2) * (n * dx / (g.size - 2))  # already below the rule: kept
    assert wave2d.operator_grid(few, lam, b) is few


@pytest.mark.parametrize("propagator,fresnel", [("exact", False), ("paraxial", True)])
def test_batches_give_the_whole_blocks_operator(circles, propagator, fresnel):
    """The operator pushed through in the CPU's batches (work arrays reused) gives what
    one batch of the whole block gives (no work arrays), forward (with the power beyond
    the band) and adjoint, to the last bits of double precision; threads sharing the
    operator get the same (their work arrays are their own); and the adjoint is the
    forward's, with the exact and the paraxial first step, with and without the filter
    above the top mask."""
    d, smp = circles
    rng = np.random.default_rng(1)
    st, _ = wave2d._stack(d, (0, 0), smp, propagator, fresnel=fresnel, precision="double")
    assert (st.top is not None) == fresnel and (st.first is not None) == (propagator == "exact")
    w = rng.standard_normal((5, *st.sources)) + 0j
    assert 1 < st.bk.batch < 5  # 5 fields: whole batches and a part
    one, lost1 = st.forward(w, with_power=True)
    back1 = st.adjoint(one)
    with ThreadPoolExecutor(4) as pool:
        side = list(pool.map(lambda i: st.forward(w, with_power=True)[0], range(8)))
    assert all(np.array_equal(a, one) for a in side)
    st.bk = replace(st.bk, batch=0)
    two, lost2 = st.forward(w, with_power=True)
    back2 = st.adjoint(two)
    assert np.abs(one - two).max() <= 1e-12 * np.abs(two).max()
    assert np.abs(lost1 - lost2).max() <= 1e-12 * np.abs(lost2).max()
    assert np.abs(back1 - back2).max() <= 1e-12 * np.abs(back2).max()
    # <A w, v> = <w, A^H v>
    v = rng.standard_normal(one.shape) + 1j * rng.standard_normal(one.shape)
    lhs, rhs = np.vdot(v, st.forward(w)), np.vdot(st.adjoint(v), w)
    assert lhs == pytest.approx(rhs, rel=1e-10)


def test_in_band_runs_refuse_other_bins():
    """The in-band bins as their two runs, and a refusal where they are not."""
    assert wave2d.in_band_runs(np.array([0, 1, 2, 9, 10]), 11) == (3, 2)
    assert wave2d.in_band_runs(np.arange(4), 10) == (4, 0)
    with pytest.raises(ValueError, match="runs"):
        wave2d.in_band_runs(np.array([0, 1, 2, 8, 9]), 11)


def test_project_out_orthogonalises_in_one_or_two_passes():
    """Rows nearly in the span found get a second pass (orthogonal to 1e-13 of what they
    keep), rows far from it one (the same result as two, to rounding)."""
    rng = np.random.default_rng(2)
    q, _ = np.linalg.qr(rng.standard_normal((400, 24)) + 1j * rng.standard_normal((400, 24)))
    rows = q.T.copy()
    coef = rng.standard_normal((3, 24)) + 1j * rng.standard_normal((3, 24))
    noise = rng.standard_normal((3, 400)) + 1j * rng.standard_normal((3, 400))
    for eps in (1.0, 1e-9):  # far from the span, then 1e-9 of the norm outside it
        y = coef @ q.T + eps * noise
        r = wave2d._project_out(np, y, rows)
        exact = noise * eps - (noise * eps) @ q.conj() @ q.T
        assert np.abs(r - exact).max() < 1e-13 * np.abs(y).max()
        assert np.abs(r @ q.conj()).max() < 1e-13 * np.linalg.norm(r, axis=1).max() / eps**0.5
    assert wave2d._project_out(np, y, rows[:0]) is y


def test_the_basis_rows_grow_as_their_blocks_joined():
    """The range finder's basis (rows added block by block to one array that doubles its
    room) holds the blocks' rows as their concatenation, whatever the blocks' sizes, and
    an empty basis has no rows."""
    rng = np.random.default_rng(5)
    rows = wave2d._Rows(np)
    assert rows.rows.shape[0] == 0 and rows.rank == 0
    blocks = [rng.standard_normal((k, 7)) + 1j * rng.standard_normal((k, 7)) for k in
              (3, 16, 1, 16, 40, 0, 5)]  # fmt: skip
    for b in blocks:
        rows.add(b)
    assert rows.rank == 81 and rows.a.shape[0] >= 81
    assert np.array_equal(rows.rows, np.concatenate(blocks))


def test_gram_t_is_the_product():
    """The CPU's Hermitian Gram product (zherk) equals a^T conj(a)."""
    rng = np.random.default_rng(3)
    a = rng.standard_normal((300, 40)) + 1j * rng.standard_normal((300, 40))
    g = arrays.CPU.gram_t(a)
    assert np.abs(g - a.T @ a.conj()).max() < 1e-12 * np.abs(g).max()
    assert np.allclose(g, g.conj().T)


def test_add_abs2_on_a_window_of_a_transformed_array():
    """acc += |u|^2 in one pass (the maps' accumulation), on a strided window of a
    complex64 array as the maps take it: the sum of the squares in float32 to the bit."""
    rng = np.random.default_rng(4)
    w = (rng.standard_normal((7, 40)) + 1j * rng.standard_normal((7, 40))).astype(np.complex64)
    u = w[:, 5:31]
    acc = rng.standard_normal(u.shape).astype(np.float32)
    want = acc + (np.square(u.real) + np.square(u.imag))
    arrays.CPU.add_abs2(acc, u)
    assert acc.dtype == np.float32 and np.array_equal(acc, want)


def test_gather_and_scatter_move_the_in_band_bins_as_their_runs():
    """The in-band bins taken out of an axis and put back (the operator's and the maps'
    pruned transforms) as the fancy indexing by the bins does it, 0 between the runs,
    into work arrays given or new ones."""
    from opticalstamp.analysis.wave2dop import gather_bins, scatter_bins

    rng = np.random.default_rng(5)
    n, k = 12, np.array([0, 1, 2, 10, 11])
    runs = wave2d.in_band_runs(k, n)
    a = rng.standard_normal((3, n, 4)) + 1j * rng.standard_normal((3, n, 4))
    got = gather_bins(np, a, runs, -2)
    assert np.array_equal(got, a[:, k, :])
    out = np.full((3, k.size, 4), np.nan + 0j)
    assert gather_bins(np, a, runs, -2, out=out) is out and np.array_equal(out, got)
    want = np.zeros_like(a)
    want[:, k, :] = got
    work = np.full_like(a, np.nan)
    assert np.array_equal(scatter_bins(np, got, runs, n, -2), want)
    assert scatter_bins(np, got, runs, n, -2, out=work) is work
    assert np.array_equal(work, want)
