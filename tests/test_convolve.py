"""The scans' FFT convolution (imaging/convolve.py) against scipy.signal.fftconvolve, and
the modules a scan, a report's or a fit's processes load without scipy.signal."""

from __future__ import annotations

import numpy as np
import pytest
from tests.helpers import run_python

from opticalstamp.imaging.convolve import fft_convolve


@pytest.mark.parametrize("mode", ["full", "same"])
@pytest.mark.parametrize(
    "sa, sb", [((7, 9), (3, 4)), ((40, 61), (11, 8)), ((5, 5), (9, 12)), ((1, 1), (1, 1)),
               ((16, 3), (2, 30)), ((33, 20), (6, 7))],
)  # fmt: skip
def test_equals_scipys_fftconvolve(sa, sb, mode):
    from scipy.signal import fftconvolve  # here: ~1.4 s to import

    rng = np.random.default_rng(sum(sa) * 100 + sum(sb))
    a, b = rng.random(sa), rng.standard_normal(sb)
    want = fftconvolve(a, b, mode=mode)
    got = fft_convolve(a, b, mode=mode)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())
    # and a direct sum at a few points of the full result
    full = fft_convolve(a, b)
    for i, j in [(0, 0), (sa[0] - 1, sb[1] - 1), (full.shape[0] - 1, full.shape[1] - 1)]:
        direct = sum(
            a[p, q] * b[i - p, j - q]
            for p in range(sa[0])
            for q in range(sa[1])
            if 0 <= i - p < sb[0] and 0 <= j - q < sb[1]
        )
        assert full[i, j] == pytest.approx(direct, abs=1e-12)


def test_the_scans_call_gives_fftconvolves_values_to_the_last_bit():
    """As the scan calls it (imaging/scan.py): a padded document of block means and the
    ghost kernel reversed along x (a view with a negative stride)."""
    from scipy.signal import fftconvolve

    rng = np.random.default_rng(7)
    blocks, g = rng.random((83, 263)), rng.random((40, 180))
    np.testing.assert_array_equal(
        fft_convolve(blocks, g[:, ::-1]), fftconvolve(blocks, g[:, ::-1], mode="full")
    )
    np.testing.assert_array_equal(
        fft_convolve(blocks, g, mode="same"), fftconvolve(blocks, g, mode="same")
    )


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="2-D"):
        fft_convolve(np.ones(3), np.ones((2, 2)))
    with pytest.raises(ValueError, match="mode"):
        fft_convolve(np.ones((3, 3)), np.ones((2, 2)), mode="valid")
    with pytest.raises(TypeError, match="real"):
        fft_convolve(np.ones((3, 3)) * 1j, np.ones((2, 2)))
    with pytest.raises(ValueError, match="non-empty"):
        fft_convolve(np.ones((0, 3)), np.ones((2, 2)))


def test_the_scan_the_studies_and_the_fit_load_no_scipy_signal():
    """scipy.signal (which imports scipy.stats) takes 1.4 s to import on SciPy 1.17: every
    `opticalstamp scan` and every process a report, a search or a fit spawns paid them
    (a small scan took 4.0 s, 2.3 s without; a light of several wavelengths still loads
    scipy.signal for its czt, tests/test_architecture.py)."""
    mods = (
        "opticalstamp.cli, opticalstamp.imaging.scan, opticalstamp.imaging.outputkernel, "
        "opticalstamp.studies.fit, opticalstamp.studies.waveestimate, "
        "opticalstamp.studies.tolerance, opticalstamp.studies.search, "
        "opticalstamp.report.studies, opticalstamp.analysis.wavespectral"
    )
    slow = "('scipy.signal', 'scipy.stats')"
    code = f"import sys, {mods}; print(sorted(m for m in {slow} if m in sys.modules))"
    res = run_python(code)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]", res.stdout
