"""Command line: `opticalstamp ghosts | spots | psf | rmtf | efficiency | diffraction |
measure-rmtf | sfr | report`."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

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


def _resolution(path: Path, file_dpi: float | None, dpi: float | None, lo: float) -> float:
    """The image's dpi: --dpi, else the file's; checked to lie in [lo, 20000]."""
    use = dpi or file_dpi
    if use is None:
        _fail(f"{path}: the file carries no resolution; give --dpi")
    if not lo <= use <= 20000:
        _fail(f"--dpi: must lie in [{lo:g}, 20000] (got {use:g})")
    return use


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


# the other commands register themselves on ``app`` (imported last: they use the above)
from . import cli_metrics, cli_scan, cli_search  # noqa: E402, F401


def main() -> None:  # pragma: no cover
    app()
