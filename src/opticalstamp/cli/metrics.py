"""Commands of the image-quality metrics: rmtf, efficiency, diffraction, measure-rmtf, sfr."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..defaults import (
    DOF_THRESHOLD,
    RAYS_LSF,
    SHIFT_STEP_UM,
    WINDOW_UM,
    Z_GRID_MM,
)
from ..design import RodLensDesign
from .common import (
    BOTH_KINDS,
    DesignOpt,
    FresnelOpt,
    JsonOpt,
    PlotOpt,
    RaysOpt,
    SeedOpt,
    command,
    emit,
    fail,
    float_list,
    number,
    open_design,
    ray_count,
    resolution,
    save_plot,
    z_grid,
)
from .optics import OpticsOpt, optics_line


def _dpi_list(text: str) -> tuple[float, ...]:
    return float_list(text, "--dpi", 1.0, 5000.0)


@command()
def rmtf(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    dpi: Annotated[
        str | None,
        typer.Option(
            help="chart resolutions (dpi), comma-separated [default: the paper's 100, 150, "
            "200, 247 dpi scaled to the design's resolution, with the depth-of-field chart]",
            show_default=False,
        ),
    ] = None,
    z: Annotated[str, typer.Option(help="object distances (mm), or START:STOP:STEP")] = Z_GRID_MM,
    ghosts: Annotated[bool, typer.Option("--ghosts/--no-ghosts", help="count ghost light")] = True,
    method: Annotated[str, typer.Option(help="trace (exact) or paraxial (closed form)")] = "trace",
    window_um: Annotated[
        float,
        typer.Option(
            help="chart window for Imax/Imin (um), (0, 1e6]", callback=number(0, 1e6, lo_open=True)
        ),
    ] = WINDOW_UM,
    shift_um: Annotated[
        float,
        typer.Option(
            help="chart shift step (um), (0, 1000]", callback=number(0, 1000, lo_open=True)
        ),
    ] = SHIFT_STEP_UM,
    threshold: Annotated[
        float,
        typer.Option(
            help="RMTF threshold of the depth of field, (0, 1)",
            callback=number(0, 1, lo_open=True, hi_open=True),
        ),
    ] = DOF_THRESHOLD,
    dof_dpi: Annotated[
        float | None,
        typer.Option(
            help="chart dpi of the depth of field, 1 to 5000 [default: 2/3 of the design's "
            "resolution: 200 for 300 dpi, 400 for 600]",
            callback=number(1, 5000),
            show_default=False,
        ),
    ] = None,
    shading: Annotated[
        bool,
        typer.Option(
            "--shading/--raw-line",
            help="the merged line shading-corrected, each pixel over its own white response, "
            "as a scanner delivers it (default), or raw",
        ),
    ] = True,
    fresnel: FresnelOpt = False,
    optics: OpticsOpt = "auto",
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """RMTF of bar charts versus object distance and the depth of field (paper Fig. 11)."""
    from ..analysis.colour import rmtf_channel_lines
    from ..analysis.dof import dof_lines
    from ..analysis.rmtf import rmtf as run
    from ..design.resolution import nominal_dpi
    from ..io.files import provenance

    d = open_design(design)
    if method not in ("trace", "paraxial"):
        fail(f"--method: must be trace or paraxial (got {method!r})")
    if method == "paraxial" and any(m.shape == "circle" for m in d.masks):
        fail("--method paraxial: needs rectangular holes (this design has circular ones)")
    zs = z_grid(z)
    r = run(
        d,
        dpi=None if dpi is None else _dpi_list(dpi),
        z_mm=zs,
        method=method,
        ghosts=ghosts,
        fresnel=fresnel,
        n_rays=ray_count(rays, RAYS_LSF),
        seed=seed,
        window_um=window_um,
        shift_step_um=shift_um,
        dof_threshold=threshold,
        dof_dpi=dof_dpi,
        progress=not as_json,
        shading=shading,
        optics=optics,
    )
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    keys = list(r.rmtf_max)
    light = "with ghost light" if r.ghosts else "own path only"
    lines = [f"design {d.name}: RMTF (max over chart shifts), {r.method}, {light}"]
    lines.append(optics_line(r.meta["optics"]))
    lines.append("Z (mm) " + "".join(f"{k + ' dpi':>10}" for k in keys))
    for i, zz in enumerate(r.z_mm):
        lines.append(f"{zz:6.2f} " + "".join(f"{r.rmtf_max[k][i]:10.3f}" for k in keys))
    lines += dof_lines(r.to_dict(), nominal_dpi(d))
    if "headline" in r.meta:  # a colour scanner: the table is the worst channel's
        lines[0] += f"; the {r.meta['headline']['channel']} channel's curves (the headline)"
    lines += rmtf_channel_lines(r.to_dict())  # and every channel's depth of field
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_rmtf

        save_plot(plot_rmtf(r), plot)


@command()
def efficiency(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    study: Annotated[
        bool, typer.Option("--study", help="also run the study of the unstated parameters")
    ] = False,
    fresnel: FresnelOpt = False,
    optics: OpticsOpt = "auto",
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Light efficiency against the paper's reference lens (Fig. 13), working F-number
    (a rod-lens array: averaged along the array, with its ripple)."""
    from ..analysis.colour import light_channel_lines
    from ..analysis.efficiency import efficiency as run
    from ..analysis.efficiency import ratio_text
    from ..io.files import provenance

    d = open_design(design, kinds=BOTH_KINDS)
    if isinstance(d, RodLensDesign):
        if study:
            fail("--study: the study of the paper's unstated parameters is for stamps")
        _rod_efficiency(d, seed, fresnel, as_json, plot)
        return
    from ..design import load_design

    r = run(d, seed=seed, fresnel=fresnel, progress=not as_json, optics=optics)
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    o = r.meta["optics"]
    lines = [optics_line(o)]
    if o["engine"] == "wave":
        lines.append(
            f"all light {o['etendue_um2sr']:.4g} µm²·sr = wave in band "
            f"{o['wave_in_band_um2sr']:.4g} + traced beyond it {o['far_traced_um2sr']:.4g}; "
            f"ray optics gives {o['ray_etendue_um2sr']:.4g} "
            f"({o['etendue_um2sr'] / o['ray_etendue_um2sr'] - 1:+.1%} by wave optics); the "
            "own path below is the wave light in band, the sensitive-area figures are geometric"
        )
        lines += light_channel_lines(o)  # a colour scanner's channels
    lines += [
        f"design {d.name}: etendue of one pixel {r.etendue_um2sr:.4g} ± {r.etendue_se:.2g}"
        f" µm²·sr (own path {r.etendue_own_um2sr:.4g})",
        f"reference lens (F {r.reference_f_number:g}, "
        f"{r.meta['reference_lens']['pixel_um']:.1f} µm pixel): "
        f"{r.reference_etendue_um2sr:.4g} µm²·sr",
        f"light efficiency (own path: the signal) {ratio_text(r.ratio_own)}, working F-number "
        f"{r.working_f_number_own:.1f}; with the ghost light (crosstalk, not signal) "
        f"{ratio_text(r.ratio)}, F {r.working_f_number:.1f}",
    ]
    if r.etendue_um2sr == 0:
        lines.append("no light found reaching this pixel: efficiency 0, F-number infinite")
    if d.fingerprint() == load_design("paper2016").fingerprint():  # the paper's own design
        lines[-1] += "; the paper (its prototype, Fig. 13): 1/36, F 60"
    for a in r.sensitive_area:
        if r.etendue_um2sr == 0:  # no gain to state over no light
            lines.append(
                f"sensitive area {a['sensitive_um'][0]:.1f} µm ({a['area_scale']:g}× area): "
                f"{a['etendue_um2sr']:.4g} µm²·sr"
            )
            continue
        lines.append(
            f"sensitive area {a['sensitive_um'][0]:.1f} µm ({a['area_scale']:g}× area): "
            f"{a['gain_vs_design']:.2f}× the light ({a['gain_own_vs_design']:.2f}× own path)"
        )
    if study:
        from ..analysis.paper_study import parameter_study

        st = parameter_study(d, seed=seed, progress=not as_json)
        data["study"] = st.to_dict()
        lines.append("shape   area  gap   fresnel glass  1/ratio   F    DOF(mm) ghost  paper?")
        for row in st.rows:
            ok = "yes" if row["consistent_efficiency"] and row["consistent_dof"] else ""
            lines.append(
                f"{row['hole_shape']:7} {row['sensitive_um']:5.1f} {str(row['gap_medium']):5} "
                f"{'yes' if row['fresnel'] else 'no':7} {row['glass_index']:5.2f}  "
                f"{row['inverse_ratio']:6.1f} {row['working_f_number']:5.1f} {row['dof_mm']:6.2f}  "
                f"{row['ghost_fraction']:.3f}  {ok}"
            )
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_efficiency

        save_plot(plot_efficiency(r), plot)


def _rod_efficiency(d, seed: int, fresnel: bool, as_json: bool, plot) -> None:
    from ..analysis.rodlens import rod_efficiency
    from ..io.files import provenance

    r = rod_efficiency(d, seed=seed, fresnel=fresnel, progress=not as_json)
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    lines = [
        f"design {d.name} (rod-lens array): etendue of one pixel {r.etendue_um2sr:.4g} ± "
        f"{r.etendue_se:.2g} µm²·sr, averaged along the array",
        f"reference lens (F {r.reference_f_number:g}, "
        f"{r.meta['reference_lens']['pixel_um']:.1f} µm pixel): "
        f"{r.reference_etendue_um2sr:.4g} µm²·sr",
        f"ratio {r.ratio:.3f} ± {r.ratio_se:.3f}; working F-number {r.working_f_number:.2f}",
        f"ripple along one rod period {r.ripple:.3f} (noise alone ~{r.ripple_noise:.3f})",
    ]
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_rod_ripple

        save_plot(plot_rod_ripple(r), plot)


@command(traces=False)
def diffraction(
    design: DesignOpt = "paper2016",
    slit_um: Annotated[
        float | None,
        typer.Option(
            help="slit width (µm), (0, 10000] (default: the design's object-side hole)",
            callback=number(0, 1e4, lo_open=True),
        ),
    ] = None,
    wavelength_um: Annotated[str, typer.Option(help="wavelengths (µm), comma-separated")] = (
        "0.4,0.7"
    ),
    z: Annotated[
        float, typer.Option(help="point source distance Z (mm), 0 to 100", callback=number(0, 100))
    ] = 1.0,
    gap_um: Annotated[
        float | None,
        typer.Option(
            help="air-equivalent source gap above Z=0 (µm), 0 to 1e6 (default: the design's)",
            callback=number(0, 1e6),
        ),
    ] = None,
    next_um: Annotated[
        float | None,
        typer.Option(
            help="air-equivalent distance to the next layer (µm), (0, 1e6] (default: the design's)",
            callback=number(0, 1e6, lo_open=True),
        ),
    ] = None,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Fresnel diffraction of a slit (paper Fig. 6) and the design's per-layer budget."""
    from ..analysis.diffraction import diffraction_budget, slit_case

    gap_um_given = gap_um is not None
    d = open_design(design)
    waves = float_list(wavelength_um, "--wavelength-um", 0.2, 2.0)
    b = diffraction_budget(d, z_mm=z, wavelengths_um=waves)
    own = b["layers"][0]  # the design's layer 1, as design_slit_case takes it
    slit_um = own["hole_um"] if slit_um is None else slit_um
    if gap_um is None:
        gap_um = own["r1_um"] - z * 1000.0 / d.index(d.object_medium)
    next_um = own["r2_um"] if next_um is None else next_um
    if z == 0 and gap_um <= 0:
        whose = "" if gap_um_given else " (the design's reference_gap.thickness_um)"
        fail(
            f"--z 0 with --gap-um 0{whose} puts the point source in the slit (R1 = 0): it "
            "casts no geometric shadow, so there is no edge to diffract around; give --z > 0 "
            "or --gap-um > 0"
        )
    r = slit_case(slit_um=slit_um, z_mm=z, gap_um=gap_um, r2_um=next_um, wavelengths_um=waves)
    data = r.to_dict() | {"budget": b}
    lines = [
        f"slit {slit_um:g} µm, source Z = {z:g} mm (R1 {r.r1_um:.0f} µm), next layer "
        f"{r.r2_um:.0f} µm: geometric edge X = {r.geometric_edge_um:.2f} µm",
    ]
    for k, v in r.fraction_outside.items():
        lines.append(f"  {k} µm: {v:.1%} of the light outside the geometric edge")
    lines.append(f"design {d.name}, per-layer budget at Z = {z:g} mm:")
    for row in b["layers"]:
        outs = ", ".join(
            f"{k} µm: {row['outside_shadow'][k]:.1%} outside shadow, "
            f"{row['outside_next'][k]:.1%} outside {row['next']}"
            for k in row["outside_shadow"]
        )
        lines.append(
            f"  {row['layer']} ({row['hole_um']:g} µm {row['shape']}): {outs} "
            f"(geometric {row['outside_next_geometric']:.1%})"
        )
    for w in b["warnings"]:
        lines.append(f"warning: {w}")
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_diffraction

        save_plot(plot_diffraction(r), plot)


def read_scan_image(path: Path, dpi: float | None, linear: bool | None, min_px: int = 8):
    """An image checked from its header (``min_px`` pixels a side at least) and read,
    decoded to linear values as its file says (``linear`` None) or as the user says."""
    from ..io.files import ImageError, image_encoding, read_image

    try:
        if linear is None:
            enc = image_encoding(path)
            linear = enc == "srgb"
            if enc == "untagged":
                typer.echo(
                    f"warning: {path}: an 8-bit image without colour information, taken as "
                    "linear values; if it is sRGB-encoded (most 8-bit images are), pass "
                    "--linear to decode it",
                    err=True,
                )
        img, file_dpi = read_image(path, linear=linear, dpi=dpi, min_px=min_px)
    except ImageError as err:
        fail(str(err))
    return img, resolution(path, file_dpi, dpi, 10.0)


ImageArg = Annotated[Path, typer.Argument(help="image file (PNG, TIFF, JPEG)")]
DpiOpt = Annotated[
    float | None,
    typer.Option(
        help="image resolution, 10 to 20000 dpi (default: from the file)",
        callback=number(10, 20000),
    ),
]
LinearOpt = Annotated[
    bool | None,
    typer.Option(
        "--linear/--as-stored",
        help="decode sRGB values to linear first, or take them as stored (default: as the "
        "file states its encoding; 16-bit and TIFF as stored)",
        show_default=False,
    ),
]


@command("measure-rmtf", traces=False)
def measure_rmtf(
    image: ImageArg,
    dpi: DpiOpt = None,
    axis: Annotated[str, typer.Option(help="x: bars vary along x; y: along y")] = "x",
    linear: LinearOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Find the bar blocks of a chart image and measure RMTF per period (paper Fig. 12)."""
    from ..imaging.measure import measure_rmtf as run

    if axis not in ("x", "y"):
        fail(f"--axis: must be x or y (got {axis!r})")
    img, use = read_scan_image(image, dpi, linear)
    blocks = run(img, use, axis="xy".index(axis))
    if not blocks:
        fail(f"{image}: no bar blocks found (need >= 3 periods of equal bars along {axis})")
    data = {"image": str(image), "dpi": use, "blocks": blocks}
    lines = [
        f"{image} at {use:g} dpi (amplitude: the fitted fundamental over the ideal's; CNR: "
        "contrast to noise; overshoot past white or black):",
        "period (µm)   dpi    periods  Imax    Imin    RMTF  amplitude      CNR  overshoot",
    ]
    for b in blocks:
        lines.append(
            f"{b['period_um']:10.1f} {b['dpi']:6.1f} {b['n_periods']:8.1f} "
            f"{b['imax']:7.4f} {b['imin']:7.4f} {b['rmtf']:7.4f} {b['amplitude_rel']:9.3f} "
            f"{b['cnr']:8.1f} {b['overshoot']:10.3f}"
        )
    emit(data, as_json, lines)


def _mtf50(r: dict) -> str:
    """MTF50 as a line says it: the frequency, or that the SFR never fell to 0.5."""
    if r["mtf50_reached"]:
        return f"MTF50 {r['mtf50_cy_per_mm']:.3f} cycles/mm"
    return (
        "MTF50 not reached: the SFR stays above 0.5 up to the sampling frequency, "
        f"{r['freq_cy_per_mm'][-1]:.3g} cycles/mm (an edge sharper than the pixels resolve)"
    )


@command(traces=False)
def sfr(
    image: ImageArg,
    dpi: DpiOpt = None,
    direction: Annotated[
        str, typer.Option(help="x, y, auto (one edge) or both (a slanted dark square)")
    ] = "auto",
    roi: Annotated[str | None, typer.Option(help="region x0,y0,x1,y1 (pixels)")] = None,
    linear: LinearOpt = None,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Slanted-edge SFR (ISO 12233 e-SFR) of an image: curve, MTF50, 100/200-dpi values."""
    from ..imaging.measure import sfr as run

    img, use = read_scan_image(image, dpi, linear, min_px=16)
    if roi:
        box = float_list(roi, "--roi", 0, 1e6)
        if len(box) != 4:
            fail("--roi: expected x0,y0,x1,y1")
        x0, y0, x1, y1 = (int(v) for v in box)
        if not (x0 < x1 <= img.shape[1] and y0 < y1 <= img.shape[0]):
            fail(f"--roi: must lie inside the {img.shape[1]} x {img.shape[0]} image")
        img = img[y0:y1, x0:x1]
    if direction == "both":
        from ..imaging.measure import sfr_xy

        if roi:
            fail("--roi: not with --direction both (the square's edges are found)")
        try:
            both = sfr_xy(img, use)
        except ValueError as err:
            fail(f"{image}: {err}")
        data = {"image": str(image), "dpi": use} | both
        lines = [f"{image} at {use:g} dpi, slanted square:"]
        for axis, r in both.items():
            lines.append(
                f"  along {axis}: {_mtf50(r)}; SFR at 100 dpi "
                f"{r['sfr_at_dpi']['100']:.3f}, at 200 dpi {r['sfr_at_dpi']['200']:.3f}"
            )
        emit(data, as_json, lines)
        if plot:
            from ..report.plotting import plot_sfr

            save_plot(plot_sfr(both["x"], f"{image.name} (x)", extra=both["y"]), plot)
        return
    try:
        r = run(img, use, direction=direction)
    except ValueError as err:
        fail(f"{image}: {err}")
    if "roi" in r and roi:  # the square's edge found inside --roi: image coordinates
        r["roi"] = [v + (x0, y0)[i % 2] for i, v in enumerate(r["roi"])]
    data = {"image": str(image), "dpi": use} | r
    lines = [
        f"{image} at {use:g} dpi: edge along {r['direction']}, angle {r['edge_angle_deg']:.2f}°",
        f"{_mtf50(r)}; SFR at 100 dpi {r['sfr_at_dpi']['100']:.3f}"
        f", at 200 dpi {r['sfr_at_dpi']['200']:.3f}",
    ]
    if "roi" in r:
        lines.insert(1, "the left edge of the dark square, region {},{},{},{}".format(*r["roi"]))
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_sfr

        save_plot(plot_sfr(r, str(image.name)), plot)


@command()
def wave(
    design: DesignOpt = "paper2016",
    z: Annotated[str, typer.Option(help="object distances (mm), comma-separated")] = "0,1,2,3",
    rays: RaysOpt = None,
    seed: SeedOpt = 0,
    spectrum: Annotated[
        str | None,
        typer.Option(
            help="the light: mono (the design's wavelength), white, red, green, blue or rgb "
            "(one comparison per LED); default the design's electronics.illumination"
        ),
    ] = None,
    fresnel: FresnelOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Ray against wave optics (issue 23): light, spot and RMTF of the own path and near
    crosstalk by the wave engine and by the tracer in the same band, and the layers'
    Fresnel numbers; under a spectrum, both weighted over its wavelengths; with
    --fresnel, both engines with Fresnel transmission losses. Holes that are not
    rectangles (circles) take the wave engine's 2-D path: minutes a height on a CPU
    (a progress bar and the expected cost on stderr), seconds on a CUDA GPU."""
    from ..analysis.spectrum import CHANNELS, channels
    from ..analysis.wavecompare import compare_wave_ray, comparison_lines

    d = open_design(design)
    if spectrum is not None and spectrum not in CHANNELS:
        fail(f"--spectrum: must be one of {', '.join(CHANNELS)} (got {spectrum!r})")
    lights = channels(d, spectrum)
    if plot and len(lights) > 1:
        fail(f"--plot: draws one light; {', '.join(lights)} are {len(lights)}: pass one of them")
    zs = float_list(z, "--z", 0.0, 100.0)
    n = ray_count(rays, RAYS_LSF)
    cs = {
        k: compare_wave_ray(
            d, zs, n_rays=n, seed=seed, spectrum=v, fresnel=fresnel, progress=not as_json
        )
        for k, v in lights.items()
    }
    if len(cs) == 1:
        c = next(iter(cs.values()))
        emit(c.to_dict(), as_json, comparison_lines(c))
    else:
        lines = [f"{k}: " + "\n".join(comparison_lines(c)) for k, c in cs.items()]
        emit({k: c.to_dict() for k, c in cs.items()}, as_json, lines)
    if plot:
        from ..report.plotting.wave import plot_wave_ray

        save_plot(plot_wave_ray(next(iter(cs.values()))), plot)
