"""Restoration against height: how far deconvolution with the known blur carries the
depth of field, judged by measures restoration cannot fool.

At each height a bar chart of the depth-of-field frequency and a white page are scanned
(noise on, the design's electronics) and restored by each method; measured:
- ``amplitude_rel``: the fundamental's fitted amplitude over the band-limited ideal's;
- ``cnr``: contrast to noise, 2 amplitude over the noise along the bars;
- ``overshoot``: past white or black;
- ``noise_gain``: the white page's rms noise restored over raw;
- the own path's transfer at that frequency (the physical ceiling: past its zero the
  detail is gone, whatever the method).

The *restored depth of field* is the largest height up to which ``amplitude_rel >=
threshold`` and ``cnr >= floor`` (crossings interpolated linearly); "raw" is the scan
itself by the same rule.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..design import Design
from ..design.resolution import dof_chart_dpi
from ..imaging.charts import bar_chart
from ..imaging.measure import measure_rmtf
from ..imaging.outputkernel import output_kernel
from ..imaging.restore import METHODS, MODEL_ERROR, noise_sigma, restore
from ..imaging.scan import ScanSettings, prepare_kernels, simulate_scan
from ..units import period_of_dpi

#: restored depth of field: the fundamental at least this share of the ideal's ...
AMPLITUDE_THRESHOLD = 0.3
#: ... and contrast to noise at least this (Rose's criterion for seeing a feature)
CNR_FLOOR = 5.0
STUDY_Z_MM = (0.5, 1.5, 2.5, 3.0, 3.5, 4.0, 4.5)
CHART_DPI = 1200.0


def _block(image: np.ndarray, dpi: float, near: float) -> dict | None:
    blocks = [b for b in measure_rmtf(image, dpi) if abs(b["dpi"] - near) < 0.06 * near]
    return max(blocks, key=lambda b: b["n_periods"]) if blocks else None


def _interior_std(img: np.ndarray, margin: int = 12) -> float:
    return float(img[margin:-margin, margin:-margin].std())


def crossing_dof(z: list[float], amp: list[float], cnr: list[float], thr: float, floor: float):
    """Largest Z up to which amp >= thr and cnr >= floor (linear in between); the last Z
    where both hold to the end (with ``open_ended``)."""
    ok = [a >= thr and c >= floor for a, c in zip(amp, cnr, strict=True)]
    if not ok[0]:
        return 0.0, False
    for i in range(1, len(z)):
        if not ok[i]:
            # the first measure to fail sets the crossing
            fa = (amp[i - 1] - thr) / (amp[i - 1] - amp[i]) if amp[i] < thr else 1.0
            fc = (cnr[i - 1] - floor) / (cnr[i - 1] - cnr[i]) if cnr[i] < floor else 1.0
            return float(z[i - 1] + min(fa, fc) * (z[i] - z[i - 1])), False
    return float(z[-1]), True


def restoration_study(
    design: Design,
    *,
    z_mm=STUDY_Z_MM,
    methods=METHODS,
    settings: ScanSettings | None = None,
    seed: int = 0,
    dpi: float | None = None,
    threshold: float = AMPLITUDE_THRESHOLD,
    cnr_floor: float = CNR_FLOOR,
    model_error: float = MODEL_ERROR,
    tracer=None,
    kernels=None,
) -> dict:
    """Amplitude, contrast to noise, overshoot and noise gain against height, raw and per
    method, and each one's restored depth of field (see the module's docstring); ``dpi``:
    the chart (default 2/3 of the design's resolution, as the depth of field's);
    ``kernels``: a :class:`~opticalstamp.imaging.kernels.KernelCache` built for these
    settings, seed and heights (each Z its own scan), e.g. the report's scans' (default:
    built here)."""
    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    st = settings or ScanSettings(sensor=design.electronics)
    zs = [float(z) for z in z_mm]
    chart = bar_chart(CHART_DPI, chart_dpi=(dpi,), block_mm=6.0, height_mm=6.0)
    white = np.ones((240, 360), np.float32)
    cache = kernels
    if cache is None:
        cache = prepare_kernels(design, z_mm=zs, settings=st, seed=seed, tracer=tracer)
    names = ["raw", *methods]
    series = {n: {"amplitude_rel": [], "cnr": [], "overshoot": [], "noise_gain": []} for n in names}
    transfer, sigmas, cases = [], [], []
    for z in zs:  # the scans (numba's threads) one after the other
        scan = simulate_scan(
            chart, CHART_DPI, design, z_mm=z, settings=st, seed=seed, kernels=cache
        )
        page = simulate_scan(
            white, CHART_DPI, design, z_mm=z, settings=st, seed=seed, kernels=cache
        )
        ok = output_kernel(design, z, settings=st, seed=seed, kernels=cache)
        sigma = noise_sigma(st.sensor, ok.white, model_error)
        sigmas.append(sigma)
        pitch = ok.pitch_um
        transfer.append(float(ok.transfer(pitch / period_of_dpi(dpi))))
        cases.append((scan, page, ok, sigma))

    def measured(job: tuple[int, str]) -> tuple[dict | None, float]:
        """The chart's block and the white page's noise gain, raw or restored."""
        scan, page, ok, sigma = cases[job[0]]
        img, wimg = scan.image, page.image
        if job[1] != "raw":
            kw = {"method": job[1], "sigma": sigma, "surround": st.surround}
            img = restore(img, ok, **kw).image
            wimg = restore(wimg, ok, **kw).image
        raw = _interior_std(page.image)  # 0 where white clips at full well: no gain
        return _block(img, scan.dpi, dpi), _interior_std(wimg) / raw if raw > 0 else math.nan

    # the restorations (FFTs and numpy: no numba) at once, on every core
    jobs = [(i, n) for i in range(len(zs)) for n in names]
    with ThreadPoolExecutor(max(1, min(len(jobs), os.cpu_count() or 1))) as pool:
        results = list(pool.map(measured, jobs))
    for (_, n), (b, gain) in zip(jobs, results, strict=True):
        s = series[n]
        s["amplitude_rel"].append(0.0 if b is None else b["amplitude_rel"])
        s["cnr"].append(0.0 if b is None else min(b["cnr"], 1e6))
        s["overshoot"].append(0.0 if b is None else b["overshoot"])
        s["noise_gain"].append(gain)
    dof = {}
    for n in names:
        v, open_ended = crossing_dof(
            zs, series[n]["amplitude_rel"], series[n]["cnr"], threshold, cnr_floor
        )
        dof[n] = {"dof_mm": v, "open_ended": open_ended}
    # the ceiling: the own transfer at the chart's frequency on a finer, longer Z grid
    z_fine = [round(v, 6) for v in np.arange(0.0, max(zs) + 1.5 + 1e-9, 0.125)]
    # (ray optics: the wave engine's kernels at ~50 heights would cost a minute)
    st_own = st.model_copy(update={"kernel": "auto"}) if st.kernel == "wave" else st
    own_cache = prepare_kernels(
        design, z_mm=z_fine, settings=st_own, seed=seed, ghosts=False, tracer=tracer
    )
    t = np.array(
        [
            output_kernel(
                design, z, settings=st_own, seed=seed, ghosts=False, kernels=own_cache
            ).transfer(pitch / period_of_dpi(dpi))
            for z in z_fine
        ]
    )
    sign = np.flatnonzero(np.signbit(t[1:]) != np.signbit(t[:-1]))
    zero = None
    if sign.size:
        i = int(sign[0])
        zero = float(z_fine[i] + t[i] / (t[i] - t[i + 1]) * (z_fine[i + 1] - z_fine[i]))
    return {
        "design": design.name,
        "fingerprint": design.fingerprint(),
        "seed": seed,
        "dpi": dpi,
        "z_mm": zs,
        "threshold": threshold,
        "cnr_floor": cnr_floor,
        "model_error": model_error,
        "sigma": sigmas,
        "series": series,
        "dof": dof,
        "transfer": transfer,
        "transfer_z_mm": z_fine,
        "transfer_fine": t.tolist(),
        "transfer_zero_mm": zero,
        "kernels": st.kernel,
        "transfer_kernels": st_own.kernel,
    }


def restored_dof_closed_form(
    design: Design,
    *,
    dpi: float | None = None,
    ghost_fraction: float = 0.0,
    settings: ScanSettings | None = None,
    z_step_mm: float = 0.25,
    z_max_mm: float = 20.0,
    threshold: float = AMPLITUDE_THRESHOLD,
    cnr_floor: float = CNR_FLOOR,
    model_error: float = MODEL_ERROR,
) -> dict:
    """The Wiener restored depth of field in closed form, for a search (no scan, no trace):
    at each height the own path's transfer T at the chart's frequency (paraxial closed
    form, rectangular holes), H = (1 - ghost fraction) T, the restored amplitude over the
    ideal's |H|^2 / (|H|^2 + sigma^2 / S) (the Wiener chain at that frequency), and the
    contrast to noise 2 (2/pi) amplitude / (sigma_sensor G), G the Wiener noise gain on
    white noise (closed form); the depth of field by the rule of
    :func:`restoration_study` (its simulated figure for the prototype: docs/restore.md).
    Heights run in ``z_step_mm`` until a criterion fails or ``z_max_mm``; ``dpi``: the
    chart (default 2/3 of the design's resolution).
    """
    from ..imaging.restore import Grid, prior_spectrum, wiener_noise_gain

    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    base = settings or ScanSettings(sensor=design.electronics)
    st = base.model_copy(update={"kernel": "paraxial"})
    n = 128
    sub = Grid((n, n), 0, 0, n, n, 1, False)
    prior = prior_spectrum(sub)
    nu = None
    zs, amp, cnr = [], [], []
    z = 0.0
    while z <= z_max_mm + 1e-9:
        ok = output_kernel(design, z, settings=st, ghosts=False)
        if nu is None:
            nu = ok.pitch_um / period_of_dpi(dpi)
            s_nu = float(np.interp(nu, np.fft.fftfreq(n)[: n // 2], prior[0, : n // 2]))
            white = ok.white / (1 - ghost_fraction) if ghost_fraction < 1 else ok.white
            sigma = noise_sigma(st.sensor, white, model_error)
            sensor_sigma = noise_sigma(st.sensor, white, 0.0)
        h = (1 - ghost_fraction) * float(ok.transfer(nu))
        a = h * h / (h * h + sigma**2 / s_nu)
        zs.append(round(z, 9))
        amp.append(a)
        if a < threshold:  # the crossing: the noise gain is not needed
            cnr.append(0.0 if len(cnr) == 0 else cnr[-1])
            break
        gain = wiener_noise_gain(replace_own(ok, 1 - ghost_fraction), (n, n), sigma)
        cnr.append(2 * (2 / np.pi) * a / (sensor_sigma * gain))
        if cnr[-1] < cnr_floor:
            break
        z += z_step_mm
    dof, open_ended = crossing_dof(zs, amp, cnr, threshold, cnr_floor)
    return {"dof_mm": dof, "open_ended": open_ended, "z_mm": zs, "amplitude_rel": amp, "cnr": cnr}


def replace_own(ok, share: float):
    """``ok`` with its own kernels scaled to sum to ``share`` (the ghost light's share
    taken off)."""
    from dataclasses import replace

    return replace(ok, own=ok.own * (share / ok.own_fraction))
