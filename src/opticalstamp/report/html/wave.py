"""The page's "Ray vs wave optics" section (issue 23)."""

from __future__ import annotations

import html

from .common import table, unmeasured

TITLE = "Ray vs wave optics"


def _dof(v: dict, engine: str) -> str:
    return f"{'≥ ' if v['dof_open_ended'][engine] else ''}{v['dof_mm'][engine]:.2f} mm"


def wave_html(w: dict | None, fresnel_losses: bool = False) -> str:
    """Fresnel numbers, light, spot and RMTF by both engines, and the verdict on which
    holds, from report.json's "ray_vs_wave" (None: the section was not run)."""
    if w is None:
        return ""
    missing = unmeasured(TITLE, w)
    if missing is not None:
        return missing
    v, s, r, wv, d = w["verdict"], w["sampling"], w["ray"], w["wave"], w["difference"]
    tol = v["tolerances"]
    fres = [
        [f"{f['layer']} → {f['towards']}", f["hole_um"], f["distance_um"], f["fresnel_number"]]
        for f in w["fresnel"]
    ]
    own = w["own_exact_um2sr"]
    light = [
        ["wave engine", wv["light_um2sr"], "-"],
        ["tracer, rays in the band (own + near ghosts)", r["light_um2sr"],
         f"own {r['own_in_band_um2sr']:.4g} + near {r['near_um2sr']:.4g}"],
        ["own path, exact etendue (rays)", own, "for reference"],
        ["wave light diffracted beyond the band by the object-side mask",
         wv["lost_to_band_top_um2sr"], "not in the wave figure"],
    ]  # fmt: skip
    if own is None:
        light.pop(2)
    rows = [
        [
            z,
            wv["fwhm_x_um"][i],
            r["fwhm_x_um"][i],
            wv["center_cell_fraction"][i],
            r["center_cell_fraction"][i],
            wv["rmtf"][i],
            r["rmtf"][i],
            f"{d['rmtf'][i]:+.3f}",
        ]
        for i, z in enumerate(w["z_mm"])
    ]
    head = [
        "Z (mm)",
        "FWHM x wave (µm)",
        "FWHM x ray (µm)",
        "central cell wave",
        "central cell ray",
        f"RMTF {w['dof_dpi']:g} dpi wave",
        "RMTF ray",
        "wave − ray",
    ]
    dl = "n/a" if v["light_difference"] is None else f"{v['light_difference'] * 100:+.1f} %"
    notes = []
    if fresnel_losses:
        notes.append(
            "Fresnel transmission losses, on in the other sections, are off on both sides "
            "here (the comparison isolates diffraction)"
        )
    note = "".join(f" Note: {html.escape(n)}." for n in notes)
    light_words = f"at λ = {s['wavelength_um']:g} µm in the band"
    spec = w["meta"].get("spectrum") or {}
    lams = spec.get("wavelengths_um") or []
    if len(lams) > 1:
        light_words = (
            f"under the {html.escape(str(spec.get('name', '')))} light ("
            f"{len(lams)} wavelengths, {min(lams):.3f}-{max(lams):.3f} µm; both engines' figures "
            f"are the weighted sums, each wavelength in its own band; the Fresnel numbers at "
            f"the mean wavelength) in the band, at the heaviest wavelength,"
        )
    return f"""<h2>{TITLE}</h2>
<p>The tracer is geometric optics; where holes are small against the gaps below them
(Fresnel numbers a²/(λd) near or below 1) diffraction changes the light and the spot. The
wave engine (scalar, band-limited angular spectrum through every slab and mask, the pixel
as an incoherent source; docs/wave.md) computes the pixel's responsivity
{light_words} |s<sub>x</sub>|, |s<sub>y</sub>| &lt; {s["band"]:.3f}; the ray figures beside
it are the tracer's rays in the same band
({r["n_rays"]:,} rays per pixel row). Both are the own path and the near crosstalk: the far
ghost light, which the RMTF section includes, is left out on both sides.{note}</p>
<p><b>{html.escape(v["text"])}</b></p>
<p>Ray optics is judged to hold where the wave figures agree with the ray figures within
{tol["light"] * 100:g} % in light (wave/ray − 1) and within {tol["rmtf"]:g} (absolute) in RMTF on
the {w["dof_dpi"]:g}-dpi chart at every height compared; here light wave/ray {dl}, RMTF
wave − ray largest {_signed(v["rmtf_difference_max"])} at Z = {_z(v)}. Depth of field
(first Z where that RMTF falls below {v["dof_threshold"]:g}, interpolated between the
heights below): wave {_dof(v, "wave")}, ray {_dof(v, "ray")}.</p>
{prediction_html(w.get("prediction"), v["holds"])}
<h3>Fresnel numbers</h3>
<p>Each mask's holes over the gap below it (reduced distance Σ t/n) and the object-side
mask over the reference gap; a is half the hole's smaller side. Smallest:
{v["fresnel_min"]:.2f}.</p>
{table(fres, ["layer → towards", "hole (µm)", "reduced distance (µm)", "Fresnel number"])}
<h3>Light in the band (µm²·sr, one pixel of row A)</h3>
{table(light, ["engine", "light", "note"])}
<h3>Spot and RMTF against height</h3>
<p>FWHM of row A's x line-spread function, share of its light in the central output
cell, and the RMTF on the {w["dof_dpi"]:g}-dpi chart (period {w["period_um"]:.1f} µm) of
rows A and B merged (shading-corrected, maximum over chart shifts).</p>
{table(rows, head)}
<img src="raywave.png" alt="RMTF against height and line-spread functions by both engines">
"""


def _signed(x) -> str:
    return "n/a" if x is None else f"{x:+.3f}"


def _z(v: dict) -> str:
    z = v["rmtf_difference_at_z_mm"]
    return "-" if z is None else f"{z:g} mm"


def prediction_html(pred: dict | None, holds: str) -> str:
    """The validity rule's prediction (from the geometry alone) beside the measured
    verdict."""
    if not pred:
        return ""
    same = "agrees with" if pred["engine"] == holds else "differs from"
    return (
        f"<p>The validity rule (docs/wave-validity.md), from the geometry alone without a "
        f"wave run, predicts <b>{html.escape(pred['engine'])} optics</b>: "
        f"{html.escape(pred['reason'])}. It {same} the measurement above (its RMTF bound "
        "covers Z = 0-3 mm).</p>"
    )
