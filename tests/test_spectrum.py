"""Light as it is (issue 23): the illumination's spectrum times the sensor's QE, sampled
at a few wavelengths, and the wave engine over it. Checked against independent
computations: the quadrature's moments against the trapezoid rule of its density, the
spectral response against an explicit weighted sum of single-wavelength runs, a
spectrum of one repeated wavelength against that wavelength alone, dispersion against
the catalogue, the mirror-twin shortcut against row B computed."""

from __future__ import annotations

import json

import numpy as np
import pytest

from edges import assert_clean_refusal, run
from opticalstamp.analysis import spectrum as sp
from opticalstamp.analysis.wave import stack_reach, wave_lsf_x, wave_response
from opticalstamp.analysis.wavebase import band_integral, stack_axes, wave_sampling
from opticalstamp.analysis.wavecompare import fold, wave_folded_lsf
from opticalstamp.analysis.wavespectral import (
    at_wavelength,
    mirror_twin,
    spectral_lsf_x,
    spectral_samplings,
    wave_response_channels,
    wave_response_spectral,
)
from opticalstamp.design.files import design_from_dict
from opticalstamp.design.materials import refractive_index
from opticalstamp.design.model import DesignError
from opticalstamp.design.variants import replace
from opticalstamp.validate import InputError

Z = (0.0, 0.1)


def _stamp(glass="N-BK7", offsets=None, illumination=None):
    """A small two-row stamp (holes 10/10/12 um, Fresnel numbers near 1): air 60, glass
    60 and 100 um of ``glass``, 100 um air gap."""
    offsets = offsets or [(0.0, 0.0)] * 3
    slabs = [("air", 60.0, 10.0), (glass, 60.0, 10.0), (glass, 100.0, 12.0)]
    data = {
        "name": "small",
        "wavelength_um": 0.55,
        "sensor": {
            "pixel_pitch_um": 12.0,
            "sensitive_width_um": 8.0,
            "sensitive_height_um": 8.0,
            "rows": 2,
            "row_pitch_um": 48.0,
            "row_b_offset_x_um": 24.0,
            "row_b_offset_y_um": 24.0,
            "pixels_per_row": 101,
        },
        "slabs": [
            {
                "medium": m,
                "thickness_um": t,
                "mask_top": {
                    "shape": "square",
                    "size_um": h,
                    "offset_x_um": o[0],
                    "offset_y_um": o[1],
                },
            }
            for (m, t, h), o in zip(slabs, offsets, strict=True)
        ],
        "reference_gap": {"medium": "air", "thickness_um": 100.0},
    }
    if illumination:
        data["electronics"] = {"illumination": illumination}
    return design_from_dict(data)


@pytest.fixture(scope="module")
def stamp():
    return _stamp()


# -- the spectra ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["white", "red", "green", "blue"])
def test_quadrature_weights_sum_to_one_and_integrate_the_density(name):
    """The n-point rule's weights sum to 1 and it integrates lambda^k, k <= 2n - 1,
    against the density (LED power x lambda x QE) as the trapezoid rule on a fine grid
    does (to 1e-10); its nodes lie where the light is."""
    s = sp.spectrum_of(name)
    w, lam = np.array(s.weights), np.array(s.wavelengths_um)
    assert len(lam) == sp.DEFAULT_POINTS[name]
    assert abs(w.sum() - 1) < 1e-12 and w.min() > 0
    grid = np.linspace(0.35, 1.1, 30001)
    dens = sp.led_power(name, grid) * grid * sp.silicon_qe(grid)
    norm = np.trapezoid(dens, grid)
    for k in range(2 * lam.size):
        want = np.trapezoid(dens * grid**k, grid) / norm
        assert np.dot(w, lam**k) == pytest.approx(want, rel=1e-8)
    peaks = [p for p, _, _ in sp.LEDS[name]]
    assert lam.min() < min(peaks) and lam.max() > max(peaks)


def test_the_led_shapes_and_the_qe_are_typical():
    """The white LED has its blue pump at 450 nm and its phosphor hump near 560 nm; the
    colour LEDs peak where their tables say; silicon's QE is highest in the red, low in
    the blue and gone past 1.1 um."""
    lam = np.linspace(0.38, 0.78, 4001)
    white = sp.led_power("white", lam)
    assert lam[np.argmax(white)] == pytest.approx(0.450, abs=1e-3)
    hump = lam > 0.5
    assert lam[hump][np.argmax(white[hump])] == pytest.approx(0.560, abs=5e-3)
    for name, peak in (("red", 0.630), ("green", 0.525), ("blue", 0.465)):
        assert lam[np.argmax(sp.led_power(name, lam))] == pytest.approx(peak, abs=1e-3)
    q = sp.silicon_qe(np.array([0.40, 0.55, 0.68, 1.2]))
    assert q[0] < q[1] < q[2] and q[3] == 0.0
    assert sp.spectrum_of("white").mean_um == pytest.approx(0.550, abs=0.01)


def test_channels_follow_the_design_illumination(stamp):
    assert list(sp.channels(stamp)) == ["mono"]
    assert sp.channels(stamp)["mono"].wavelengths_um == (0.55,)
    rgb = sp.channels(stamp, "rgb")
    assert list(rgb) == ["red", "green", "blue"]
    means = [rgb[c].mean_um for c in ("blue", "green", "red")]
    assert means == sorted(means)
    assert list(sp.channels(_stamp(illumination="white"))) == ["white"]


def test_bad_illumination_is_refused_naming_the_field(stamp):
    with pytest.raises(DesignError, match=r"electronics\.illumination"):
        replace(stamp, {"electronics.illumination": "purple"})
    with pytest.raises(InputError, match="spectrum: unknown illumination 'purple'"):
        sp.channels(stamp, "purple")
    with pytest.raises(InputError, match=r"'rgb' has 3 channels \(red, green, blue\)"):
        wave_response_spectral(stamp, Z, spectrum="rgb")
    with pytest.raises(InputError, match="spectrum: weights must be > 0 and sum to 1"):
        sp.Spectrum("bad", (0.5, 0.6), (0.5, 0.6))
    with pytest.raises(InputError, match="spectrum: wavelengths_um must lie in"):
        sp.Spectrum("bad", (0.2,), (1.0,))


# -- dispersion ----------------------------------------------------------------------------
def test_dispersion_changes_the_indices_per_wavelength(stamp):
    """At each of white light's wavelengths the glass has the catalogue's index there
    (N-BK7's Sellmeier formula), so the stack's reduced heights sum t / n differ; a
    glass given as a number keeps its index."""
    lams = sp.spectrum_of("white").wavelengths_um
    idx = [at_wavelength(stamp, lam).index("N-BK7") for lam in lams]
    assert idx == [refractive_index("N-BK7", lam) for lam in lams]
    assert all(a > b for a, b in zip(idx, idx[1:], strict=False))  # normal dispersion
    assert idx[0] - idx[-1] > 0.01
    h = [stack_axes(at_wavelength(stamp, lam))[0].heights for lam in (lams[0], lams[-1])]
    assert h[0][0] == h[1][0] and np.all(h[0][1:] < h[1][1:])  # air, then glass
    plain = _stamp(glass=1.52)
    assert {at_wavelength(plain, lam).index(1.52) for lam in lams} == {1.52}
    smps = spectral_samplings(stamp, sp.spectrum_of("white"))
    assert [s.wavelength_um for s in smps] == list(lams)
    own = [wave_sampling(at_wavelength(stamp, lam)) for lam in lams]
    assert [s.band for s in smps] == [s.band for s in own]  # each its own sampling
    assert len({round(s.step_um, 9) for s in smps}) == len(lams)


# -- the wave engine over a spectrum -------------------------------------------------------
def test_mono_is_the_single_wavelength_engine(stamp):
    """ "mono" (the default) gives wave_response's arrays exactly; the RMTF path's folded
    LSFs (x-only path, row B from row A's mirror image) agree with folding
    wave_response's LSFs of both rows to 1e-6."""
    r = wave_response(stamp, Z)
    s = wave_response_spectral(stamp, Z)
    assert s.spectrum.name == "mono" and len(s.parts) == 1
    for key in ("x_um", "lsf_x", "lsf_y", "etendue_um2sr", "center_cell_fraction"):
        np.testing.assert_array_equal(getattr(s, key), getattr(r, key))
    per = [48.0, 24.0]
    f = wave_folded_lsf(stamp, Z, per)
    for r_i, row in enumerate((r, wave_response(stamp, Z, pixel=(1, 0)))):
        for q, h in zip(per, f.h, strict=True):
            want = np.array([fold(row.x_um, p, q, h.shape[-1]) for p in row.lsf_x])
            np.testing.assert_allclose(h[r_i, 0], want, rtol=0, atol=1e-6 * want.max())


def test_a_spectrum_of_one_repeated_wavelength_is_mono(stamp):
    s = sp.Spectrum("same", (0.55, 0.55, 0.55), (0.2, 0.3, 0.5))
    r = wave_response_spectral(stamp, Z, spectrum=s)
    m = wave_response(stamp, Z)
    assert r.etendue_um2sr == pytest.approx(m.etendue_um2sr, rel=1e-8)
    assert r.center_cell_fraction == pytest.approx(m.center_cell_fraction, rel=1e-8)
    np.testing.assert_allclose(r.lsf_x, m.lsf_x, rtol=0, atol=1e-7 * m.lsf_x.max())
    x, lsf, light = spectral_lsf_x(stamp, Z, spectrum=s)
    np.testing.assert_allclose(lsf, m.lsf_x, rtol=0, atol=1e-6 * m.lsf_x.max())


def test_white_light_is_the_weighted_sum_of_single_wavelength_runs(stamp):
    """White light's responsivity on a dispersive stamp equals sum_i w_i R(lambda_i) of
    explicit wave_response calls on the design at each wavelength: the light and the
    centre-cell share to 1e-12, the LSFs' integrals over 4-um bins (exact band-limited
    integrals on each run's own grid) to 1e-8 in L1; its spot map is the weighted sum of
    the runs' maps."""
    white = sp.spectrum_of("white")
    r = wave_response_spectral(stamp, Z, spectrum=white)
    smps = spectral_samplings(stamp, white)
    runs = [
        wave_response(at_wavelength(stamp, lam), Z, sampling=s)
        for lam, s in zip(white.wavelengths_um, smps, strict=True)
    ]
    w = np.array(white.weights)
    light = sum(wi * p.etendue_um2sr for wi, p in zip(w, runs, strict=True))
    inside = sum(
        wi * p.etendue_um2sr * p.center_cell_fraction for wi, p in zip(w, runs, strict=True)
    )
    np.testing.assert_allclose(r.etendue_um2sr, light, rtol=1e-12)
    np.testing.assert_allclose(r.center_cell_fraction, inside / light, rtol=1e-12)
    edges = np.arange(-60.0, 60.01, 4.0)
    for axis in ("x", "y"):
        grid = getattr(r, f"{axis}_um")
        got = getattr(r, f"lsf_{axis}")
        want = sum(
            wi * _binned(getattr(p, f"{axis}_um"), getattr(p, f"lsf_{axis}"), edges)
            for wi, p in zip(w, runs, strict=True)
        )
        assert np.abs(_binned(grid, got, edges) - want).sum() / want.sum() < 1e-8
        assert np.trapezoid(got, grid, axis=1) == pytest.approx(light, rel=1e-4)
    edges, m = r.spot(1, bin_um=2.0, half_um=40.0)
    want = sum(wi * p.spot(1, 2.0, 40.0)[1] for wi, p in zip(w, runs, strict=True))
    np.testing.assert_allclose(m, want, rtol=1e-12)
    # dispersion and the band make the wavelengths differ: the sum is not any one of them
    lights = [p.etendue_um2sr[0] for p in runs]
    assert max(lights) / min(lights) > 1.02
    # the RMTF path's x-only LSFs give the same white LSF
    x, lsf, tot = spectral_lsf_x(stamp, Z, spectrum=white)
    np.testing.assert_array_equal(x, r.x_um)
    np.testing.assert_allclose(lsf, r.lsf_x, rtol=0, atol=1e-6 * r.lsf_x.max())
    assert tot == pytest.approx(light[0], rel=1e-12)


def _binned(x, y, edges):
    """Integrals of band-limited samples y (nz, n) on x over the bins ``edges``, exact
    (:func:`~opticalstamp.analysis.wavebase.band_integral`): (nz, bins)."""
    return np.stack([band_integral(x, y, a, b) for a, b in zip(edges, edges[1:], strict=False)], 1)


def test_rgb_gives_one_responsivity_per_channel():
    d = _stamp(illumination="rgb")
    ch = wave_response_channels(d, (0.0,))
    assert list(ch) == ["red", "green", "blue"]
    for name, r in ch.items():
        assert r.spectrum.name == name and len(r.parts) == 3
        assert r.etendue_um2sr[0] > 0
    assert len({round(float(r.etendue_um2sr[0]), 9) for r in ch.values()}) == 3


def test_row_b_is_row_a_mirrored_on_the_nominal_lattice(stamp):
    """mirror_twin holds on the nominal lattice (and row B computed gives row A's
    LSFs, 1e-6); it fails where a mask is misregistered in y and where the line is so
    short that its ends lie within the holes the engine takes."""
    reach = stack_reach(stamp, wave_sampling(stamp))
    assert mirror_twin(stamp, (0, 0), (1, 0), reach)
    _, a, _, _ = wave_lsf_x(stamp, Z, pixel=(0, 0))
    _, b, _, _ = wave_lsf_x(stamp, Z, pixel=(1, 0))
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-6 * a.max())
    shifted = _stamp(offsets=[(0.0, 0.0), (0.0, 1.5), (0.0, 0.0)])
    assert not mirror_twin(shifted, (0, 0), (1, 0), reach)
    along_x = _stamp(offsets=[(0.0, 0.0), (1.5, 0.0), (0.0, 0.0)])
    assert mirror_twin(along_x, (0, 0), (1, 0), reach)
    short = replace(stamp, {"sensor.pixels_per_row": 3})
    assert not mirror_twin(short, (0, 0), (1, 0), reach)


def test_the_wave_command_takes_a_spectrum():
    """opticalstamp wave --spectrum red: both engines weighted over the red LED's three
    wavelengths (JSON names them); an unknown light and --plot with three channels are
    refused naming the option, exit 2."""
    res = run(
        ["wave", "--design", "paper2016", "--z", "0", "--rays", "65536"]
        + ["--spectrum", "red", "--json"]
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    spec = out["meta"]["spectrum"]
    assert spec["name"] == "red" and len(spec["wavelengths_um"]) == 3
    assert abs(sum(spec["weights"]) - 1) < 1e-12
    assert out["sampling"]["wavelength_um"] == pytest.approx(0.630, abs=0.01)
    assert 0.5 < out["wave"]["light_um2sr"] / out["ray"]["light_um2sr"] < 2
    assert_clean_refusal(run(["wave", "--spectrum", "purple"]), "--spectrum")
    assert_clean_refusal(run(["wave", "--spectrum", "rgb", "--plot", "w.png"]), "--plot")


def test_a_given_sampling_is_carried_to_each_wavelength(stamp):
    """A sampling at the design's wavelength (as --optics wave passes it): mono keeps it
    as it is; over white light every wavelength gets its band, a step and margin scaled
    with the wavelength (still within lambda / 6B) and the source points the rule gives."""
    smp = wave_sampling(stamp)
    assert spectral_samplings(stamp, sp.mono(0.55), smp) == [smp]
    white = sp.spectrum_of("white")
    for lam, w, s in zip(
        white.wavelengths_um, white.weights, spectral_samplings(stamp, white, smp), strict=True
    ):
        assert s.wavelength_um == lam and s.band == smp.band
        assert s.step_um == pytest.approx(smp.step_um * lam / 0.55, rel=1e-12)
        assert s.step_um <= lam / (6 * s.band) * (1 + 1e-9)
        assert s.margin_um == pytest.approx(smp.margin_um * lam / 0.55, rel=1e-12)
        own = wave_sampling(at_wavelength(stamp, lam), band=smp.band)
        assert all(abs(a - b) <= 1 for a, b in zip(s.source_points, own.source_points, strict=True))
        assert s.mode_tol == pytest.approx(min(1e-6, smp.mode_tol / w))
    f = wave_folded_lsf(stamp, Z, [48.0], sampling=smp, spectrum=white)
    g = wave_folded_lsf(stamp, Z, [48.0], spectrum=white)
    np.testing.assert_allclose(f.h[0], g.h[0], rtol=0, atol=1e-3 * g.h[0].max())
