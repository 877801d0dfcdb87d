"""The wave engine's marginals alone (the fit's forward model): each axis's line-spread
function from the leading coherent modes of its mutual intensity
(``waveobject._eig_modes``, ``wave.wave_marginals``), against the full responsivity."""

from __future__ import annotations

import numpy as np

from opticalstamp.analysis import waveobject
from opticalstamp.analysis.wave import wave_marginals, wave_response
from opticalstamp.analysis.wavebase import wave_sampling
from opticalstamp.design import load_design
from opticalstamp.design.variants import replace
from opticalstamp.studies.fitwave import held_sampling


def _rows(seed: int, r: int = 40, n: int = 256) -> np.ndarray:
    """Random rows whose powers fall by 10 decades: a mutual intensity with a long tail."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((r, n)) + 1j * rng.standard_normal((r, n))
    mix = rng.standard_normal((r, r)) + 1j * rng.standard_normal((r, r))
    return (mix * np.logspace(0, -5, r)[None, :]) @ a  # correlated rows, decaying power


def test_eig_modes_leave_out_a_positive_part_within_the_tolerance():
    """What the modes leave out is positive semi-definite: after any unitary transform
    (here the FFT, as a propagation) their intensity lies below the rows' everywhere (to
    rounding), and the total left out is at most ``tol`` of the power. The pivoted
    Cholesky (``_modes``), a projection of the rows, has cross terms that go both ways."""
    for seed in (0, 1):
        a = _rows(seed)
        exact = np.sum(np.abs(np.fft.fft(a, axis=-1)) ** 2, axis=0)
        total = exact.sum()
        for tol in (1e-4, 1e-8):
            m = waveobject._eig_modes(a, tol)
            assert 1 <= m.shape[0] < a.shape[0]
            approx = np.sum(np.abs(np.fft.fft(m, axis=-1)) ** 2, axis=0)
            gap = exact - approx
            assert gap.min() >= -1e-12 * exact.max()
            assert 0 <= gap.sum() <= tol * total
            # the fewest modes: without the weakest kept one, more than tol is left out
            power = np.sum(np.abs(np.fft.fft(m, axis=-1)) ** 2, axis=1)  # each mode's
            assert gap.sum() + power.min() > tol * total
        piv = waveobject._modes(a, 1e-4)
        gap = exact - np.sum(np.abs(np.fft.fft(piv, axis=-1)) ** 2, axis=0)
        assert gap.min() < -1e-9 * exact.max()  # the projection's cross terms


def test_marginals_are_the_responsivitys_own():
    """wave_marginals gives wave_response's marginals and light (L1 to 1e-13 of the
    light, the modes' tolerance 1e-14), on the prototype and on it with layer 2 shifted
    and slab 2 thinner, at the fit's held sampling."""
    d = load_design("paper2016")
    zs = (0.5, 2.0, 4.5)
    moved = replace(d, {"slabs.1.mask_top.offset_x_um": 4.0, "slabs.1.thickness_um": 420.0})
    smp = held_sampling(d, wave_sampling(d), max(zs))
    for design in (d, moved):
        full = wave_response(design, zs, sampling=smp)
        x, lx, y, ly, light = wave_marginals(design, zs, sampling=smp)
        assert np.array_equal(x, full.x_um) and np.array_equal(y, full.y_um)
        assert light == full.etendue_um2sr[0]
        for got, want, g in ((lx, full.lsf_x, x), (ly, full.lsf_y, y)):
            step = g[1] - g[0]
            l1 = np.abs(got - want).sum(axis=1) * step
            assert np.all(l1 <= 1e-13 * want.sum(axis=1) * step)
