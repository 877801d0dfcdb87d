"""Two checks of the wave engine (issue 23's Tests) by computations that do not go
through its responsivity code: reciprocity (a band-limited point on the object plane
propagated down gives the pixel the power that the reverse responsivity gives that
point) and Talbot self-imaging of a periodic mask at z_T = 2 p^2 / lambda (paraxial:
exactly, to the band limit; exact propagator: the non-paraxial departure, measured
against its own Fourier series)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import fft as sfft

from opticalstamp.analysis import wave, wavebase
from opticalstamp.analysis.wave2d import stack_modes
from opticalstamp.analysis.wave2dgrid import Hole, layers_of, mask_field_2d, transfer
from opticalstamp.design.model import Design
from test_wave import LAM, _stack

Z_MM = 0.05


@pytest.fixture(scope="module")
def stamp():
    """The small two-row stamp of test_wave (holes 10/10/12 um, two masks misregistered
    by 1-2 um), its reference gap glass (1.52) and its object medium 1.33, so that the
    object side's reduced distances are tested too; band 0.3, pruning and mode
    compression at 1e-14 (the crosstalk point's R is 5e-5 of the peak)."""
    d = _stack((10.0, 10.0, 12.0), offsets=[(1.5, -1.0), (0.0, 0.0), (-2.0, 0.7)])
    gap = {"medium": 1.52, "thickness_um": 100.0}
    d = Design.model_validate(d.model_dump() | {"object_medium": 1.33, "reference_gap": gap})
    smp = wavebase.wave_sampling(d, band=0.3).refined(margin=0.5)
    return d, replace(smp, mode_tol=1e-14, prune_tol=1e-14)


def point_to_pixel(
    design, smp, xf, yf, ix, iy, z_mm, propagator="paraxial", *, reach=False
) -> float:
    """lambda^2 times the power that a band-limited point at (xf[ix], yf[iy]) on the
    object plane z_mm above the reference plane (flat spectrum 1 over |s_x|, |s_y| < B
    in spatial frequency) delivers onto the pixel's sensitive area (sr).

    Downwards, in the opposite order to the engine: the point's spectrum on the object
    grid ``xf`` x ``yf`` through the object medium and the reference gap, cut to the
    stack's window, then at each mask from the object side down the mask's low-passed
    transmission (every hole of the lattice inside the window, 2-D; ``reach``: only
    those the engine takes, within the band's reach and the margin) and the slabs below
    it; the last slab to the sensor in closed form (the Fresnel integrals of
    :func:`wavebase.point_sources`, so that the band there is the continuous |s| < B of
    the reverse source, not the grid's bins), and |u|^2 integrated over the sensitive
    area by Gauss-Legendre in x0 and y0 (the integrand is band-limited).
    """
    lam, b, step = smp.wavelength_um, smp.band, smp.step_um
    gap = design.reference_gap
    above = [(gap.thickness_um, design.index(gap.medium))]
    above.append((z_mm * 1e3, design.index(design.object_medium)))
    layers = layers_of(design, (0, 0), 4000.0)
    s = design.sensor
    hw, hh = s.sensitive_width_um / 2, s.sensitive_height_um / 2
    x = wavebase.stack_grid((-hw, hw), layers[-1].reduced, smp)
    y = wavebase.stack_grid((-hh, hh), layers[-1].reduced, smp)
    ox, oy = (int(round((g[0] - gf[0]) / step)) for g, gf in ((x, xf), (y, yf)))
    fx = sfft.fftfreq(xf.size, step)[None, :]
    fy = sfft.fftfreq(yf.size, step)[:, None]
    point = np.exp(-2j * np.pi * (fx * (xf[ix] - xf[0]) + fy * (yf[iy] - yf[0]))) / step**2
    u = sfft.ifft2(point * transfer(xf, yf, above, lam, b, propagator))
    u = u[oy : oy + y.size, ox : ox + x.size]  # the stack's window
    u = sfft.ifft2(sfft.fft2(u) * transfer(x, y, [], lam, b, "paraxial"))  # its band
    for i, lay in enumerate(layers[::-1]):
        inside = [
            h
            for h in lay.holes
            if x[0] + h.hw < h.cx < x[-1] - h.hw and y[0] + h.hh < h.cy < y[-1] - h.hh
        ]
        if reach:  # the engine's rule: the holes within the band's reach and the margin
            r_i = lay.reduced * b + smp.margin_um
            inside = [
                h for h in inside if abs(h.cx) - h.hw < hw + r_i and abs(h.cy) - h.hh < hh + r_i
            ]
        u = u * mask_field_2d(x, y, inside, b, lam)
        if i < len(layers) - 1:
            u = sfft.ifft2(sfft.fft2(u) * transfer(x, y, lay.slabs, lam, b, propagator))
    bottom = layers[0]
    if propagator == "exact":  # exact over paraxial: the closed form below is paraxial
        u = sfft.ifft2(sfft.fft2(u) * transfer(x, y, bottom.slabs, lam, b, "exact", relative=True))
    n = 48
    x0, wx = wavebase.gauss_legendre(-hw, hw, n)
    y0, wy = wavebase.gauss_legendre(-hh, hh, n)
    hx = wavebase.point_sources(x, x0, np.ones(n), lam, bottom.reduced, b)  # h(x - x0)
    hy = wavebase.point_sources(y, y0, np.ones(n), lam, bottom.reduced, b)
    amp = hy.T @ u @ hx * step * step  # (y0, x0): the kernel is even, h(x0 - x) = h(x - x0)
    return lam**2 * float(wy @ (np.abs(amp) ** 2) @ wx)


def _node(g: np.ndarray, v: float) -> int:
    return int(np.argmin(np.abs(g - v)))


def _points(design, smp, x, y, r, r_own):
    """The object points (indices on the grids): on axis, the peak, a diffraction tail
    beyond the own path's geometric reach in x, and the near-crosstalk lobe (the largest
    R where the sequences through row B's holes carry more than half of it), each
    checked to be what it is said to be."""
    peak = np.unravel_index(r.argmax(), r.shape)
    # the paraxial own path reaches at most |X| <= top hole's edge + s_own d (x axis)
    top = design.masks[-1]
    d_obj = design.reference_gap.thickness_um / design.index(design.reference_gap.medium)
    d_obj += Z_MM * 1e3 / design.index(design.object_medium)
    reach = abs(top.offset_x_um) + top.hole_width_um / 2 + wavebase.own_slope(design) * d_obj
    tail = (_node(y, 0.0), _node(x, reach + 20.0))
    cross = np.unravel_index(np.where(r - r_own > 0.5 * r, r, 0.0).argmax(), r.shape)
    pts = {"axis": (_node(y, 0.0), _node(x, 0.0)), "peak": peak, "tail": tail, "cross": cross}
    assert 1e-4 < r[tail] / r.max() < 1e-2  # diffraction, not geometric light
    assert (r - r_own)[cross] > 0.99 * r[cross] and r[cross] > 1e-5 * r.max()
    assert np.hypot(x[cross[1]], y[cross[0]]) > 40.0  # above a neighbouring hole
    return pts


def test_reciprocity_separable_path(stamp):
    """The separable (paraxial) path's R(X, Y; Z) at four object points (on axis, the
    peak, the diffraction tail at 5e-4 of the peak, the crosstalk lobe through row B at
    5e-5) equals lambda^2 times the power a band-limited point there sends down onto the
    sensitive area. The normalisation: a point of flat spectrum 1 over the band carries
    (2B)^2 / lambda^2 (a Lambertian point: flat in s); R in sr is (2B)^2 times the share
    of it that reaches the pixel.

    With every hole of the window in the forward computation, measured: 5e-8 and 9e-8
    (axis, peak), 5e-5 (tail: the engine's 17 source points; 8e-7 with 26) and 8e-5
    (crosstalk: the holes beyond the band's reach and the margin, which the engine
    leaves out and the band edge's slow tails still light), all within 3e-8 of the
    peak; tested at 1e-4 R + 1e-7 R_peak. With the engine's holes alone and 1.5x its
    source points (26) the forward computation is the engine's operator transposed:
    6e-13 or less at every point, tested at 1e-9."""
    d, smp = stamp
    for points in (1.0, 1.5):
        r = wave.wave_response(d, (Z_MM,), sampling=smp.refined(points=points))
        assert r.meta["sequences"][0] == "AAA"
        (x, gx), (y, gy) = r.fields.terms(Z_MM)
        rr = np.einsum("jlx,jly->yx", gx, gy).real  # sr, on the object grid's nodes
        own = np.outer(gy[0, 0], gx[0, 0]).real
        for name, (j, i) in _points(d, smp, x, y, rr, own).items():
            ix, iy = _node(r.x_um, x[i]), _node(r.y_um, y[j])
            if points == 1.0:
                fwd = point_to_pixel(d, smp, r.x_um, r.y_um, ix, iy, Z_MM)
                assert abs(fwd - rr[j, i]) <= 1e-4 * rr[j, i] + 1e-7 * rr.max(), name
            else:
                same = point_to_pixel(d, smp, r.x_um, r.y_um, ix, iy, Z_MM, reach=True)
                assert same == pytest.approx(rr[j, i], rel=1e-9), name


def test_reciprocity_2d_exact_path(stamp):
    """The 2-D path with the exact angular spectrum (randomized coherent modes to 1e-6
    of the power, double precision): its R at the same points equals the exact forward
    computation (measured: 2.0e-5 relative on axis, 5e-6 at the peak, 6.3e-4 in the
    tail, 1.9e-3 at the crosstalk lobe, all within 2e-5 of the peak: the modes leave
    out 1e-6 of the light; tested at 1e-4 R + 1e-6 R_peak). The paraxial R differs
    from it by more than twice that on axis (3.7e-4), at the peak (1.2e-3) and in the
    tail (20 % less, where the light is steep; 2.7 % at the crosstalk lobe, within its
    floor there), so the check sees which propagator it gets."""
    d, smp = stamp
    sm = stack_modes(d, sampling=smp, propagator="exact", precision="double", device="cpu")
    st = sm.stack
    gap = d.reference_gap
    above = [(gap.thickness_um, d.index(gap.medium)), (Z_MM * 1e3, d.index(d.object_medium))]
    d_obj = sum(t / n for t, n in above)
    xf, ox = wavebase.object_grid(st.x, d_obj, smp)
    yf, oy = wavebase.object_grid(st.y, d_obj, smp)
    h = transfer(xf, yf, above, LAM, smp.band, "exact")
    rr = np.zeros((yf.size, xf.size))
    u = np.zeros((yf.size, xf.size), dtype=np.complex128)
    for m in sm.modes:  # as wave_response_2d, on the object grid's nodes (sr)
        u[oy : oy + st.y.size, ox : ox + st.x.size] = st.field(m)
        rr += np.abs(sfft.ifft2(sfft.fft2(u) * h)) ** 2
    sep = wave.wave_response(d, (Z_MM,), sampling=smp)
    (x, gx), (y, gy) = sep.fields.terms(Z_MM)
    own = np.outer(gy[0, 0], gx[0, 0]).real
    par = np.einsum("jlx,jly->yx", gx, gy).real
    for name, (j, i) in _points(d, smp, x, y, par, own).items():
        ix, iy = _node(xf, x[i]), _node(yf, y[j])
        fwd = point_to_pixel(d, smp, xf, yf, ix, iy, Z_MM, "exact")
        tol = 1e-4 * rr[iy, ix] + 1e-6 * rr.max()
        assert abs(fwd - rr[iy, ix]) <= tol, name
        if name != "cross":  # there the floor 1e-6 R_peak is 2 % of R
            assert abs(par[j, i] - fwd) > 2 * tol, name
        if name == "tail":
            assert par[j, i] < 0.9 * fwd  # paraxial: 20 % less


# -- Talbot self-imaging ------------------------------------------------------------------
P_UM = 20.0


def _grating_1d(band: float, periods: int = 4):
    """A plane wave through a grating of period P_UM (open half), the mask low-passed to
    2B as the engine does, on a periodic grid of whole periods: (x, field, grid points
    per period)."""
    m = 2 * int(np.ceil(P_UM / (LAM / (6 * band)) / 2))  # even: p / 2 falls on a node
    step = P_UM / m
    x = (np.arange(periods * m) - periods * m // 2) * step
    holes = np.array([[k * P_UM - P_UM / 4, k * P_UM + P_UM / 4] for k in range(-9, 10)])
    return x, wavebase.mask_field(x, holes, band, LAM), m


def test_talbot_paraxial_self_imaging():
    """Paraxial (wavebase.kernel, wavebase.mask_field; p = 20 um, open half, band 0.3:
    harmonics |j| <= 10): at z_T = 2 p^2 / lambda the intensity is the band-limited
    grating's (its Fourier series, term by term) to 1e-12 of its peak; at z_T / 2 it
    is the same shifted by p / 2; at z_T / 4 it is not (differs by > 10 % of the peak:
    the test can fail)."""
    band = 0.3  # harmonics |j| <= 10
    x, m_field, m = _grating_1d(band)
    step = x[1] - x[0]
    zt = 2 * P_UM**2 / LAM
    u0 = wavebase.propagate(m_field, wavebase.kernel(x.size, step, LAM, 0.0, band))
    i0 = np.abs(u0) ** 2
    j = np.arange(-10, 11)  # the grating's harmonics in the band, term by term
    series = np.exp(2j * np.pi * np.outer(x, j) / P_UM) @ (0.5 * np.sinc(0.5 * j))
    np.testing.assert_allclose(u0, series, atol=1e-12)
    assert i0.max() > 0.9 and i0.min() < 0.1  # a grating, within its band

    def at(z):
        return np.abs(wavebase.propagate(m_field, wavebase.kernel(x.size, step, LAM, z, band))) ** 2

    assert np.abs(at(zt) - i0).max() < 1e-12 * i0.max()
    assert np.abs(at(zt / 2) - np.roll(i0, m // 2)).max() < 1e-12 * i0.max()
    assert np.abs(at(zt / 4) - i0).max() > 0.1 * i0.max()


def _series(p_um: float, x: np.ndarray, z_um: float, exact: bool) -> np.ndarray:
    """The square-hole grating's (period p, holes p / 2 centred at p / 2) field at z,
    its harmonics |j|, |k| <= 4 summed term by term with the analytic coefficients
    (w / p) sinc(w j / p) exp(-2 pi i j c / p) and each harmonic's phase, exact
    2 pi z (sqrt(1 / lambda^2 - f^2) - 1 / lambda) or paraxial -pi lambda z f^2: (n, n)."""
    j = np.arange(-4, 5)
    a = 0.5 * np.sinc(0.5 * j) * np.exp(-1j * np.pi * j)
    f2 = (j[:, None] ** 2 + j[None, :] ** 2) / p_um**2
    if exact:
        phase = 2 * np.pi * z_um * (np.sqrt(1 / LAM**2 - f2) - 1 / LAM)
    else:
        phase = -np.pi * LAM * z_um * f2
    e = np.exp(2j * np.pi * np.outer(x, j) / p_um)  # (n, 9)
    return e @ (np.outer(a, a) * np.exp(1j * phase)) @ e.T


def test_talbot_exact_departure():
    """The exact angular spectrum (wave2dgrid.transfer) at z_T on a square-hole grating
    (mask_field_2d, one periodic cell, harmonics |j|, |k| <= 4 in the band): each
    harmonic carries 2 pi z_T (sqrt(1 / lambda^2 - f^2) - 1 / lambda) instead of the
    paraxial 2 pi (j^2 + k^2) (= 0 mod 2 pi), about -pi lambda^2 (j^2 + k^2)^2 / (2 p^2)
    off, so the image departs from the grating's intensity by D = max |I(z_T) - I_0| /
    max I_0. The grating's field is real (centred holes) and the phase errors are even,
    so the first-order change of |u|^2 vanishes and D goes as the square of the phase
    errors, 1/p^4. Measured: D = 0.088 at p = 10 um, 0.0060 at 20 um, 3.7e-4 at 40 um
    (ratios 14.7 and 16.0: small for p >> lambda); the engine's fields equal the
    term-by-term series to 1e-12, and its paraxial image is the grating's to 1e-12."""
    ds = []
    for p in (10.0, 20.0, 40.0):
        band = 4.5 * LAM / p  # the same harmonics at every period
        m = 2 * int(np.ceil(p / (LAM / (6 * band)) / 2))
        x = np.arange(m) * (p / m)
        mk = mask_field_2d(x, x, [Hole("rect", p / 2, p / 2, p / 4, p / 4)], band, LAM)
        zt = 2 * p * p / LAM

        def at(z, prop, mk=mk, x=x, band=band):
            return sfft.ifft2(sfft.fft2(mk) * transfer(x, x, [(z, 1.0)], LAM, band, prop))

        i0 = np.abs(at(0.0, "paraxial")) ** 2
        np.testing.assert_allclose(i0, np.abs(_series(p, x, 0.0, False)) ** 2, atol=1e-12)
        assert np.abs(np.abs(at(zt, "paraxial")) ** 2 - i0).max() < 1e-12
        ex = at(zt, "exact")
        np.testing.assert_allclose(ex, _series(p, x, zt, True), atol=1e-12)
        ds.append(float(np.abs(np.abs(ex) ** 2 - i0).max() / i0.max()))
    d10, d20, d40 = ds
    assert d40 < 1e-3 < d20 < 1e-2 < d10
    assert d10 / d20 == pytest.approx(16.0, rel=0.1) and d20 / d40 == pytest.approx(16.0, rel=0.03)
