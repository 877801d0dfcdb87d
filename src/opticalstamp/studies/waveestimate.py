"""A design's search figures by wave optics: a fast estimator and the exact wave figures.

Where the validity rule (:mod:`~opticalstamp.analysis.validity`) says ray optics fails
(or where the user asks for wave optics), a search judges its candidates on their
wave-optical light, depth of field and crosstalk. The figures are those of
:func:`~opticalstamp.studies.evaluate.evaluate_design`, with the same keys, from:

* :func:`evaluate_wave`, the **wave estimator** of the search: the separable wave
  engine (:class:`~opticalstamp.analysis.wavecompare.WaveFolds`, the stack traversed once
  per evaluation) in the analyses' own band (``ESTIMATE_ORDERS``, the same 12 diffraction
  orders of the smallest hole over the own path's slopes) on the search's Z grid, for the
  own path with its diffraction and the near crosstalk in that band; the light outside
  the band (the far ghost paths) traced (importance sampling, at least 2^19 rays,
  :func:`far_light`) and joined where it lands, as the analyses join it; the RMTF
  crossings refined between heights by the exact figures' rule (``REFINE`` steps) up to
  the grid's first crossing, past which no height can move the depth of field. What
  makes it cheaper than the exact figures: its modes compressed to 1e-3 of the light
  (``ESTIMATE_MODE_TOL``) instead of 1e-10, the light from the folded LSFs instead of a
  separate efficiency analysis, one trace of 2^19 rays for the far light and the LSFs
  instead of 2^20 and 2^19. Its error against the exact wave figures is measured
  (``benchmarks/wave_estimator_accuracy.py``) and held in :data:`WAVE_ACCURACY`.
* :func:`exact_wave_figures`, the **exact wave figures** a front is verified with: the
  analyses' own interface, :func:`~opticalstamp.analysis.efficiency.efficiency` and
  :func:`~opticalstamp.analysis.rmtf.rmtf` with ``optics="wave"`` (the wave engine in its
  full band joined with the traced light beyond it, the RMTF with the traced light where
  it lands, the depth of field at the refined crossing).

The signal is the light in the band (the own path with its diffraction and the near
crosstalk; :func:`~opticalstamp.analysis.responsivity.pixel_light`), the ghost fraction
the traced light beyond the band over all the light, and the near-ghost test the
nearest landing of that traced light (the near crosstalk in the band is in the LSFs, so
in the RMTF and the depth of field, where it costs contrast).
"""

from __future__ import annotations

import math
from dataclasses import replace
from types import MappingProxyType

import numpy as np

from ..analysis.efficiency import reference_etendue
from ..analysis.rmtf import (
    DEFAULT_Z_MM,
    crossing_brackets,
    period_of_dpi,
    refine_crossings,
    rmtf_from_lsf,
)
from ..analysis.tallies import BandTally, run
from ..analysis.wavebase import ORDERS, wave_sampling
from ..design import Design
from ..design.resolution import dof_chart_dpi
from ..raytrace.pixel import PixelTracer, Sampling
from ..raytrace.stack import output_pitch
from .evaluate import GHOST_Z_MM, RMTF_Z_MM, Z_LIMIT_MM, diffraction_spill, extended_z
from .verify import GHOST_REGIME

#: diffraction orders of the smallest hole over the own path's slopes in the estimator's
#: band: the analyses' own (:data:`~opticalstamp.analysis.wavebase.ORDERS`). A narrower
#: band (4 orders until 2026-11-26) leaves out the diffraction halo of the holes' edges
#: beyond it, which the exact figures count: on 600-dpi designs whose spill is large
#: (holes 25/14/13 um) that read the RMTF up to 0.04 high and the depth of field up to
#: 0.8 mm long (docs/search.md)
ESTIMATE_ORDERS = ORDERS
#: Z steps of the estimator's refinement of its RMTF crossings: the exact figures' rule
#: (:func:`~opticalstamp.analysis.rmtf.rmtf`'s ``refine``). Ghost light at steep slopes
#: moves one chart period in tens of um of Z, so the RMTF can dip through the threshold
#: between heights 1/16 mm apart (4 steps until 2026-11-26 missed dips that 8 found)
REFINE = 8
#: The fewest rays the estimator traces the light beyond its band with (its
#: ``ghost_rays`` is raised to it): with fewer the importance sampling's pilot misses
#: rare far paths and undercounts the far light, a bias, not scatter (2^17 rays read it
#: 25-30 % low on holes 15/10/27 um over 400/937.5/75 um at 600 dpi and 14/8/12 um
#: over 400/359/116 um at 1200 dpi, the depth of field 0.47 and 0.15 mm long; 2^19 within
#: 3-10 % of 2^20 and the exact figures' depth of field within 0.09 mm), at a cost below
#: the wave part's
MIN_FAR_RAYS = 1 << 19
#: Relative power of the coherent modes the estimator leaves out when it compresses the
#: light leaving the stack (the exact figures: :data:`~opticalstamp.analysis.wavebase.
#: MODE_TOL`, 1e-10): the L1 error of its LSFs is at most this fraction of the light, so
#: its RMTF moves by at most twice it (0.002, about the traced part's standard error at
#: 2^19 rays), and a design's modes drop about 5-fold (179 -> 33 on holes 22/26/12 um at
#: 600 dpi), the cost of each height with them
ESTIMATE_MODE_TOL = 1e-3
#: how :func:`evaluate_wave` estimates, recorded with every figure it makes
WAVE_ESTIMATE = (
    f"wave estimator: separable wave engine in its band of {ESTIMATE_ORDERS:g} diffraction "
    f"orders, modes to {ESTIMATE_MODE_TOL:g} of the light (own path, its diffraction, near "
    "crosstalk) + traced light beyond the band where it lands, crossings refined in "
    f"{REFINE} steps"
)
#: how :func:`exact_wave_figures` estimates
EXACT_WAVE = (
    "exact wave figures: wave engine in its full band joined with the traced light beyond "
    "it (efficiency and rmtf with optics wave), RMTF with that light where it lands"
)
#: How far the wave estimator may be from the exact wave figures: the largest |estimate -
#: exact| measured by benchmarks/wave_estimator_accuracy.py (seed 0, 2026-11-26,
#: docs/search.md) on the 600-dpi half-scale prototype and 16 random designs of the 600-
#: and 1200-dpi search spaces with some light and contrast, times about 1.2 and rounded
#: up, in two regimes of the exact ghost fraction (below and from ``GHOST_REGIME``, 0.2):
#: depth of field in mm (largest 0.010 below, 0.087 from it: a curve that hovers near the
#: threshold from 0.56 to 0.65 mm, ghost fraction 0.22), RMTF at 1, 2, 3 mm (largest
#: 0.0012; the mode compression alone may move it 0.002) and ghost fraction in absolute
#: units (0.018), the light as a relative error (0.47 %, always low: the compressed
#: modes). A depth of field where the RMTF hovers within the RMTF error of the threshold
#: can still move further: the figure is ill-conditioned there for any estimator.
WAVE_ACCURACY = MappingProxyType(
    {
        "dof_mm": 0.02,
        "rmtf": 0.003,
        "efficiency_ratio": 0.006,
        "ghost_fraction": 0.025,
        "dof_mm_high_ghost": 0.11,
        "rmtf_high_ghost": 0.003,
        "ghost_fraction_high_ghost": 0.025,
    }
)


def far_light(
    design: Design,
    band: float,
    *,
    z_mm=GHOST_Z_MM,
    n_rays: int = 1 << 17,
    seed: int = 0,
    tracer: PixelTracer | None = None,
) -> dict:
    """The traced light of used pixel (A, 0) beyond the wave band, |s_x| or |s_y| >=
    ``band`` (the far ghost paths: the own path lies inside the band), and where it lands.

    Returns
    -------
    dict
        ``far_um2sr`` (um^2 sr), ``nearest_far_mm``: the nearest landing of that light
        from the pixel's axis on the object planes ``z_mm`` (inf: none lands),
        ``ray_in_band_um2sr`` (the traced light inside the band, for reference).
    ``tracer``: a PixelTracer of this design whose pilot runs to reuse.
    """
    tr = tracer if tracer is not None else PixelTracer(design, Sampling(n_rays, seed))
    t = BandTally(band, z_mm)
    run(tr, (0, 0), [t], n_rays)
    return {
        "far_um2sr": t.far / n_rays,
        "nearest_far_mm": t.nearest / 1000.0,
        "ray_in_band_um2sr": t.inside / n_rays,
    }


def until_first_crossing(
    z_new: np.ndarray, z_grid: np.ndarray, curve: np.ndarray, threshold: float
) -> np.ndarray:
    """The heights ``z_new`` (mm) of a refinement that can move the depth of field of the
    RMTF ``curve`` sampled at ``z_grid``: those below the grid's first sample under
    ``threshold`` (all of them where none is under it; none where the curve starts under
    it, the depth of field is then 0 whatever lies between). The depth of field is the
    first crossing (:func:`~opticalstamp.analysis.dof.depth_of_field`): a sample past
    the grid's first one under the threshold can neither precede it nor bracket a crossing
    before it, so the refined depth of field is the same as with every height refined,
    bit for bit (each height's RMTF is computed on its own). What it leaves out are the
    ends of the spurious ranges past it, which the estimator does not report."""
    z_new = np.asarray(z_new, dtype=np.float64)
    c = np.asarray(curve, dtype=np.float64)
    if c.size == 0 or c[0] < threshold:
        return z_new[:0]
    below = np.flatnonzero(c < threshold)
    if below.size == 0:
        return z_new
    return z_new[z_new < float(np.asarray(z_grid, dtype=np.float64)[below[0]])]


def _joined_lsf(design: Design, zs: np.ndarray, per: float, folds, n_rays: int, seed: int, tracer):
    """The wave engine's folded LSFs (``folds``: a
    :class:`~opticalstamp.analysis.wavecompare.WaveFolds`, the stack traversed once for
    every call) joined with the traced light beyond its band where it lands
    (:func:`~opticalstamp.analysis.responsivity.join`), on the one chart period ``per`` at
    each of ``zs``."""
    from ..analysis.lsf import traced_folded_lsf
    from ..analysis.responsivity import join

    band = folds.sampling.band
    wave = folds.folded(zs, [per])
    far = traced_folded_lsf(
        design, z_mm=zs, periods_um=[per], n_rays=n_rays, seed=seed, ghosts=True,
        tracer=tracer, outside_band=band,
    )  # fmt: skip
    return wave, join(wave, far, band, float(design.index(design.object_medium)))


def evaluate_wave(
    design: Design,
    *,
    dpi: float | None = None,
    z_mm=DEFAULT_Z_MM,
    rmtf_z_mm=RMTF_Z_MM,
    dof_threshold: float = 0.3,
    near_mm: float = 1.0,
    ghost_rays: int = MIN_FAR_RAYS,
    seed: int = 0,
    wavelength_um: float | None = None,
    restored: bool = False,
    orders: float = ESTIMATE_ORDERS,
    refine: int = REFINE,
    mode_tol: float = ESTIMATE_MODE_TOL,
) -> dict:
    """The figures of :func:`~opticalstamp.studies.evaluate.evaluate_design` by the wave
    estimator (``"estimator"``: :data:`WAVE_ESTIMATE`, ``"optics"``: "wave").

    The wave engine's LSFs of rows A and B folded onto the chart of ``dpi`` at each
    ``z_mm`` (the grid runs on in its step while the RMTF stays above the threshold, up
    to 20 mm), in the band of ``orders`` diffraction orders
    (:func:`~opticalstamp.analysis.wavebase.wave_sampling`), the light leaving the stack
    compressed to its coherent modes to ``mode_tol`` of its power, the crossings refined
    in ``refine`` steps by the exact figures' rule
    (:func:`~opticalstamp.analysis.rmtf.crossing_brackets`) up to the grid's first
    crossing (:func:`until_first_crossing`: the depth of field is the same); the light
    beyond the band traced with ``ghost_rays`` rays, at least :data:`MIN_FAR_RAYS`
    (:func:`far_light`). The signal
    (efficiency) is the light in the band at Z = 0, the ghost fraction the light beyond
    it over all. The diffraction spill (closed form, at ``wavelength_um``) is reported,
    not judged; the restored depth of field (``restored``) is the closed form at this
    ghost fraction.
    """
    from ..analysis.wavecompare import WaveFolds

    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    ghost_rays = max(int(ghost_rays), MIN_FAR_RAYS)
    smp = replace(wave_sampling(design, orders=orders), mode_tol=mode_tol)
    tracer = PixelTracer(design, Sampling(ghost_rays, seed), replay=True)
    far = far_light(design, smp.band, n_rays=ghost_rays, seed=seed, tracer=tracer)
    per = period_of_dpi(dpi)
    zs = np.asarray(z_mm, dtype=np.float64)
    key = f"{dpi:g}"
    folds = None
    while True:
        if folds is None or folds.z_max_mm < zs.max():  # the stack traversed once per reach
            folds = WaveFolds(design, float(zs.max()), sampling=smp)
        wave, lsf = _joined_lsf(design, zs, per, folds, ghost_rays, seed, tracer)
        res = rmtf_from_lsf(lsf, design, dpi=[dpi], seed=seed, dof_threshold=dof_threshold,
                            dof_dpi=dpi)  # fmt: skip
        curve = np.asarray(res.rmtf_max[key])
        if curve.min() < dof_threshold or zs[-1] >= Z_LIMIT_MM:
            break
        zs = extended_z(zs)  # the depth of field is a crossing: go on in the same step
    # the crossings found again between the grid's heights by the exact figures' rule
    # (an RMTF near the threshold dips between heights where ghost light moves fast),
    # up to the grid's first crossing: no height past it can move the depth of field
    fine = until_first_crossing(crossing_brackets([res], refine), zs, curve, dof_threshold)
    if refine > 1 and fine.size:
        lsf_fine = _joined_lsf(design, fine, per, folds, ghost_rays, seed, tracer)[1]
        # one batch: the refined heights' standard errors (the RMTF of each of the 16
        # batches) feed only the range at +-2 SE and a second round, neither of which
        # the estimator makes; the RMTF itself is of the batches' sum either way
        one = [h.sum(axis=1, keepdims=True) for h in lsf_fine.h]
        res = refine_crossings(res, replace(lsf_fine, h=one), design)
    own = float(wave.h[0][0, 0, 0].sum())  # row A's in-band light at the first Z
    ghost = far["far_um2sr"]
    tot = own + ghost
    frac = ghost / tot if tot > 0 else 0.0
    ref = reference_etendue(output_pitch(design))
    restored_dof = None
    if restored:
        from .restoration import restored_dof_closed_form

        restored_dof = restored_dof_closed_form(design, dpi=dpi, ghost_fraction=frac)["dof_mm"]
    return {
        "estimator": WAVE_ESTIMATE,
        "optics": "wave",
        "band": smp.band,
        "restored_dof_mm": restored_dof,
        "etendue_own_um2sr": own,
        "etendue_ghost_um2sr": ghost,
        "ghost_fraction": frac,
        "efficiency_ratio": own / ref,
        "efficiency_ratio_total": tot / ref,
        "dof_mm": res.dof_mm[key],
        "dof_open_ended": bool(curve.min() >= dof_threshold),
        "rmtf_at": {f"{z:g}": float(np.interp(z, zs, curve)) for z in rmtf_z_mm},
        "nearest_ghost_mm": far["nearest_far_mm"],
        "near_ghost": far["nearest_far_mm"] < near_mm,
        "diffraction_spill": diffraction_spill(design, wavelength_um),
        "stack_um": float(sum(sl.thickness_um for sl in design.slabs)),
    }


#: rays of the exact wave figures: the traced light beyond the band and the LSFs' far part
EXACT_WAVE_GHOST_RAYS = 1 << 20
EXACT_WAVE_LSF_RAYS = 1 << 19


def exact_wave_figures(
    design: Design,
    *,
    dpi: float | None = None,
    z_mm=DEFAULT_Z_MM,
    rmtf_z_mm=RMTF_Z_MM,
    dof_threshold: float = 0.3,
    near_mm: float = 1.0,
    ghost_rays: int = EXACT_WAVE_GHOST_RAYS,
    lsf_rays: int = EXACT_WAVE_LSF_RAYS,
    seed: int = 0,
) -> dict:
    """The figures of :func:`evaluate_wave` from the analyses' wave optics (``"estimator"``:
    :data:`EXACT_WAVE`): the light by :func:`~opticalstamp.analysis.efficiency.efficiency`
    with ``optics="wave"`` (signal: ``ratio_own``, the light in the full band; all light:
    ``ratio``), the RMTF and depth of field by :func:`~opticalstamp.analysis.rmtf.rmtf`
    with ``optics="wave"`` on the chart of ``dpi`` (the grid run on past ``z_mm`` until the
    curve crosses, up to 20 mm), the near-ghost test on the traced light beyond the full
    band (:func:`far_light`, ``ghost_rays``). No diffraction spill (it is not estimated).
    """
    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    from ..analysis.efficiency import efficiency
    from ..analysis.ghosts import analyse_ghosts
    from ..analysis.responsivity import resolve_optics
    from ..analysis.rmtf import rmtf

    opt = resolve_optics(design, "wave")
    # one tracer for every analysis below: each pixel's pilot computed once, the rays
    # the ghost analysis traced handed out again to the far light's tally (the same
    # figures as with a tracer each)
    tracer = PixelTracer(design, Sampling(ghost_rays, seed), replay=True)
    g = analyse_ghosts(design, z_mm=GHOST_Z_MM, n_rays=ghost_rays, seed=seed, tracer=tracer)
    eff = efficiency(design, seed=seed, ghosts=g, area_scales=(1.0,), optics=opt, tracer=tracer)
    far = far_light(design, opt.band, n_rays=ghost_rays, seed=seed, tracer=tracer)
    zs = np.asarray(z_mm, dtype=np.float64)
    key = f"{dpi:g}"
    while True:
        r = rmtf(
            design, dpi=(dpi,), z_mm=zs, n_rays=lsf_rays, seed=seed, dof_dpi=dpi,
            dof_threshold=dof_threshold, optics=opt, tracer=tracer,
        )  # fmt: skip
        curve = np.asarray(r.rmtf_max[key])
        if curve.min() < dof_threshold or zs[-1] >= Z_LIMIT_MM:
            break
        zs = extended_z(zs)
    tot = eff.ratio
    return {
        "estimator": EXACT_WAVE,
        "optics": "wave",
        "band": opt.band,
        "etendue_own_um2sr": eff.etendue_own_um2sr,
        "etendue_ghost_um2sr": max(eff.etendue_um2sr - eff.etendue_own_um2sr, 0.0),
        "ghost_fraction": max(1.0 - eff.ratio_own / tot, 0.0) if tot > 0 else 0.0,
        "efficiency_ratio": eff.ratio_own,
        "efficiency_ratio_total": tot,
        "dof_mm": r.dof_mm[key],
        "dof_open_ended": bool(curve.min() >= dof_threshold),
        "rmtf_at": {f"{z:g}": float(np.interp(z, zs, curve)) for z in rmtf_z_mm},
        "rmtf_se_max": float(max(r.rmtf_max_se[key])),
        "nearest_ghost_mm": far["nearest_far_mm"],
        "near_ghost": far["nearest_far_mm"] < near_mm,
        "stack_um": float(sum(sl.thickness_um for sl in design.slabs)),
    }


def wave_errors(estimate: dict, exact: dict) -> dict:
    """|estimate - exact| of the figures :data:`WAVE_ACCURACY` bounds: ``dof_mm``,
    ``rmtf`` (the largest over the heights both have), ``efficiency_ratio`` (relative),
    ``ghost_fraction``."""
    e_s, e_x = estimate["efficiency_ratio"], exact["efficiency_ratio"]
    rel = abs(e_s / e_x - 1) if e_x > 0 else (0.0 if e_s == 0 else math.inf)
    zs = [z for z in estimate.get("rmtf_at", {}) if z in exact.get("rmtf_at", {})]
    return {
        "dof_mm": abs(estimate["dof_mm"] - exact["dof_mm"]),
        "rmtf": max((abs(estimate["rmtf_at"][z] - exact["rmtf_at"][z]) for z in zs), default=0),
        "efficiency_ratio": rel,
        "ghost_fraction": abs(estimate["ghost_fraction"] - exact["ghost_fraction"]),
    }


def wave_disagreements(estimate: dict, exact: dict, accuracy=WAVE_ACCURACY) -> list[str]:
    """The figures where the wave estimator is further from the exact wave figures than
    its stated accuracy (:data:`WAVE_ACCURACY`, in the regime of the exact ghost fraction,
    below or from ``GHOST_REGIME``), and "near_ghost" where the exact figures find
    traced light beyond the band near the pixel that the estimator's rays missed."""
    out = []
    if exact.get("near_ghost") and not estimate.get("near_ghost", False):
        out.append("near_ghost")
    high = "_high_ghost" if exact.get("ghost_fraction", 0.0) >= GHOST_REGIME else ""
    err = wave_errors(estimate, exact)
    for k in ("dof_mm", "efficiency_ratio", "ghost_fraction"):
        if err[k] > accuracy.get(k + high, accuracy[k]):
            out.append(k)
    bound = accuracy.get("rmtf" + high, accuracy["rmtf"])
    for z, v in estimate.get("rmtf_at", {}).items():
        if z in exact.get("rmtf_at", {}) and abs(v - exact["rmtf_at"][z]) > bound:
            out.append(f"rmtf@{z}")
    return out


def optics_used_text(results: dict) -> str:
    """One line: how many candidates of the searches ``results`` ({name: SearchResult})
    each engine judged, and the wave estimator's stated accuracy where it judged any."""
    used: dict[str, int] = {}
    for res in results.values():
        for k, v in res.meta.get("optics_used", {}).items():
            used[k] = used.get(k, 0) + v
    asked = next(iter(results.values())).meta.get("optics", "ray")
    text = f"optics {asked}: " + ", ".join(
        f"{v} judged by {'wave optics' if k == 'wave' else 'ray optics'}"
        for k, v in sorted(used.items())
    )
    if used.get("wave"):
        text += f" ({wave_estimator_text()})"
    return text


def wave_estimator_text() -> str:
    """The wave estimator and its stated accuracy (:data:`WAVE_ACCURACY`), in words."""
    a = WAVE_ACCURACY
    return (
        f"wave estimator, {ESTIMATE_ORDERS:g} diffraction orders; stated accuracy against "
        f"the exact wave figures: depth of field {a['dof_mm']:g} mm, RMTF {a['rmtf']:g}, "
        f"light {a['efficiency_ratio']:.0%}, ghost fraction {a['ghost_fraction']:g} "
        f"(ghost fraction >= {GHOST_REGIME:g}: depth of field {a['dof_mm_high_ghost']:g} mm, "
        f"RMTF {a['rmtf_high_ghost']:g}, ghost fraction {a['ghost_fraction_high_ghost']:g})"
    )
