"""Which optics holds for a design: the ray and wave figures judged against stated
tolerances (issue 23).

:func:`~opticalstamp.analysis.wavecompare.compare_wave_ray` measures one design's light,
spot and RMTF by the tracer and by the wave engine in the same band; :func:`judge` turns
those measured differences into a verdict. Ray optics holds where the two engines agree
within :data:`LIGHT_TOLERANCE` in light (wave / ray - 1) and within
:data:`RMTF_TOLERANCE` (absolute) in RMTF on the depth-of-field chart at every height
compared; otherwise diffraction dominates and the wave figures are the ones to use. Both
depths of field come from the compared curves by one rule
(:func:`~opticalstamp.analysis.dof.depth_of_field`: the first 0.3 crossing, interpolated
linearly between the heights), so they differ only by the physics, not by the sampling.
"""

from __future__ import annotations

import math

import numpy as np

from ..defaults import DOF_THRESHOLD
from .dof import depth_of_field

#: why no wave figures for a design with circular holes unless asked for: the 2-D path
#: (:mod:`.wave2dmaps`) takes minutes a height on a CPU
NEEDS_RECTANGLES = (
    "holes that are not rectangles take the 2-D path of the wave engine, minutes a height on "
    "a CPU: ask for it with --optics wave (report, compare) or opticalstamp wave, or run on "
    "a CUDA GPU with CuPy"
)
#: Ray optics holds where the wave light is within this fraction of the ray light
LIGHT_TOLERANCE = 0.05
#: ... and the wave RMTF within this (absolute) of the ray RMTF at every height compared
RMTF_TOLERANCE = 0.05


def sub_grid(grid_mm, step_mm: float, max_heights: int) -> tuple[float, ...]:
    """Heights of ``grid_mm`` (mm, ascending) that are whole multiples of ``step_mm``
    from its first, with its last; the step doubled until at most ``max_heights`` remain
    (a longer grid is sampled more coarsely, not cut short)."""
    g = np.asarray(sorted(float(z) for z in grid_mm))
    if g.size == 0:
        raise ValueError("heights: the grid is empty")
    if not step_mm > 0 or max_heights < 2:
        raise ValueError("heights: the step must be > 0 and at least 2 heights kept")
    step = float(step_mm)
    while True:
        k = np.round((g - g[0]) / step)
        on = np.abs(g - g[0] - k * step) < 1e-6 * max(step, 1.0)
        picked = sorted({float(z) for z in g[on]} | {float(g[-1])})
        if len(picked) <= max_heights:
            return tuple(picked)
        step *= 2


def compare_and_judge(design, z_mm, **kwargs):
    """:func:`~opticalstamp.analysis.wavecompare.compare_wave_ray` (``kwargs`` passed on)
    and its :func:`judge`: (comparison, verdict).

    Raises
    ------
    ValueError
        Where the rays find no light in the band (a stack that blocks its own path: the
        comparison's ratios divide by zero), or neither engine finds any.
    """
    from .wavecompare import compare_wave_ray

    try:
        with np.errstate(divide="ignore", invalid="ignore"):
            c = compare_wave_ray(design, z_mm, **kwargs)
    except ZeroDivisionError:
        raise ValueError(
            "the rays find no light through the pixel's own holes, so there is no ray figure "
            "to compare the wave figures with"
        ) from None
    return c, judge(c)


def _dof(z: np.ndarray, r: np.ndarray) -> tuple[float, bool]:
    """Depth of field (mm) of a curve and whether the curve never fell below the
    threshold within the heights (then the figure is a lower bound)."""
    return depth_of_field(z, r, DOF_THRESHOLD), bool(np.all(r >= DOF_THRESHOLD))


def judge(c) -> dict:
    """The verdict on which optics holds for the design of comparison ``c``.

    Parameters
    ----------
    c : :class:`~opticalstamp.analysis.wavecompare.WaveRayComparison`

    Returns
    -------
    dict
        ``holds`` ("ray" or "wave"), ``light_difference`` (wave / ray - 1; None where the
        tracer finds no light in the band), ``rmtf_difference_max`` (wave - ray at the
        height where it is largest in size) and ``rmtf_difference_at_z_mm``, ``dof_mm``
        and ``dof_open_ended`` of each engine on the chart of ``dof_dpi``,
        ``fresnel_min``, ``tolerances`` and ``text``, the verdict in words.

    Raises
    ------
    ValueError
        Where neither engine finds light in the band (nothing to judge).
    """
    w_light, r_light = float(c.wave["light_um2sr"]), float(c.ray["light_um2sr"])
    if not (w_light > 0 or r_light > 0):
        raise ValueError("no light reaches the pixel in the wave band by either engine")
    z = np.asarray(c.z_mm, dtype=np.float64)
    rw = np.asarray(c.wave["rmtf"], dtype=np.float64)
    rr = np.asarray(c.ray["rmtf"], dtype=np.float64)
    light = w_light / r_light - 1 if r_light > 0 else None
    d = rw - rr
    if r_light > 0 and w_light > 0 and np.all(np.isfinite(d)):
        i = int(np.argmax(np.abs(d)))
        d_max, z_max = float(d[i]), float(z[i])
    else:  # one engine finds no light: its RMTF means nothing
        d_max, z_max = None, None
    dof_w, open_w = _dof(z, rw)
    dof_r, open_r = _dof(z, rr)
    ok_light = light is not None and abs(light) <= LIGHT_TOLERANCE
    ok_rmtf = d_max is not None and abs(d_max) <= RMTF_TOLERANCE
    out = {
        "holds": "ray" if ok_light and ok_rmtf else "wave",
        "light_difference": light,
        "rmtf_difference_max": d_max,
        "rmtf_difference_at_z_mm": z_max,
        "dof_dpi": float(c.dof_dpi),
        "dof_mm": {"wave": dof_w, "ray": dof_r},
        "dof_open_ended": {"wave": open_w, "ray": open_r},
        "dof_threshold": DOF_THRESHOLD,
        "fresnel_min": min(f["fresnel_number"] for f in c.fresnel) if c.fresnel else None,
        "tolerances": {"light": LIGHT_TOLERANCE, "rmtf": RMTF_TOLERANCE},
    }
    out["text"] = verdict_text(out)
    return out


def _pct(x: float, sign: bool = False) -> str:
    return f"{x * 100:{'+' if sign else ''}.1f} %"


def _dof_words(j: dict, engine: str) -> str:
    v = j["dof_mm"][engine]
    return f"{'≥ ' if j['dof_open_ended'][engine] else ''}{v:.2f} mm"


def verdict_text(j: dict) -> str:
    """The verdict of :func:`judge` in plain words (one sentence)."""
    tol = j["tolerances"]
    tol_l = f"{tol['light'] * 100:g} %"
    light, d_max = j["light_difference"], j["rmtf_difference_max"]
    chart = f"the {j['dof_dpi']:g}-dpi chart"
    dof = (
        f"depth of field of the light in the band (own path and near crosstalk, no far "
        f"ghosts) {_dof_words(j, 'wave')} by wave against {_dof_words(j, 'ray')} by rays"
    )
    if j["holds"] == "ray":
        return (
            f"Ray optics holds for this design: wave and ray agree within the tolerances "
            f"(light wave/ray {_pct(light, True)}, within ±{tol_l}; RMTF on "
            f"{chart} within {abs(d_max):.3f} at every height, within ±{tol['rmtf']:g}); "
            f"{dof}."
        )
    wrong, right = [], []
    if light is None:
        wrong.append("find no light in the band where the waves find some")
    elif abs(light) > tol["light"]:
        ray_over_wave = 1 / (1 + light) - 1 if light > -1 else math.inf
        word = "understate" if ray_over_wave < 0 else "overstate"
        wrong.append(
            f"{word} the light by {_pct(abs(ray_over_wave))} (wave/ray {_pct(light, True)})"
        )
    else:
        right.append(f"the light agrees (wave/ray {_pct(light, True)})")
    if d_max is not None and abs(d_max) > tol["rmtf"]:
        word = "overstate" if d_max < 0 else "understate"
        wrong.append(
            f"{word} the RMTF on {chart} by up to {abs(d_max):.2f} "
            f"(at Z = {j['rmtf_difference_at_z_mm']:g} mm)"
        )
    elif d_max is not None:
        right.append(f"the RMTF on {chart} agrees within {abs(d_max):.3f}")
    return (
        "Diffraction dominates: ray optics does not hold for this design — the ray figures "
        + " and ".join(wrong)
        + "".join(f"; {x}" for x in right)
        + f"; {dof} (tolerances: light ±{tol_l}, RMTF ±{tol['rmtf']:g})."
    )
