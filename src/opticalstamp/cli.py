"""Command line: `opticalstamp ghosts | spots | psf | rmtf | efficiency | diffraction |
measure-rmtf | sfr | report`."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from .design import Design, DesignError, load_design

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Design and analyse lensless contact image scanners (optical stamps).",
)

DesignOpt = Annotated[str, typer.Option("--design", "-d", help="preset name or design TOML file")]
SeedOpt = Annotated[int, typer.Option("--seed", help="random seed (results are reproducible)")]
RaysOpt = Annotated[int | None, typer.Option("--rays", help="number of rays (default: automatic)")]
JsonOpt = Annotated[bool, typer.Option("--json", help="print machine-readable JSON on stdout")]
PlotOpt = Annotated[Path | None, typer.Option("--plot", help="write a PNG figure")]
FresnelOpt = Annotated[bool, typer.Option("--fresnel", help="apply Fresnel transmission losses")]


def _fail(msg: str) -> None:
    typer.echo(f"error: {msg}", err=True)
    raise typer.Exit(2)


def _design(spec: str) -> Design:
    try:
        return load_design(spec)
    except DesignError as err:
        _fail(str(err))


def _floats(text: str, name: str, lo: float = 0.0, hi: float = 1000.0) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        _fail(f"{name}: expected comma-separated numbers (got {text!r})")
    if not vals or any(not lo <= v <= hi for v in vals):
        _fail(f"{name}: values must lie in [{lo:g}, {hi:g}] (got {text!r})")
    return vals


def _rays(n: int | None, default: int) -> int:
    if n is None:
        return default
    if not 1_000 <= n <= 10**10:
        _fail(f"--rays: must be between 1000 and 1e10 (got {n})")
    return n


def _emit(data: dict, as_json: bool, lines: list[str]) -> None:
    from .io import to_json

    if as_json:
        sys.stdout.write(to_json(data) + "\n")
    else:
        typer.echo("\n".join(lines))


def _plot(fig, path: Path | None) -> None:
    if path is not None:
        from .io import save_figure

        save_figure(fig, path)
        typer.echo(f"wrote {path}", err=True)


@app.command()
def ghosts(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    z: Annotated[str, typer.Option(help="object distances (mm), comma-separated")] = "0",
    rse_own: Annotated[float, typer.Option(help="target relative SE, own path")] = 1e-3,
    rse_ghost: Annotated[float, typer.Option(help="target relative SE, ghosts")] = 1e-2,
    row: Annotated[str, typer.Option(help="pixel row, A or B")] = "A",
    detector_um: Annotated[
        float, typer.Option(help="half width of the virtual detector on the object plane (um)")
    ] = 500.0,
    fresnel: FresnelOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Ghost (crosstalk) paths of one pixel: etendue, ghost fraction, where ghosts land."""
    from .ghosts import analyse_ghosts
    from .io import provenance

    d = _design(design)
    if row not in ("A", "B") or (row == "B" and d.sensor.rows == 1):
        _fail("--row: must be A, or B for a two-row design")
    if not 0 < rse_own < 1 or not 0 < rse_ghost < 1:
        _fail("--rse-own/--rse-ghost: must lie in (0, 1)")
    zs = _floats(z, "--z", 0.0, 100.0)
    r = analyse_ghosts(
        d,
        pixel=("AB".index(row), 0),
        z_mm=zs,
        n_rays=None if rays is None else _rays(rays, 0),
        rse_own=rse_own,
        rse_ghost=rse_ghost,
        seed=seed,
        fresnel=fresnel,
        detector_half_um=detector_um,
        progress=not as_json,
    )
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    lines = [
        f"design {d.name}: pixel {row}0, {r.n_rays:,} rays",
        f"own-path etendue   {r.etendue_own_um2sr:.5g} +- {r.etendue_own_se:.2g} um^2 sr",
        f"ghost etendue      {r.etendue_ghost_um2sr:.5g} +- {r.etendue_ghost_se:.2g} um^2 sr",
        f"ghost fraction     {r.ghost_fraction:.4g} +- {r.ghost_fraction_se:.2g}",
    ]
    for zk, v in r.landing.items():
        lines.append(
            f"Z = {zk} mm: nearest ghost light {v['nearest_um']} um from the axis, "
            f"{v['within_detector_um2sr']:.3g} um^2 sr inside +-{detector_um:g} um"
        )
    for p in r.paths[:10]:
        hs = ", ".join(f"{h['mask']} {h['row']} {h['dk']:+d}" for h in p.holes)
        lines.append(
            f"  {p.etendue_um2sr:9.4g} um^2 sr  {p.share:6.1%}  [{hs}]  "
            f"{p.emission_angle_deg[0]:.1f}-{p.emission_angle_deg[1]:.1f} deg"
        )
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_ghosts

        _plot(plot_ghosts(r), plot)


@app.command()
def spots(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    z: Annotated[str, typer.Option(help="object distances (mm)")] = "0,1,2,3,4",
    no_ghosts: Annotated[bool, typer.Option("--no-ghosts")] = False,
    fresnel: FresnelOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Responsivity map (spot) of one pixel on the object plane at each Z (paper Fig. 5)."""
    from .io import provenance
    from .response import spots as run

    d = _design(design)
    r = run(
        d,
        z_mm=_floats(z, "--z", 0.0, 100.0),
        n_rays=_rays(rays, 1 << 22),
        seed=seed,
        fresnel=fresnel,
        ghosts=not no_ghosts,
        progress=not as_json,
    )
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    lines = [
        f"design {d.name}: spots of pixel A0 ({r.n_rays:,} rays)",
        "Z (mm)  extent x/y (um)   FWHM x/y (um)   centre-cell fraction",
    ]
    for s in r.spots:
        lines.append(
            f"{s.z_mm:6g}  {s.extent_x_um:7.1f} {s.extent_y_um:7.1f}  "
            f"{s.fwhm_x_um:7.1f} {s.fwhm_y_um:7.1f}   {s.center_cell_fraction:.3f}"
        )
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_spots

        _plot(plot_spots(r), plot)


@app.command()
def psf(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    z: Annotated[float, typer.Option(help="object distance Z (mm)")] = 1.0,
    x_obj: Annotated[float, typer.Option(help="object point x (um)")] = 0.0,
    y_obj: Annotated[float, typer.Option(help="object point y (um)")] = 0.0,
    fresnel: FresnelOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Where light from a Lambertian object point lands on the sensor (paper Fig. 10)."""
    from .io import provenance
    from .response import psf as run

    d = _design(design)
    if not 0 <= z <= 100:
        _fail(f"--z: must lie in [0, 100] mm (got {z})")
    r = run(
        d,
        x_obj_um=x_obj,
        y_obj_um=y_obj,
        z_mm=z,
        n_rays=_rays(rays, 1 << 22),
        seed=seed,
        fresnel=fresnel,
        progress=not as_json,
    )
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    lines = [
        f"design {d.name}: point ({x_obj:g}, {y_obj:g}) um at Z = {z:g} mm",
        f"own pixel {r.own_pixel_id['row']}{r.own_pixel_id['k']}: {r.own_pixel:.4f}",
        f"neighbours, own-path blur: {r.neighbour_own_path:.4f}",
        f"ghosts: {r.neighbour_ghost:.4f}",
        f"insensitive area: {r.insensitive:.4f}",
        f"(fractions of the {r.reaching_sensor:.3g} of emitted power reaching the sensor)",
    ]
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_psf

        _plot(plot_psf(r), plot)


def _dpi_list(text: str) -> tuple[float, ...]:
    return _floats(text, "--dpi", 1.0, 5000.0)


@app.command()
def rmtf(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    dpi: Annotated[str, typer.Option(help="chart resolutions (dpi), comma-separated")] = (
        "100,150,200,247"
    ),
    z: Annotated[str, typer.Option(help="object distances (mm), or START:STOP:STEP")] = (
        "0:4.5:0.25"
    ),
    ghosts: Annotated[bool, typer.Option("--ghosts/--no-ghosts", help="count ghost light")] = True,
    method: Annotated[str, typer.Option(help="trace (exact) or paraxial (closed form)")] = "trace",
    window_um: Annotated[float, typer.Option(help="chart window for Imax/Imin (um)")] = 5000.0,
    shift_um: Annotated[float, typer.Option(help="chart shift step (um)")] = 1.0,
    threshold: Annotated[float, typer.Option(help="RMTF threshold of the depth of field")] = 0.3,
    dof_dpi: Annotated[float, typer.Option(help="chart dpi of the depth of field")] = 200.0,
    fresnel: FresnelOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """RMTF of bar charts versus object distance and the depth of field (paper Fig. 11)."""
    from .io import provenance
    from .metrics import rmtf as run

    d = _design(design)
    if method not in ("trace", "paraxial"):
        _fail(f"--method: must be trace or paraxial (got {method!r})")
    if method == "paraxial" and any(m.shape == "circle" for m in d.masks):
        _fail("--method paraxial: needs rectangular holes (this design has circular ones)")
    if not 0 < threshold < 1:
        _fail(f"--threshold: must lie in (0, 1) (got {threshold})")
    if not 0 < window_um <= 1e6 or not 0 < shift_um <= 1000:
        _fail("--window-um must lie in (0, 1e6] and --shift-um in (0, 1000]")
    zs = _z_grid(z)
    r = run(
        d,
        dpi=_dpi_list(dpi),
        z_mm=zs,
        method=method,
        ghosts=ghosts,
        fresnel=fresnel,
        n_rays=_rays(rays, 1 << 21),
        seed=seed,
        window_um=window_um,
        shift_step_um=shift_um,
        dof_threshold=threshold,
        dof_dpi=dof_dpi,
        progress=not as_json,
    )
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    keys = list(r.rmtf_max)
    lines = [f"design {d.name}: RMTF (max over chart shifts), {r.method}, ghosts {r.ghosts}"]
    lines.append("Z (mm) " + "".join(f"{k + ' dpi':>10}" for k in keys))
    for i, zz in enumerate(r.z_mm):
        lines.append(f"{zz:6.2f} " + "".join(f"{r.rmtf_max[k][i]:10.3f}" for k in keys))
    lines.append(
        "depth of field (RMTF >= "
        + f"{threshold:g}): "
        + ", ".join(f"{k} dpi {v:.2f} mm" for k, v in r.dof_mm.items())
    )
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_rmtf

        _plot(plot_rmtf(r), plot)


def _z_grid(text: str) -> tuple[float, ...]:
    if ":" in text:
        parts = text.split(":")
        try:
            a, b, c = (float(v) for v in parts)
        except ValueError:
            _fail(f"--z: expected START:STOP:STEP (got {text!r})")
        if not (0 <= a <= b <= 100 and c > 0) or (b - a) / c > 1000:
            _fail(f"--z: need 0 <= START <= STOP <= 100 and 0 < STEP, <= 1000 steps (got {text!r})")
        return tuple(float(v) for v in np.round(np.arange(a, b + c / 2, c), 6))
    return _floats(text, "--z", 0.0, 100.0)


@app.command()
def efficiency(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    study: Annotated[
        bool, typer.Option("--study", help="also run the study of the unstated parameters")
    ] = False,
    fresnel: FresnelOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Light efficiency against the paper's reference lens (Fig. 13), working F-number."""
    from .efficiency import efficiency as run
    from .io import provenance

    d = _design(design)
    r = run(d, seed=seed, fresnel=fresnel, progress=not as_json)
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    lines = [
        f"design {d.name}: etendue of one pixel {r.etendue_um2sr:.4g} +- {r.etendue_se:.2g}"
        f" um^2 sr (own path {r.etendue_own_um2sr:.4g})",
        f"reference lens (F {r.reference_f_number:g}, 84.6 um pixel): "
        f"{r.reference_etendue_um2sr:.4g} um^2 sr",
        f"ratio 1/{1 / r.ratio:.1f} (own path only 1/{1 / r.ratio_own:.1f}); working F-number "
        f"{r.working_f_number:.1f} ({r.working_f_number_own:.1f}); paper: 1/36, F 60",
    ]
    for a in r.sensitive_area:
        lines.append(
            f"sensitive area {a['sensitive_um'][0]:.1f} um ({a['area_scale']:g}x area): "
            f"{a['gain_vs_design']:.2f}x the light ({a['gain_own_vs_design']:.2f}x own path)"
        )
    if study:
        from .study import parameter_study

        st = parameter_study(d, seed=seed, progress=not as_json)
        data["study"] = st.to_dict()
        lines.append("shape   area  gap   fresnel glass  1/ratio   F    DOF(mm) ghost  paper?")
        for row in st.rows:
            ok = "yes" if row["consistent_efficiency"] and row["consistent_dof"] else ""
            lines.append(
                f"{row['hole_shape']:7} {row['sensitive_um']:5.1f} {str(row['gap_medium']):5} "
                f"{str(row['fresnel']):7} {row['glass_index']:5.2f}  {row['inverse_ratio']:6.1f}"
                f" {row['working_f_number']:5.1f} {row['dof_mm']:6.2f}  "
                f"{row['ghost_fraction']:.3f}  {ok}"
            )
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_efficiency

        _plot(plot_efficiency(r), plot)


@app.command()
def diffraction(
    design: DesignOpt = "paper2016",
    slit_um: Annotated[float, typer.Option(help="slit width (um)")] = 48.0,
    wavelength_um: Annotated[str, typer.Option(help="wavelengths (um), comma-separated")] = (
        "0.4,0.7"
    ),
    z: Annotated[float, typer.Option(help="point source distance Z (mm)")] = 1.0,
    gap_um: Annotated[float, typer.Option(help="air-equivalent source gap above Z=0 (um)")] = (
        1000.0
    ),
    next_um: Annotated[
        float, typer.Option(help="air-equivalent distance to the next layer (um)")
    ] = 1000.0 / 1.52,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Fresnel diffraction of a slit (paper Fig. 6) and the design's per-layer budget."""
    from .diffraction import diffraction_budget, slit_case

    d = _design(design)
    waves = _floats(wavelength_um, "--wavelength-um", 0.2, 2.0)
    if not 0 < slit_um <= 10000 or not 0 <= z <= 100 or gap_um < 0 or next_um <= 0:
        _fail("--slit-um must be > 0, --z in [0, 100] mm, --gap-um >= 0, --next-um > 0")
    r = slit_case(slit_um=slit_um, z_mm=z, gap_um=gap_um, r2_um=next_um, wavelengths_um=waves)
    b = diffraction_budget(d, z_mm=z, wavelengths_um=waves)
    data = r.to_dict() | {"budget": b}
    lines = [
        f"slit {slit_um:g} um, source Z = {z:g} mm (R1 {r.r1_um:.0f} um), next layer "
        f"{r.r2_um:.0f} um: geometric edge X = {r.geometric_edge_um:.2f} um",
    ]
    for k, v in r.fraction_outside.items():
        lines.append(f"  {k} um: {v:.1%} of the light outside the geometric edge")
    lines.append(f"design {d.name}, per-layer budget at Z = {z:g} mm:")
    for row in b["layers"]:
        outs = ", ".join(
            f"{k} um: {row['outside_shadow'][k]:.1%} outside shadow, "
            f"{row['outside_next'][k]:.1%} outside {row['next']}"
            for k in row["outside_shadow"]
        )
        lines.append(
            f"  {row['layer']} ({row['hole_um']:g} um {row['shape']}): {outs} "
            f"(geometric {row['outside_next_geometric']:.1%})"
        )
    for w in b["warnings"]:
        lines.append(f"warning: {w}")
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_diffraction

        _plot(plot_diffraction(r), plot)


def _image(path: Path, dpi: float | None, linear: bool):
    from .io import ImageError, read_image

    try:
        img, file_dpi = read_image(path, linear=linear)
    except ImageError as err:
        _fail(str(err))
    use = dpi or file_dpi
    if use is None:
        _fail(f"{path}: the file carries no resolution; give --dpi")
    if not 10 <= use <= 20000:
        _fail(f"--dpi: must lie in [10, 20000] (got {use:g})")
    return img, use


ImageArg = Annotated[Path, typer.Argument(help="image file (PNG, TIFF, JPEG)")]
DpiOpt = Annotated[float | None, typer.Option(help="image resolution (default: from the file)")]
LinearOpt = Annotated[bool, typer.Option("--linear", help="decode sRGB values to linear first")]


@app.command("measure-rmtf")
def measure_rmtf(
    image: ImageArg,
    dpi: DpiOpt = None,
    axis: Annotated[str, typer.Option(help="x: bars vary along x; y: along y")] = "x",
    linear: LinearOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Find the bar blocks of a chart image and measure RMTF per period (paper Fig. 12)."""
    from .measure import measure_rmtf as run

    if axis not in ("x", "y"):
        _fail(f"--axis: must be x or y (got {axis!r})")
    img, use = _image(image, dpi, linear)
    blocks = run(img, use, axis="xy".index(axis))
    if not blocks:
        _fail(f"{image}: no bar blocks found (need >= 3 periods of equal bars along {axis})")
    data = {"image": str(image), "dpi": use, "blocks": blocks}
    lines = [f"{image} at {use:g} dpi:", "period (um)   dpi    periods  Imax    Imin    RMTF"]
    for b in blocks:
        lines.append(
            f"{b['period_um']:10.1f} {b['dpi']:6.1f} {b['n_periods']:8.1f} "
            f"{b['imax']:7.4f} {b['imin']:7.4f} {b['rmtf']:7.4f}"
        )
    _emit(data, as_json, lines)


@app.command()
def sfr(
    image: ImageArg,
    dpi: DpiOpt = None,
    direction: Annotated[
        str, typer.Option(help="x, y, auto (one edge) or both (a slanted dark square)")
    ] = "auto",
    roi: Annotated[str | None, typer.Option(help="region x0,y0,x1,y1 (pixels)")] = None,
    linear: LinearOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Slanted-edge SFR (ISO 12233 e-SFR) of an image: curve, MTF50, 100/200-dpi values."""
    from .measure import sfr as run

    img, use = _image(image, dpi, linear)
    if roi:
        box = _floats(roi, "--roi", 0, 1e6)
        if len(box) != 4:
            _fail("--roi: expected x0,y0,x1,y1")
        x0, y0, x1, y1 = (int(v) for v in box)
        if not (x0 < x1 <= img.shape[1] and y0 < y1 <= img.shape[0]):
            _fail(f"--roi: must lie inside the {img.shape[1]} x {img.shape[0]} image")
        img = img[y0:y1, x0:x1]
    if direction == "both":
        from .measure import sfr_xy

        if roi:
            _fail("--roi: not with --direction both (the square's edges are found)")
        try:
            both = sfr_xy(img, use)
        except ValueError as err:
            _fail(f"{image}: {err}")
        data = {"image": str(image), "dpi": use} | both
        lines = [f"{image} at {use:g} dpi, slanted square:"]
        for axis, r in both.items():
            lines.append(
                f"  along {axis}: MTF50 {r['mtf50_cy_per_mm']:.3f} cycles/mm; SFR at 100 dpi "
                f"{r['sfr_at_dpi']['100']:.3f}, at 200 dpi {r['sfr_at_dpi']['200']:.3f}"
            )
        _emit(data, as_json, lines)
        if plot:
            from .plotting import plot_sfr

            _plot(plot_sfr(both["x"], f"{image.name} (x)", extra=both["y"]), plot)
        return
    try:
        r = run(img, use, direction=direction)
    except ValueError as err:
        _fail(f"{image}: {err}")
    data = {"image": str(image), "dpi": use} | r
    lines = [
        f"{image} at {use:g} dpi: edge along {r['direction']}, angle {r['edge_angle_deg']:.2f} deg",
        f"MTF50 {r['mtf50_cy_per_mm']:.3f} cycles/mm; SFR at 100 dpi {r['sfr_at_dpi']['100']:.3f}"
        f", at 200 dpi {r['sfr_at_dpi']['200']:.3f}",
    ]
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_sfr

        _plot(plot_sfr(r, str(image.name)), plot)


def _document(path: Path, dpi: float | None, color: bool):
    from .io import ImageError, read_document

    try:
        doc, file_dpi = read_document(path, color=color)
    except ImageError as err:
        _fail(str(err))
    use = dpi or file_dpi
    if use is None:
        _fail(f"{path}: the file carries no resolution; give --dpi")
    if not 50 <= use <= 20000:
        _fail(f"--dpi: must lie in [50, 20000] (got {use:g})")
    if use < 600:
        typer.echo(
            f"warning: {path} is sampled at {use:g} dpi; at least 600 dpi is recommended "
            "(the document's own pixels blur the simulated 300-dpi scan)",
            err=True,
        )
    return doc, use


def _height(spec: str | None, z: float | None, doc_shape, dpi: float, seed: int):
    from .heightmap import HeightMapError, load_height_map

    if (spec is None) == (z is None):
        _fail("give exactly one of --z MM and --height-map FILE|SHAPE")
    if spec is None:
        if not 0 <= z <= 10:
            _fail(f"--z: must lie in [0, 10] mm (got {z:g})")
        return None
    h_mm, w_mm = doc_shape[0] * 25.4 / dpi, doc_shape[1] * 25.4 / dpi
    try:
        return load_height_map(spec, h_mm, w_mm, seed)
    except HeightMapError as err:
        _fail(str(err))


def _illumination_profile(path: Path) -> tuple:
    try:
        arr = np.loadtxt(path, delimiter=",", ndmin=2, comments="#")
    except (OSError, ValueError) as err:
        _fail(f"--illumination: cannot read {path} as CSV of x_mm,relative ({err})")
    if arr.shape[1] != 2 or arr.shape[0] < 2 or np.any(np.diff(arr[:, 0]) <= 0):
        _fail(f"--illumination: {path} needs two columns x_mm,relative with increasing x")
    if np.any(arr[:, 1] < 0) or not np.all(np.isfinite(arr)):
        _fail(f"--illumination: {path} has negative or non-finite values")
    return tuple((float(a), float(b)) for a, b in arr)


def _settings(
    illumination: str,
    kernel: str,
    speed_error: float,
    surround: float,
    illuminance: float,
    exposure: float,
):
    from pydantic import ValidationError

    from .scan import ScanSettings
    from .sensor import SensorModel

    profile = None
    if illumination not in ("uniform", "ripple"):
        profile = _illumination_profile(Path(illumination))
        illumination = "uniform"
    try:
        sensor = SensorModel(illuminance_lux=illuminance, exposure_ms=exposure)
        return ScanSettings(
            sensor=sensor,
            illumination=illumination,
            illumination_profile=profile,
            kernel=kernel,
            speed_error=speed_error,
            surround=surround,
        )
    except ValidationError as err:
        e = err.errors()[0]
        name = {"illuminance_lux": "illuminance-lux", "exposure_ms": "exposure-ms"}.get(
            str(e["loc"][-1]), str(e["loc"][0]).replace("_", "-")
        )
        _fail(f"--{name}: {e['msg']} (got {e.get('input')!r})")


@app.command()
def scan(
    image: ImageArg,
    output: Annotated[Path, typer.Option("-o", "--output", help="output .png or .tif")],
    z: Annotated[float | None, typer.Option(help="float height (mm)")] = None,
    height_map: Annotated[
        str | None, typer.Option(help="height map: .npy/.tif in mm, or tilt/gutter/crumple")
    ] = None,
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    dpi: DpiOpt = None,
    noiseless: Annotated[bool, typer.Option("--noiseless", help="no noise (analysis)")] = False,
    no_ghosts: Annotated[bool, typer.Option("--no-ghosts", help="leave ghost light out")] = False,
    color: Annotated[bool, typer.Option("--color", help="sequential R, G, B LEDs")] = False,
    illumination: Annotated[
        str, typer.Option(help="uniform, ripple, or a CSV file of x_mm,relative")
    ] = "uniform",
    illuminance_lux: Annotated[float, typer.Option(help="illuminance on the page (lux)")] = (
        10_000.0
    ),
    exposure_ms: Annotated[float, typer.Option(help="exposure per line (ms)")] = 1.0,
    kernel: Annotated[str, typer.Option(help="auto, paraxial or trace")] = "auto",
    speed_error: Annotated[float, typer.Option(help="relative scan-speed error")] = 0.0,
    surround: Annotated[float, typer.Option(help="reflectance outside the page")] = 0.0,
) -> None:
    """Simulate the scanner's output for a document at a float height (paper Figs. 8, 9)."""
    import json

    from .io import provenance, to_json, write_atomic, write_png, write_tiff16
    from .scan import simulate_scan

    suffix = output.suffix.lower()
    if suffix not in (".png", ".tif", ".tiff"):
        _fail(f"-o: the output must end in .png, .tif or .tiff (got {output.name!r})")
    d = _design(design)
    st = _settings(illumination, kernel, speed_error, surround, illuminance_lux, exposure_ms)
    doc, use = _document(image, dpi, color)
    hm = _height(height_map, z, doc.shape, use, seed)
    try:
        r = simulate_scan(
            doc,
            use,
            d,
            z_mm=z,
            height_map=hm,
            settings=st,
            seed=seed,
            ghosts=not no_ghosts,
            noiseless=noiseless,
            color=color,
            progress=True,
        )
    except ValueError as err:
        _fail(str(err))
    meta = provenance(d, seed) | {k: v for k, v in r.meta.items() if k != "settings"}
    meta |= {
        "input": str(image),
        "output_dpi": r.dpi,
        "settings": r.meta["settings"],
        "height_map_spec": height_map,
    }
    png = output.with_suffix(".png")
    tif = output.with_suffix(".tif") if suffix == ".png" else output
    write_png(png, r.image, r.dpi)
    write_tiff16(tif, r.image, r.dpi, description=json.dumps(meta))
    write_atomic(output.with_suffix(".json"), to_json(meta))
    typer.echo(
        f"wrote {png} (8-bit sRGB), {tif} (16-bit linear) and {output.with_suffix('.json')}: "
        f"{r.image.shape[1]} x {r.image.shape[0]} pixels at {r.dpi:.1f} dpi",
        err=True,
    )


@app.command()
def chart(
    kind: Annotated[str, typer.Argument(help="bars, edge, text or lines")],
    output: Annotated[Path, typer.Option("-o", "--output", help="output .png")],
    dpi: Annotated[float, typer.Option(help="resolution of the chart")] = 1200.0,
) -> None:
    """Write a built-in test chart (bar charts, slanted edge, 8-pt text, fine lines)."""
    from .charts import KINDS, make_chart
    from .io import write_atomic, write_png

    if kind not in KINDS:
        _fail(f"KIND: must be one of {', '.join(KINDS)} (got {kind!r})")
    if not 100 <= dpi <= 4800:
        _fail(f"--dpi: must lie in [100, 4800] (got {dpi:g})")
    if output.suffix.lower() != ".png":
        _fail(f"-o: charts are written as .png (got {output.name!r})")
    img, text = make_chart(kind, dpi)
    write_png(output, img, dpi)
    if text is not None:
        write_atomic(output.with_suffix(".txt"), text + "\n")
    typer.echo(f"wrote {output} ({img.shape[1]} x {img.shape[0]} at {dpi:g} dpi)", err=True)


@app.command("ocr-eval")
def ocr_eval(
    image: ImageArg,
    text: Annotated[Path, typer.Option("--text", help="ground-truth text file")],
    z: Annotated[str, typer.Option(help="float heights (mm)")] = "0.5,1.5,2.5,3.5",
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    dpi: DpiOpt = None,
    noiseless: Annotated[bool, typer.Option("--noiseless")] = False,
    as_json: JsonOpt = False,
) -> None:
    """Scan a text image at each Z, read it with Tesseract, report the character error rate."""
    from .io import linear_to_srgb, provenance
    from .ocr import OCRUnavailable, character_error_rate, recognise
    from .scan import simulate_scan

    d = _design(design)
    try:
        truth = text.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        _fail(f"--text: cannot read {text} ({err})")
    doc, use = _document(image, dpi, False)
    zs = _floats(z, "--z", 0.0, 10.0)
    out = {"z_mm": list(zs), "cer": [], "text": []}
    for zz in zs:
        r = simulate_scan(doc, use, d, z_mm=zz, seed=seed, noiseless=noiseless)
        try:
            got = recognise(linear_to_srgb(r.image), r.dpi)
        except OCRUnavailable as err:
            _fail(str(err))
        out["cer"].append(character_error_rate(truth, got))
        out["text"].append(got)
    data = out | {"provenance": provenance(d, seed)}
    lines = [f"{image}: character error rate against {text}"]
    lines += [f"Z = {zz:g} mm: CER {c:.3f}" for zz, c in zip(zs, out["cer"], strict=True)]
    _emit(data, as_json, lines)


DaskOpt = Annotated[
    str | None, typer.Option("--dask", help="Dask scheduler address, tcp://HOST:PORT")
]
WorkersOpt = Annotated[
    int | None, typer.Option("--workers", help="local worker processes (default: all cores)")
]


def _check_dask(address: str | None) -> None:
    if address is not None and not address.startswith(("tcp://", "tls://", "inproc://")):
        _fail(f"--dask: expected tcp://HOST:PORT (got {address!r})")


def _journal(out: Path | None) -> Path | None:
    return None if out is None else out.with_name(out.name + ".journal.jsonl")


def _pins(text: str | None) -> dict:
    if not text:
        return {}
    out = {}
    for part in text.split(","):
        k, _, v = part.partition("=")
        try:
            out[k.strip()] = float(v)
        except ValueError:
            _fail(f"--pin: expected NAME=VALUE pairs such as hole0=48,t2=1000 (got {part!r})")
    return out


@app.command()
def search(
    dpi: Annotated[float, typer.Option(help="target resolution of the merged line (dpi)")] = 300.0,
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    dof_dpi: Annotated[float, typer.Option(help="chart dpi of the depth of field")] = 200.0,
    budget_mm: Annotated[float, typer.Option(help="total stack thickness budget (mm)")] = 2.5,
    near_mm: Annotated[float, typer.Option(help="no ghost light within this distance")] = 1.0,
    max_ghost: Annotated[float | None, typer.Option(help="bound on the ghost fraction")] = None,
    population: Annotated[int, typer.Option(help="designs per generation")] = 32,
    generations: Annotated[int, typer.Option(help="NSGA-II generations")] = 15,
    pin: Annotated[str | None, typer.Option(help="fixed variables, e.g. hole0=48,t2=1000")] = None,
    layers: Annotated[
        str | None, typer.Option(help="also search other numbers of mask layers, e.g. 2,3")
    ] = None,
    stagger: Annotated[
        str | None, typer.Option(help="stagger patterns to search: yes, no or yes,no")
    ] = None,
    workers: WorkersOpt = None,
    dask: DaskOpt = None,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="results .nc")] = None,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Search hole sizes and gaps for ghost-free, bright, deep designs (paper §3)."""
    from .io import provenance, save_dataset
    from .search import base_for_dpi, search_dataset
    from .search import search as run

    _check_dask(dask)
    d = _design(design)
    if not 50 <= dpi <= 2400 or not 50 <= dof_dpi <= 2400:
        _fail("--dpi and --dof-dpi must lie in [50, 2400]")
    if not 0.2 <= budget_mm <= 20 or near_mm < 0:
        _fail("--budget-mm must lie in [0.2, 20] and --near-mm be >= 0")
    if not 4 <= population <= 1000 or not 1 <= generations <= 1000:
        _fail("--population must lie in [4, 1000] and --generations in [1, 1000]")
    if output is not None and output.suffix != ".nc":
        _fail(f"-o: results are written as netCDF, .nc (got {output.name!r})")
    merged = d.sensor.row_pitch_um / d.sensor.rows
    # 300 dpi is 84.67 um; the paper's sensor is 84.6 um (600-dpi pixels of 42.3): within
    # 1 % counts as the same resolution
    base = d if abs(25400.0 / dpi / merged - 1) < 0.01 else base_for_dpi(d, dpi)
    from .search import merged_front, structural_variants

    if layers or stagger:
        try:
            n_l = [int(v) for v in (layers or str(len(base.masks))).split(",")]
            sts = [v.strip() for v in (stagger or "yes").split(",")]
            bases = structural_variants(base, layers=n_l, stagger=sts)
        except ValueError as err:
            _fail(f"--layers/--stagger: {err}")
    else:
        bases = {base.name: base}
    results = {}
    for i, (name, b) in enumerate(bases.items()):
        out_i = output
        if output is not None and len(bases) > 1:
            out_i = output.with_name(f"{output.stem}.v{i}{output.suffix}")
        try:
            results[name] = run(
                b,
                dpi=dpi,
                dof_dpi=dof_dpi,
                budget_mm=budget_mm,
                near_mm=near_mm,
                max_ghost=max_ghost,
                population=population,
                generations=generations,
                seed=seed,
                pinned=_pins(pin),
                workers=workers,
                dask_address=dask,
                journal=_journal(out_i),
                progress=not as_json,
            )
        except (ValueError, OSError) as err:
            _fail(str(err))
        if out_i is not None:
            save_dataset(search_dataset(results[name], b, seed), out_i)
    r = next(iter(results.values()))
    data = r.to_dict() | {"provenance": provenance(base, seed)}
    if len(results) > 1:
        data["pareto"] = merged_front(results)
        data["variants"] = {k: v.to_dict() for k, v in results.items()}
    lines = [
        f"{base.name}: {sum(len(v.records) for v in results.values())} designs in "
        f"{len(results)} variant(s); Pareto front (holes object side first, um; slabs sensor "
        "first, um):"
    ]
    for p in data["pareto"]:
        tag = f" [{p['variant']}]" if "variant" in p else ""
        lines.append(
            f"  holes {p['holes_um']} slabs {p['thicknesses_um']}: efficiency "
            f"1/{1 / p['efficiency_ratio']:.0f}, DOF {p['dof_mm']:.2f} mm, ghosts "
            f"{p['ghost_fraction']:.3f}{tag}"
        )
    for name, res in results.items():
        ref = res.reference
        if ref:
            lines.append(
                f"base {name}: efficiency 1/{1 / ref['efficiency_ratio']:.0f}, DOF "
                f"{ref['dof_mm']:.2f} mm, ghosts {ref['ghost_fraction']:.3f}, dominated by "
                f"{ref.get('dominated_by', 0)} of its variant's designs"
            )
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_pareto, plot_pareto_variants

        _plot(plot_pareto(r) if len(results) == 1 else plot_pareto_variants(results), plot)


@app.command()
def tolerance(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    misregistration_um: Annotated[float, typer.Option(help="sigma of x/y misregistration")] = 3.0,
    hole_um: Annotated[float, typer.Option(help="sigma of the hole sizes (um)")] = 1.0,
    thickness_um: Annotated[float, typer.Option(help="sigma of plates and gaps (um)")] = 10.0,
    tilt_deg: Annotated[float, typer.Option(help="sigma of the stack tilt (deg)")] = 0.02,
    samples: Annotated[int, typer.Option(help="Monte Carlo samples")] = 1000,
    dpi: Annotated[float, typer.Option(help="chart dpi of the RMTF")] = 200.0,
    z: Annotated[str, typer.Option(help="distances of the RMTF (mm)")] = "0.5,1,2,3,3.5",
    spec: Annotated[str | None, typer.Option(help="e.g. dof>=2.2,ghost<=0.2,rmtf@2>=0.35")] = (
        None
    ),
    workers: WorkersOpt = None,
    dask: DaskOpt = None,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="results .nc")] = None,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Monte Carlo of assembly errors: RMTF, DOF, efficiency, ghosts, sensitivity, yield."""
    from .io import provenance, save_dataset
    from .tolerance import parse_spec, tolerance_dataset
    from .tolerance import tolerance as run

    _check_dask(dask)
    d = _design(design)
    if min(misregistration_um, hole_um, thickness_um, tilt_deg) < 0:
        _fail("sigmas (--misregistration-um, --hole-um, --thickness-um, --tilt-deg) must be >= 0")
    if not 1 <= samples <= 10**6:
        _fail(f"--samples: must lie in [1, 1e6] (got {samples})")
    if output is not None and output.suffix != ".nc":
        _fail(f"-o: results are written as netCDF, .nc (got {output.name!r})")
    try:
        parse_spec(spec)
    except ValueError as err:
        _fail(f"--spec: {err}")
    zs = _floats(z, "--z", 0.0, 10.0)
    sig = {
        "misregistration_um": misregistration_um,
        "hole_um": hole_um,
        "thickness_um": thickness_um,
        "tilt_deg": tilt_deg,
    }
    try:
        r = run(
            d,
            samples=samples,
            sigmas=sig,
            dpi=dpi,
            z_mm=zs,
            spec=spec,
            seed=seed,
            workers=workers,
            dask_address=dask,
            journal=_journal(output),
            progress=not as_json,
        )
    except (ValueError, OSError) as err:
        _fail(str(err))
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    if output is not None:
        save_dataset(tolerance_dataset(r, d), output)
    key = f"rmtf{dpi:g}"
    lines = [f"{d.name}: {samples} samples ({data['n_failed']} failed)"]
    for zz, pc in data[key].items():
        lines.append(
            f"  RMTF {dpi:g} dpi at Z = {zz} mm: median {pc['p50']:.3f} "
            f"(5-95 %: {pc['p5']:.3f}-{pc['p95']:.3f}), nominal "
            f"{r.nominal['rmtf_at'][zz]:.3f}"
        )
    dp = data["dof_mm"]
    lines.append(
        f"  DOF median {dp['p50']:.2f} mm (5-95 %: {dp['p5']:.2f}-{dp['p95']:.2f}), "
        f"nominal {r.nominal['dof_mm']:.2f}"
    )
    lines.append(
        "  most sensitive: "
        + ", ".join(
            f"{row['error']} ({row['d_dof_mm']:.3f} mm DOF per sigma)" for row in r.sensitivity[:5]
        )
    )
    if r.yield_fraction is not None:
        lines.append(f"  yield for {spec}: {r.yield_fraction:.1%}")
    _emit(data, as_json, lines)
    if plot:
        from .plotting import plot_tolerance

        _plot(plot_tolerance(r), plot)


@app.command()
def report(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="output folder")] = Path("report"),
    fresnel: FresnelOpt = False,
) -> None:
    """Run every analysis and write JSON, PNG figures and one HTML page."""
    from .report import build_report

    d = _design(design)
    build_report(d, out, seed=seed, n_rays=_rays(rays, 1 << 22), fresnel=fresnel, progress=True)
    typer.echo(f"wrote {out / 'index.html'} and {out / 'report.json'}")


def main() -> None:  # pragma: no cover
    app()
