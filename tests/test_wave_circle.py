"""The wave engine's 2-D path feeding the analyses (issue 23): line-spread functions for
any hole shape (:mod:`opticalstamp.analysis.wave2dlsf`), exact angular filters, the
array backend (:mod:`opticalstamp.analysis.arrays`)."""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pytest

from opticalstamp.analysis import wave, wavebase
from opticalstamp.analysis.arrays import backend, cupy_found
from opticalstamp.analysis.responsivity import folded_lsf, resolve_optics
from opticalstamp.analysis.wave2d import wave_response_2d
from opticalstamp.analysis.wave2dlsf import lsf_source_2d
from opticalstamp.design import design_from_dict
from opticalstamp.device import DeviceUnavailable
from test_wave import _stack

ZS = (0.0, 0.4)


def _with(d, **sensor):
    raw = d.model_dump()
    raw["sensor"] |= sensor
    return design_from_dict(raw)


def _lsfs(src, zs=ZS):
    x, lsf, light, _ = src.lsf_x(zs)
    return x, lsf, light


@pytest.fixture(scope="module")
def squares():
    """The small two-row stamp of test_wave, square holes, two masks misregistered."""
    d = _stack((10.0, 10.0, 12.0), offsets=[(1.5, -1.0), (0.0, 0.0), (-2.0, 0.7)])
    return d, wavebase.wave_sampling(d, band=0.2).refined(margin=0.5)


@pytest.mark.parametrize("fresnel", [False, True], ids=["plain", "fresnel"])
def test_2d_lsfs_equal_the_separable_path_on_squares(squares, fresnel):
    """Square holes, where both paths apply: the 2-D path's x line-spread functions (the
    marginal's coherent modes of the randomized 2-D modes, paraxial propagator) equal the
    separable path's to 1e-4 of their peak and its light to 1e-5, with and without the
    Fresnel filters (exact in 2-D; a separable sum within 1e-5 of peak in the separable
    path)."""
    d, smp = squares
    sep = _lsfs(wave.lsf_source(d, max(ZS), sampling=smp, fresnel=fresnel))
    two = _lsfs(lsf_source_2d(d, max(ZS), sampling=smp, fresnel=fresnel, propagator="paraxial"))
    np.testing.assert_allclose(two[0], sep[0])
    assert two[2] == pytest.approx(sep[2], rel=5e-5)
    assert np.abs(two[1] - sep[1]).max() < 1e-4 * sep[1].max()


def test_2d_fresnel_loses_what_the_interfaces_transmit(squares):
    """The small stamp's interfaces (air/glass at the sensor-side mask, glass/air under
    the reference gap): with Fresnel losses the 2-D light drops by about the normal
    incidence transmittances' product (4 n1 n2 / (n1 + n2)^2 each), a little more at the
    band's oblique directions."""
    d, smp = squares
    plain = lsf_source_2d(d, 0.1, sampling=smp).light
    lossy = lsf_source_2d(d, 0.1, sampling=smp, fresnel=True).light
    t0 = (4 * 1.52 / 2.52**2) ** 2
    assert t0 * 0.99 < lossy / plain < t0


def test_2d_cone_against_the_separable_staircase(squares):
    """A 2-degree acceptance cone (|s| <= 0.035 inside a band of 0.2): the 2-D path
    applies the disk exactly, the separable path its staircase of strips with the disk's
    area: the light agrees to 0.5 %, the LSFs to 1 % of their peak."""
    d, smp = squares
    d = _with(d, acceptance_half_angle_deg=2.0)
    sep = _lsfs(wave.lsf_source(d, max(ZS), sampling=smp))
    two = _lsfs(lsf_source_2d(d, max(ZS), sampling=smp, propagator="paraxial"))
    full = lsf_source_2d(_with(d, acceptance_half_angle_deg=90.0), 0.1, sampling=smp).light
    assert two[2] < 0.9 * full  # the cone cuts
    assert two[2] == pytest.approx(sep[2], rel=5e-3)
    assert np.abs(two[1] - sep[1]).max() < 1e-2 * sep[1].max()


def test_circle_marginals_equal_the_full_2d_object_side():
    """Circular holes (not separable): the LSFs from the marginal's coherent modes equal
    the 2-D intensity integrated over y on the full object grid (both paraxial above the
    stack) to 1e-3 of their peak, and the light to 1e-3."""
    d = _stack((10.0, 10.0, 12.0), shape="circle", offsets=[(1.5, -1.0), (0, 0), (-2.0, 0.7)])
    smp = wavebase.wave_sampling(d, band=0.2).refined(margin=0.5)
    src = lsf_source_2d(d, max(ZS), sampling=smp, propagator="paraxial")
    x, lsf, light = _lsfs(src)
    full = wave_response_2d(d, ZS, sampling=smp, propagator="paraxial")
    assert light == pytest.approx(full.etendue_um2sr[0], rel=1e-3)
    for iz in range(len(ZS)):
        a = np.interp(full.x_um, x, lsf[iz])
        assert np.abs(a - full.lsf_x[iz]).max() < 1e-3 * full.lsf_x[iz].max()
    # a circle passes less than its bounding square, more than the inscribed half
    sq = lsf_source_2d(_stack((10.0, 10.0, 12.0), offsets=[(1.5, -1.0), (0, 0), (-2.0, 0.7)]),
                       0.1, sampling=smp, propagator="paraxial")  # fmt: skip
    assert 0.3 * sq.light < light < sq.light


def test_single_precision_operator_gives_the_double_figures(squares):
    """The stack operator's FFTs in complex64 (the default) against complex128: the light
    and the LSFs to 1e-6 (relative to the peak)."""
    d, smp = squares
    one = _lsfs(lsf_source_2d(d, 0.2, sampling=smp, precision="single"), (0.0, 0.2))
    two = _lsfs(lsf_source_2d(d, 0.2, sampling=smp, precision="double"), (0.0, 0.2))
    assert one[2] == pytest.approx(two[2], rel=1e-6)
    assert np.abs(one[1] - two[1]).max() < 1e-6 * two[1].max()


def test_lost_to_band_estimate_against_the_separable_budget(squares):
    """The 2-D range finder's estimate of the light the masks send beyond the band
    (random vectors) against the separable path's exact budget: within 4 standard
    errors."""
    d, smp = squares
    sep = wave.wave_response(d, (0.0,), sampling=smp).budget[-1]["lost_to_band"]
    info = lsf_source_2d(d, 0.1, sampling=smp, propagator="paraxial").meta
    assert abs(info["lost_to_band"] - sep) < 4 * info["lost_to_band_se"]
    assert info["lost_to_band_se"] < 0.1 * sep


def test_circles_take_wave_optics_where_asked_for():
    """Circular holes: ``wave`` gives the 2-D path's LSFs (folded onto a chart, as the
    RMTF asks), equal to the marginal source's; ``auto`` keeps ray optics on a CPU and
    says why (the 2-D maps' cost), naming ``--optics wave`` (the maps themselves:
    tests/test_wave_circle_maps.py)."""
    d = _stack((10.0, 10.0, 12.0), shape="circle")
    opt = resolve_optics(d, "wave")
    assert opt.engine == "wave"
    smp = wavebase.wave_sampling(d, band=0.2).refined(margin=0.5)
    f = folded_lsf(d, z_mm=[0.0, 0.3], periods_um=[60.0], optics=replace(opt, sampling=smp),
                   ghosts=False)  # fmt: skip
    x, lsf, light = _lsfs(lsf_source_2d(d, 0.3, sampling=smp), (0.0, 0.3))
    assert f.h[0][0, 0].sum(axis=-1) == pytest.approx(np.trapezoid(lsf, x, axis=-1), rel=1e-3)
    auto = resolve_optics(d, "auto")
    assert auto.engine == "ray" and "circular" in auto.reason
    assert "--optics wave" in auto.reason


def test_object_side_in_batches_of_heights_equals_one_at_a_time(squares, monkeypatch):
    """The object side on a backend (the 2-D path's on a GPU: batches of heights, one
    transform each) gives the host loop's LSFs to rounding, run here on the CPU backend,
    with batches of several heights and of one (a tiny byte bound)."""
    from opticalstamp.analysis import waveobject

    d, smp = squares
    src = lsf_source_2d(d, 0.4, sampling=smp, propagator="paraxial")
    zs = np.linspace(0.0, 0.4, 7)
    loop = waveobject.lsf_x_from(src.side, src.modes, zs)
    batched = waveobject.lsf_x_from(src.side, src.modes, zs, backend("cpu"))
    assert np.abs(batched - loop).max() < 1e-12 * loop.max()
    monkeypatch.setattr(waveobject, "BATCH_BYTES", 1)
    ones = waveobject.lsf_x_from(src.side, src.modes, zs, backend("cpu"))
    assert np.abs(ones - loop).max() < 1e-12 * loop.max()


def test_2d_sources_propagate_the_marginals_modes_uncompressed(squares):
    """The 2-D path's source carries the x marginal's coherent modes as they are (one
    row each, no second compression): orthogonal rows (to 1e-5 of the strongest: the
    object grid's band takes a few 1e-6 of each field's power), holding the light to
    1e-4; their LSFs equal those of the modes compressed once more (the object side's
    x_modes, which the path used to apply) within that compression's tolerance, L1."""
    from opticalstamp.analysis import waveobject

    d, smp = squares
    src = lsf_source_2d(d, 0.4, sampling=smp, propagator="paraxial")
    step, n = smp.step_um, src.side.grids[0].size
    g = src.modes @ src.modes.conj().T * (step / n)  # Gram of the modes' fields (um sr)
    assert np.trace(g).real == pytest.approx(src.light, rel=1e-4)
    off = np.abs(g - np.diag(np.diag(g)))
    assert off.max() < 1e-5 * np.abs(np.diag(g)).max()
    again, _ = waveobject.x_modes(src.side)
    assert again.shape[0] <= src.modes.shape[0]
    zs = np.array([0.0, 0.2, 0.4])
    a = waveobject.lsf_x_from(src.side, src.modes, zs)
    b = waveobject.lsf_x_from(src.side, again, zs)
    assert (np.abs(a - b).sum(axis=1) * step).max() <= 1.01 * smp.mode_tol * src.light


@pytest.mark.skipif(cupy_found(), reason="CuPy is installed here")
def test_cuda_without_cupy_is_refused_naming_it():
    with pytest.raises(DeviceUnavailable, match="CuPy"):
        backend("cuda")


def _gpu() -> bool:
    if not cupy_found():
        return False
    try:
        backend("cuda")
    except DeviceUnavailable:
        return False
    return True


@pytest.mark.skipif(not _gpu(), reason="no CuPy GPU")
def test_cuda_backend_gives_the_cpu_figures():
    """The same 2-D path on CuPy arrays, in double precision: the CPU's LSFs and light to
    1e-9 (relative)."""
    d = _stack((10.0, 10.0, 12.0), shape="circle")
    smp = wavebase.wave_sampling(d, band=0.2).refined(margin=0.5)
    cpu = _lsfs(lsf_source_2d(d, max(ZS), sampling=smp, device="cpu", precision="double"))
    gpu = _lsfs(lsf_source_2d(d, max(ZS), sampling=smp, device="cuda", precision="double"))
    assert gpu[2] == pytest.approx(cpu[2], rel=1e-9)
    assert np.abs(gpu[1] - cpu[1]).max() < 1e-9 * cpu[1].max()


def test_a_faint_wavelength_gets_a_looser_range_tolerance(monkeypatch):
    """A wavelength of weight w gets the range finder's tolerance / w (at most
    MAX_RANGE_TOL): the light's faint end takes fewer blocks of vectors, and the sum
    leaves out at most n x RANGE_TOL of its light (n wavelengths) against every
    wavelength at RANGE_TOL (measured here: 1.9e-6 of 3e-6)."""
    from opticalstamp.analysis import wave2d, wavespectral
    from opticalstamp.analysis.spectrum import Spectrum

    assert wave2d.range_tol(1.0) == wave2d.RANGE_TOL
    assert wave2d.range_tol(0.5) == pytest.approx(2 * wave2d.RANGE_TOL)
    assert wave2d.range_tol(1e-6) == wave2d.MAX_RANGE_TOL == 1e-3
    d = _stack((10.0, 10.0, 12.0), shape="circle")
    smp = wavebase.wave_sampling(d, band=0.12)
    light = Spectrum("faint end", (0.5, 0.6, 0.7), (0.6, 0.399, 0.001))
    weighted = wavespectral.SpectralLSFSource.of(d, 0.4, spectrum=light, sampling=smp)
    monkeypatch.setattr(wavespectral, "range_tol", lambda w: wave2d.RANGE_TOL)
    even = wavespectral.SpectralLSFSource.of(d, 0.4, spectrum=light, sampling=smp)
    blocks = [[s.meta["blocks"] for s in src.sources] for src in (weighted, even)]
    assert blocks[0][2] < blocks[1][2] and blocks[0][:2] == blocks[1][:2]
    (_, a, light_a), (_, b, light_b) = weighted.lsf_x(ZS), even.lsf_x(ZS)
    assert light_a == pytest.approx(light_b, rel=3 * wave2d.RANGE_TOL)
    assert light_a != light_b
    assert np.abs(a - b).max() < 3 * wave2d.RANGE_TOL * b.max()


def test_the_heaviest_wavelengths_start_first_and_come_back_in_order(monkeypatch):
    """The 2-D path's wavelengths are started heaviest first (their tolerance, and so
    their cost, follows their weight: the cheap faint ends fill the end) and come back
    in the light's order; the maps' path gives each its weight's tolerance too."""
    from opticalstamp.analysis import wave2d, wave2dmaps, wavespectral, wavethreads
    from opticalstamp.analysis.spectrum import Spectrum

    d = _stack((10.0, 10.0, 12.0), shape="circle")
    smp = wavebase.wave_sampling(d, band=0.12)
    light = Spectrum("three", (0.5, 0.6, 0.7), (0.2, 0.5, 0.3))
    seen = {}

    def record(fn, jobs, order, gpu):
        seen["order"] = list(order)
        return [(lam, w) for lam, _, w in jobs]

    monkeypatch.setattr(wavespectral, "side_by_side", record)
    src = wavespectral.SpectralLSFSource.of(d, 0.4, spectrum=light, sampling=smp)
    assert seen["order"] == [1, 2, 0]
    assert src.sources == [(0.5, 0.2), (0.6, 0.5), (0.7, 0.3)]
    # side by side: started in the order given, each result in its job's place
    monkeypatch.setattr(wavethreads, "usable_cores", lambda: 2)
    started = []

    def job(i):
        started.append(i)
        return i * i

    assert wavethreads.side_by_side(job, [(i,) for i in range(5)], [4, 3, 2, 1, 0], False) == [
        0, 1, 4, 9, 16,
    ]  # fmt: skip
    assert sorted(started) == list(range(5)) and set(started[:2]) <= {4, 3, 2}
    # the maps: each wavelength's range finder at its weight's tolerance
    tols = []

    class Seen(Exception):
        pass

    def maps(*args, tol, **kwargs):
        tols.append(tol)
        raise Seen

    monkeypatch.setattr(wave2dmaps, "wave_maps_2d", maps)
    faint_first = Spectrum("faint first", (0.7, 0.5), (0.001, 0.999))
    with pytest.raises(Seen):
        wavespectral.wave_response_spectral(d, ZS, spectrum=faint_first, sampling=smp)
    with pytest.raises(Seen):
        wavespectral.wave_response_spectral(d, ZS, spectrum="mono", sampling=smp)
    assert tols == [1e-3, wave2d.RANGE_TOL]


def test_wavelengths_side_by_side_give_the_figures_one_after_the_other(monkeypatch):
    """Light of several wavelengths by the 2-D path: the sources built in threads, on a
    GPU one per wavelength (here on the CPU, each thread in a copy of the run's context),
    on the CPU two at a time with their FFTs on one thread each, give the sequential
    sources' LSFs and light exactly, and BLAS's thread limit is the process's own again
    afterwards."""
    from threadpoolctl import threadpool_info

    from opticalstamp.analysis import arrays, wavespectral, wavethreads
    from opticalstamp.analysis.spectrum import Spectrum
    from opticalstamp.device import run_device, using_device

    d = _stack((10.0, 10.0, 12.0), shape="circle")
    smp = wavebase.wave_sampling(d, band=0.12)
    light = Spectrum("two", (0.5, 0.6), (0.4, 0.6))
    monkeypatch.setattr(wavethreads, "CPU_SIDE_BY_SIDE", 1)
    one = wavespectral.SpectralLSFSource.of(d, 0.4, spectrum=light, sampling=smp)
    monkeypatch.setattr(wavethreads, "CPU_SIDE_BY_SIDE", 2)
    monkeypatch.setattr(wavethreads, "usable_cores", lambda: 2)
    threads, seen = [], []
    fft_alone = wavethreads._one_fft_thread

    def counted(fn, *args):  # the FFTs' threads inside each side-by-side source
        def seen_by_backend(*a):
            threads.append((arrays.fft_workers(), arrays.CPU._kw()["workers"]))
            return fn(*a)

        return fft_alone(seen_by_backend, *args)

    monkeypatch.setattr(wavethreads, "_one_fft_thread", counted)
    two = wavespectral.SpectralLSFSource.of(d, 0.4, spectrum=light, sampling=smp)
    assert threads == [(1, 1), (1, 1)]

    def direct(fn, *args):  # the stream is CuPy's; the threads and contexts are tested
        seen.append(run_device())
        ran_on.append(threading.current_thread())
        return fn(*args)

    ran_on = []

    monkeypatch.setattr(wavespectral, "_on_gpu", lambda design: True)
    monkeypatch.setattr(wavethreads, "_on_stream", direct)
    before = [lib["num_threads"] for lib in threadpool_info()]
    with using_device("cpu"):
        side = wavespectral.SpectralLSFSource.of(d, 0.4, spectrum=light, sampling=smp)
    assert seen == ["cpu"] * 2  # each thread ran in the run's context
    # on a GPU the threads are the process's kept pool, alive after the call (their
    # CuPy FFT plans kept for the next)
    kept = wavethreads._gpu_threads(2)
    assert all(t in kept._threads and t.is_alive() for t in ran_on)
    assert [lib["num_threads"] for lib in threadpool_info()] == before
    a, c = one.lsf_x(ZS), two.lsf_x(ZS)
    assert np.array_equal(a[1], c[1]) and a[2] == c[2]
    a, b = one.lsf_x(ZS), side.lsf_x(ZS)
    assert np.array_equal(a[1], b[1]) and a[2] == b[2]
