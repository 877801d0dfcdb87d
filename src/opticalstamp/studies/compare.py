"""Designs of any kind side by side: light, thickness, depth of field, ghosts.

Every design is evaluated with the definitions shared by both kinds:

* ``light_vs_f10``: etendue of one output pixel from a uniform Lambertian object over the
  paper's F/10 1:1 reference lens for the same pixel. For a stamp, own-path light only
  (ghost light is crosstalk, not signal); for a rod-lens array, averaged over the pixel's
  position along the array. ``working_f_number`` = 10 / sqrt(light_vs_f10).
* ``thickness_mm``: from the sensor surface to the document reference (a stamp's
  reference plane Z = 0; a rod-lens array's cover-glass top, or its nominal object plane
  TC when it has no cover glass).
* Heights: measured from the document reference, positive away from the scanner, for
  both kinds. A stamp's nominal object plane is its reference plane (its contrast is
  highest there and the document cannot come closer); a rod-lens array's is its focus.
* ``dof_mm``: heights where the contrast on one chart for every design (shading-corrected
  RMTF, maximised over the chart's shift) stays >= 0.3 — by default the first design's
  depth-of-field chart, 2/3 of its resolution (200 dpi for a 300-dpi design), ``dof_dpi``
  in every row —, as ``[low, high]`` relative to the nominal object
  plane, ``dof_span_mm`` their span; each end at the first crossing from the best height
  (``dof_detail``: whether an end is the grid's, and a note).
* ``ghost_fraction``: the stamp's traced ghost light over all traced light (by ray optics
  whatever the optics of the light columns, as ``ghosts`` and the report); 0 for a rod-lens
  array, whose model has no stray path (skin and resin absorb: ``ghost_note`` says so).
* ``fresnel_min``: the smallest Fresnel number a^2/(lambda d) of the stamp's masks over
  the gaps below them (:func:`~opticalstamp.analysis.wavebase.fresnel_numbers`); None
  for a rod-lens array. ``wave``: ray against wave optics on the same chart at
  :data:`WAVE_HEIGHTS_MM` (:func:`wave_figures`: the wave/ray light ratio, the RMTF and
  depth of field of the own path and near crosstalk by both engines, which optics holds);
  for circular holes ``{"not_measurable": reason}`` unless wave optics is asked for (or
  the run has a GPU with CuPy), for a rod-lens array ``{"note": "n/a (not an aperture
  stack)"}``.
* ``optics``: the engine of a stamp's light, contrast and depth of field (``optics``
  argument: "ray", "wave" or "auto", each stamp by its own validity rule), and why.
"""

from __future__ import annotations

import math

import numpy as np

from ..analysis.efficiency import efficiency
from ..analysis.raywave import NEEDS_RECTANGLES, compare_and_judge
from ..analysis.rmtf import rmtf
from ..analysis.rodlens import RAYS_CONTRAST, rod_contrast, rod_efficiency
from ..defaults import Z_GRID_MM
from ..design import AnyDesign, Design, RodLensDesign
from ..design.resolution import dof_chart_dpi
from ..validate import parse_grid

#: The rod-lens presets a report compares its design with (docs/rodlens.md).
RODLENS_PRESETS = ("sla-1row-12deg", "sla-2row-20deg")
#: Chart resolutions of the overlay plot (dpi).
COMPARE_DPI = (100.0, 200.0, 300.0)
#: Heights (mm from the document reference) of a stamp's contrast curve.
STAMP_HEIGHTS_MM = parse_grid(Z_GRID_MM, "z_mm", 0.0, 100.0)
#: Heights (mm from the document reference) of the text scanned by each design.
TEXT_HEIGHTS_MM = (0.0, 0.5, 1.0, 2.0)
#: Fraction of the full well that white fills in the text scans (auto-exposure).
WHITE_FILL = 0.8
#: Sampling (dpi) of the text document scanned by each design.
TEXT_DPI = 600.0
#: Heights (mm from the nominal object plane) of a rod-lens array's contrast curve.
ROD_HEIGHTS_MM = tuple(np.round(np.arange(-1.5, 1.5001, 0.125), 6))
#: Heights (mm from the reference plane) of a stamp's ray-vs-wave comparison: a few, the
#: wave engine's cost grows with each (finer where a 600-dpi stamp's RMTF falls).
WAVE_HEIGHTS_MM = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0)
#: Rays per pixel row of the ray side of that comparison.
WAVE_RAYS = 1 << 19
#: A rod-lens array's ray-vs-wave entry: it has no aperture stack to diffract.
NOT_A_STACK = "n/a (not an aperture stack)"


def _kind(design: AnyDesign) -> str:
    return "rod-lens-array" if isinstance(design, RodLensDesign) else "stamp"


def evaluate_stamp(
    design: Design,
    *,
    seed: int = 0,
    fresnel: bool = False,
    dof_dpi: float | None = None,
    optics: str = "ray",
) -> dict:
    """A stamp's comparison figures; ``optics`` ("ray", "wave", "auto") gives its light,
    contrast and depth of field (:func:`~opticalstamp.analysis.responsivity.
    resolve_optics`; ``optics`` in the row says which engine and why)."""
    eff = efficiency(
        design, seed=seed, fresnel=fresnel, area_scales=(1.0,), z_mm=(0.0,), optics=optics
    )
    r = rmtf(
        design,
        dpi=COMPARE_DPI,
        z_mm=STAMP_HEIGHTS_MM,
        seed=seed,
        fresnel=fresnel,
        dof_dpi=dof_dpi,
        optics=optics,
    )
    row = stamp_row(design, eff, r) | {"optics": r.meta.get("optics")}
    return row | wave_figures(design, seed=seed, dof_dpi=r.dof_dpi, optics=optics)


def wave_figures(
    design: Design, *, seed: int = 0, dof_dpi: float | None = None, optics: str = "ray"
) -> dict:
    """A stamp's ``fresnel_min`` and ``wave`` (see the module's docstring): the wave
    engine against the tracer in its band at :data:`WAVE_HEIGHTS_MM`, ``WAVE_RAYS`` rays
    per pixel row, on the ``dof_dpi`` chart (default the design's). Holes that are not
    rectangles take the wave engine's 2-D path (minutes a height on a CPU): measured
    where ``optics`` is "wave" or the run's device is a GPU with CuPy, else
    ``{"not_measurable": reason}``."""
    from ..analysis.wave2dmaps import maps_on_gpu
    from ..analysis.wavebase import fresnel_numbers, rectangular

    fres = fresnel_numbers(design)
    out: dict = {"fresnel_min": min(f["fresnel_number"] for f in fres) if fres else None}
    if not rectangular(design) and optics != "wave" and not maps_on_gpu():
        return out | {"wave": {"not_measurable": NEEDS_RECTANGLES}}
    try:
        c, v = compare_and_judge(
            design, WAVE_HEIGHTS_MM, n_rays=WAVE_RAYS, seed=seed, dof_dpi=dof_dpi
        )
    except ValueError as err:  # no ray light to compare with
        return out | {"wave": {"not_measurable": str(err)}}
    light = v["light_difference"]
    return out | {
        "wave": {
            "holds": v["holds"],
            "light_wave_over_ray": None if light is None else 1 + light,
            "light_wave_um2sr": c.wave["light_um2sr"],
            "light_ray_um2sr": c.ray["light_um2sr"],
            "heights_mm": list(c.z_mm),
            "dof_dpi": c.dof_dpi,
            "rmtf_wave": c.wave["rmtf"],
            "rmtf_ray": c.ray["rmtf"],
            "dof_wave_mm": v["dof_mm"]["wave"],
            "dof_ray_mm": v["dof_mm"]["ray"],
            "dof_open_ended": v["dof_open_ended"],
            "rmtf_difference_max": v["rmtf_difference_max"],
            "tolerances": v["tolerances"],
            "verdict": v["text"],
            "wavelength_um": c.sampling["wavelength_um"],
            "spectrum": c.meta.get("spectrum"),
            "band": c.sampling["band"],
            "n_rays": WAVE_RAYS,
            "note": "own path and near crosstalk in the wave band, by both engines (the far "
            "ghost light, in dof_mm, is left out on both sides); depth of field "
            "interpolated between these heights",
        }
    }


def stamp_row(design: Design, eff, r) -> dict:
    """A stamp's comparison figures from its efficiency and (traced) RMTF results."""
    key = f"{r.dof_dpi:g}"
    high = float(r.dof_mm[key])
    wave = eff.own_method.startswith("wave")
    # the traced ghost light over all traced light, as `ghosts` and the report give it: the
    # wave engine's band holds the own path and the near crosstalk together, so a ghost
    # share over its light would divide ray ghosts by wave light (two engines in a ratio)
    traced = eff.etendue_own_traced_um2sr + eff.etendue_ghost_um2sr if wave else eff.etendue_um2sr
    ghost = eff.etendue_ghost_um2sr / traced if traced > 0 else 0.0
    far = 1.0 - eff.etendue_own_um2sr / eff.etendue_um2sr if wave and eff.etendue_um2sr > 0 else 0.0
    return {
        "light_vs_f10": eff.ratio_own,
        "light_vs_f10_se": eff.etendue_own_se / eff.reference_etendue_um2sr,
        "light_vs_f10_with_ghosts": eff.ratio,
        "working_f_number": eff.working_f_number_own,
        "thickness_mm": design.reference_plane_um / 1000,
        "nominal_object_plane_mm": 0.0,
        "dof_mm": [0.0, high],
        "dof_span_mm": high,
        "dof_detail": {
            "clipped_low": False,
            "clipped_high": bool(high >= r.z_mm[-1]),
            "note": "low end: the reference plane, the closest a document can come",
        },
        "dof_dpi": r.dof_dpi,
        "ghost_fraction": ghost,
        "ghost_note": "traced ghost (crosstalk) light over all light reaching the pixel"
        + (
            ", by ray optics as `opticalstamp ghosts` and the report give it (the light "
            "columns are wave optics': its band holds the own path and the near crosstalk "
            f"together; the traced light beyond the band, the far ghosts, is {far:.3g} of "
            "all light there)"
            if wave
            else ""
        ),
        "contrast": {
            "heights_mm": list(r.z_mm),
            "by_dpi": {
                k: list(v)
                for k, v in r.rmtf_max.items()
                if float(k) in COMPARE_DPI or float(k) == r.dof_dpi
            },
        },
        "estimator": r.method,
    }


def evaluate_rodlens(
    design: RodLensDesign,
    *,
    seed: int = 0,
    fresnel: bool = False,
    dpi=COMPARE_DPI,
    heights_mm=ROD_HEIGHTS_MM,
    n_rays: int = RAYS_CONTRAST,
    dof_dpi: float | None = None,
) -> dict:
    """A rod-lens array's comparison figures (``dpi``, ``heights_mm``, ``n_rays``: of the
    contrast curves; the depth of field, on the ``dof_dpi`` chart, is refined by
    bisection whatever the grid)."""
    eff = rod_efficiency(design, seed=seed, fresnel=fresnel)
    dof_dpi = dof_chart_dpi(design) if dof_dpi is None else float(dof_dpi)
    con = rod_contrast(
        design,
        dpi=sorted({float(d) for d in dpi} | {dof_dpi}),
        heights_mm=heights_mm,
        n_rays=n_rays,
        seed=seed,
        fresnel=fresnel,
        dof_dpi=dof_dpi,
    )
    a = design.array
    return {
        "light_vs_f10": eff.ratio,
        "light_vs_f10_se": eff.ratio_se,
        "working_f_number": eff.working_f_number,
        "ripple": eff.ripple,
        "ripple_noise": eff.ripple_noise,
        "thickness_mm": design.reference_plane_um / 1000,
        "conjugate_length_mm": a.conjugate_um / 1000,
        "rod_length_mm": a.length_um / 1000,
        "working_distance_mm": a.working_um / 1000,
        "nominal_object_plane_mm": 0.0,
        "dof_mm": [con.dof_mm["low"], con.dof_mm["high"]],
        "dof_span_mm": con.dof_mm["span"],
        "dof_detail": {
            k: con.dof_mm[k] for k in ("clipped_low", "clipped_high", "usable_from_reference")
        }
        | {"note": "each end at the first 0.3 crossing from the best focus"},
        "dof_dpi": con.dof_dpi,
        "ghost_fraction": 0.0,
        "ghost_note": "no stray path in the model: rod skin and black resin absorb",
        "contrast": {
            "heights_mm": con.heights_mm,
            "by_dpi": {f"{d:g}": row for d, row in zip(con.dpi, con.contrast, strict=True)},
        },
        "mtf": {
            "heights_mm": con.heights_mm,
            "by_dpi": {f"{d:g}": row for d, row in zip(con.dpi, con.mtf, strict=True)},
        },
        "lsf": {"x_um": con.lsf_x_um, "heights_mm": con.heights_mm, "per_um": con.lsf},
        "ripple_profile": {
            "positions_um": eff.positions_um,
            "relative": (np.asarray(eff.etendue_by_position_um2sr) / eff.etendue_um2sr).tolist(),
        },
        "estimator": "trace",
        "fresnel_min": None,
        "wave": {"note": NOT_A_STACK},
    }


def evaluate(
    design: AnyDesign,
    *,
    seed: int = 0,
    fresnel: bool = False,
    dof_dpi: float | None = None,
    optics: str = "ray",
) -> dict:
    """One design's comparison figures (see the module's docstring for definitions);
    ``dof_dpi``: the depth-of-field chart (default: the design's own, 2/3 of its
    resolution); ``optics``: a stamp's engine (a rod-lens array has its own tracer)."""
    if isinstance(design, RodLensDesign):
        row = evaluate_rodlens(design, seed=seed, fresnel=fresnel, dof_dpi=dof_dpi)
    else:
        row = evaluate_stamp(design, seed=seed, fresnel=fresnel, dof_dpi=dof_dpi, optics=optics)
    return labelled(design, row, seed, fresnel)


def labelled(design: AnyDesign, row: dict, seed: int, fresnel: bool) -> dict:
    """A design's row with its name, kind, fingerprint, seed and Fresnel setting first."""
    return {
        "name": design.name,
        "kind": _kind(design),
        "fingerprint": design.fingerprint(),
        "seed": seed,
        "fresnel": fresnel,
    } | row


def compare(
    designs,
    *,
    seed: int = 0,
    fresnel: bool = False,
    dof_dpi: float | None = None,
    optics: str = "ray",
) -> list[dict]:
    """Evaluate each design, every depth of field on one chart (``dof_dpi``; default the
    first design's, 2/3 of its resolution), each stamp by ``optics`` ("auto": each by
    its own rule); add each one's light relative to the first."""
    designs = list(designs)
    dof_dpi = dof_chart_dpi(designs[0]) if dof_dpi is None else float(dof_dpi)
    rows = [
        evaluate(d, seed=seed, fresnel=fresnel, dof_dpi=dof_dpi, optics=optics) for d in designs
    ]
    return relative_to_first(rows)


def relative_to_first(rows: list[dict]) -> list[dict]:
    """Add ``light_vs_first``: each row's light over the first row's."""
    ref = rows[0]["light_vs_f10"]
    for r in rows:
        r["light_vs_first"] = r["light_vs_f10"] / ref if ref > 0 else math.inf
    return rows


def text_scans(
    designs,
    *,
    heights_mm=TEXT_HEIGHTS_MM,
    seed: int = 0,
    fresnel: bool = False,
    engines=None,
):
    """The same text (the built-in text chart's first half lines) scanned by each design at
    each height: [(title, image)] in design-major order, linear reflectance. Each scanner
    has its design's electronics and is exposed so that white fills WHITE_FILL of the full
    well (a rod-lens array collects about 100 times a stamp's light: at one exposure one
    of them would clip or starve). ``engines``: per design, "wave" to scan through the
    wave engine's kernels (the engine of its row; a colour scanner's under its grey
    light, its three LEDs lit together, as the report's), else the default kernels."""
    from ..analysis.responsivity import wave_unavailable
    from ..imaging.charts import text_chart
    from ..imaging.scan import ScanSettings, prepare_kernels, simulate_scan
    from ..imaging.sensor import exposure_for_white

    doc, _ = text_chart(TEXT_DPI)
    doc = doc[: doc.shape[0] // 2, : doc.shape[1] // 2]  # two half lines of 8-pt text
    panels = []
    for d, engine in zip(designs, engines or [None] * len(designs), strict=True):
        wave = engine == "wave" and wave_unavailable(d, maps=False, channels=True) is None
        base = ScanSettings(fresnel=fresnel, kernel="wave" if wave else "auto")
        kern = prepare_kernels(d, z_mm=heights_mm, settings=base, seed=seed)
        groups = kern.lookup(
            d, [heights_mm[0]], source=base.kernel, fresnel=fresnel, n_rays=base.kernel_rays,
            seed=seed,
        )  # fmt: skip
        white = float(np.mean([k[0].own_etendue + k[0].ghost_etendue for k in groups]))
        ms = exposure_for_white(d.electronics, white, WHITE_FILL)
        st = base.model_copy(
            update={"sensor": d.electronics.model_copy(update={"exposure_ms": ms})}
        )
        for z in heights_mm:
            r = simulate_scan(doc, TEXT_DPI, d, z_mm=z, settings=st, seed=seed, kernels=kern)
            panels.append((f"{d.name}, {z:g} mm", r.image))
    return panels
