"""Command line: `opticalstamp ghosts | spots | psf | rmtf | efficiency | diffraction |
measure-rmtf | sfr | report`."""

from __future__ import annotations

import functools
import sys
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Annotated

import typer

from ..defaults import DETECTOR_HALF_UM, RAYS_MAP, RSE_GHOST, RSE_OWN
from ..design import AnyDesign, Design, RodLensDesign, load_design
from ..validate import (
    InputError,
    check_number,
    check_output_path,
    check_seed,
    parse_grid,
    parse_numbers,
)

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    rich_markup_mode=None,
    help="Design and analyse lensless contact image scanners (optical stamps).",
)


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"opticalstamp {__version__}")
        raise typer.Exit()


#: the environment variable that gives ``--device`` its default; click reads it for the
#: command line (the library never reads the environment: it is handed the device)
DEVICE_ENV = "OPTICALSTAMP_DEVICE"


def _device(ctx: typer.Context, param: typer.CallbackParam, value: str | None) -> str | None:
    """--device (or OPTICALSTAMP_DEVICE): its name checked now, exit 2 naming where it
    came from; whether CUDA can run is checked when a command that traces rays starts
    (:func:`command`), so that ``--help`` and the commands that trace nothing work
    anywhere."""
    if value is None or ctx.resilient_parsing:
        return value
    from ..device import device_name

    try:
        return device_name(value)
    except InputError as err:
        msg = str(err).removeprefix("device: ")
        source = ctx.get_parameter_source(param.name)
        if source is not None and source.name == "ENVIRONMENT":
            fail(f"{DEVICE_ENV}: {msg}")
        raise typer.BadParameter(msg) from None


@app.callback()
def _options(
    ctx: typer.Context,
    version: Annotated[
        bool,
        typer.Option(
            "--version", help="print the version and exit", callback=_version, is_eager=True
        ),
    ] = False,
    device: Annotated[
        str | None,
        typer.Option(
            "--device",
            metavar="[auto|cpu|cuda]",
            help="where rays are traced: auto (a CUDA GPU where opticalstamp[cuda] is "
            f"installed, else the CPU), cpu or cuda; default: {DEVICE_ENV}, else auto",
            callback=_device,
            envvar=DEVICE_ENV,
            show_envvar=False,
        ),
    ] = None,
) -> None:
    """Design and analyse lensless contact image scanners (optical stamps)."""
    ctx.with_resource(_choosing(device or "auto"))


#: the device name this command line chose (--device, else OPTICALSTAMP_DEVICE, else
#: auto), set for the invocation by :func:`_options` and undone when it ends; resolved by
#: :func:`command` for the commands that trace rays
_CHOSEN: ContextVar[str] = ContextVar("opticalstamp_cli_device", default="auto")


@contextmanager
def _choosing(name: str):
    token = _CHOSEN.set(name)
    try:
        yield
    finally:
        _CHOSEN.reset(token)


def command(*args, traces: bool = True, **kwargs):
    """``app.command`` whose body turns any :class:`InputError` into ``error: ...``, exit 2.

    Options are checked by their callbacks while the command line is parsed (click reports
    ``Invalid value for '--option'`` with exit 2); what only the library can check (a
    design file, an image, a height map) raises InputError before any work is done. An
    OSError while writing (disk full) is reported in one line with exit code 1.
    ``traces``: the command traces rays: the device chosen is resolved once, before any
    work (``cuda`` without a GPU: exit 2), and the command runs with it as the run's
    device (:func:`~opticalstamp.device.using_device`): every tracer, study payload and
    provenance of the command takes it from there.
    """

    def deco(fn):
        @functools.wraps(fn)
        def run(*a, **kw):
            from contextlib import nullcontext

            from ..device import DeviceUnavailable, resolve_device, using_device

            try:
                scope = nullcontext()
                if traces:
                    try:
                        scope = using_device(resolve_device(_CHOSEN.get()))
                    except DeviceUnavailable as err:
                        fail(f"{err} (chosen by --device, else {DEVICE_ENV})")
                with scope:
                    return fn(*a, **kw)
            except InputError as err:
                fail(str(err))
            except OSError as err:  # the disk failed us mid-run: no traceback, exit 1
                typer.echo(f"error: {err}", err=True)
                raise typer.Exit(1) from None

        return app.command(*args, **kwargs)(run)

    return deco


def number(lo=None, hi=None, *, lo_open=False, hi_open=False, integer=False):
    """Option callback: a finite number in the interval (None passes: option not given)."""

    def check(ctx: typer.Context, param: typer.CallbackParam, value):
        if value is None or ctx.resilient_parsing:
            return value
        try:
            check_number(value, "value", lo, hi, lo_open=lo_open, hi_open=hi_open, integer=integer)
        except InputError as err:
            raise typer.BadParameter(str(err).removeprefix("value: ")) from None
        return value

    return check


def writable(*suffixes: str, directory: bool = False, marker: str | None = None):
    """Option callback: a writable output path with one of ``suffixes`` (see
    :func:`check_output_path`)."""

    def check(ctx: typer.Context, param: typer.CallbackParam, value):
        if value is None or ctx.resilient_parsing:
            return value
        try:
            check_output_path(value, "path", suffixes=suffixes, directory=directory, marker=marker)
        except InputError as err:
            raise typer.BadParameter(str(err).removeprefix("path: ")) from None
        return value

    return check


DesignOpt = Annotated[str, typer.Option("--design", "-d", help="preset name or design TOML file")]


def _seed(ctx: typer.Context, param: typer.CallbackParam, value):
    try:
        return check_seed(value, "--seed")
    except InputError as err:
        raise typer.BadParameter(str(err).removeprefix("--seed: ")) from None


SeedOpt = Annotated[
    int,
    typer.Option(
        "--seed", help="random seed, 0 to 2^63-1 (results are reproducible)", callback=_seed
    ),
]
RaysOpt = Annotated[
    int | None,
    typer.Option(
        "--rays",
        help="number of rays, 1000 to 1e10 (default: automatic)",
        callback=number(1000, 1e10, integer=True),
    ),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="print machine-readable JSON on stdout")]
PlotOpt = Annotated[
    Path | None, typer.Option("--plot", help="write a PNG figure", callback=writable(".png"))
]
FresnelOpt = Annotated[bool, typer.Option("--fresnel", help="apply Fresnel transmission losses")]


_fraction = number(0, 1, lo_open=True, hi_open=True)
_z_mm = number(0, 100)
_coordinate = number(-1e5, 1e5)


def fail(msg: str) -> None:
    typer.echo(f"error: {msg}", err=True)
    raise typer.Exit(2)


#: Commands that take either kind of design.
BOTH_KINDS = ("stamp", "rod-lens-array")


def open_design(spec: str, kinds: tuple[str, ...] = ("stamp",)) -> AnyDesign:
    """Load a design (InputError: exit 2); print a stamp's geometric-optics warnings.

    ``kinds``: the kinds of design the command analyses; another kind is refused with a
    message naming the command's scope and the commands that take it.
    """
    from ..analysis.diffraction import geometric_optics_warnings
    from ..design.describe import sensor_warnings

    d = load_design(spec)
    kind = "rod-lens-array" if isinstance(d, RodLensDesign) else "stamp"
    if kind not in kinds:
        raise InputError(
            f"--design {spec}: a {kind} design; this command analyses "
            f"{' and '.join(kinds)} designs (a rod-lens array: `opticalstamp compare`)"
        )
    if isinstance(d, Design):
        for w in sensor_warnings(d) + geometric_optics_warnings(d):
            typer.echo(f"warning: {w}", err=True)
    return d


def float_list(text: str, name: str, lo: float = 0.0, hi: float = 1000.0) -> tuple[float, ...]:
    return parse_numbers(text, name, lo, hi)


def z_grid(text: str, hi: float = 100.0) -> tuple[float, ...]:
    return parse_grid(text, "--z", 0.0, hi)


def ray_count(n: int | None, default: int) -> int:
    return default if n is None else n


def resolution(path: Path, file_dpi: float | None, dpi: float | None, lo: float) -> float:
    """The image's dpi: --dpi, else the file's; checked to lie in [lo, 20000]."""
    use = dpi or file_dpi
    if use is None:
        fail(f"{path}: the file carries no resolution; give --dpi")
    check_number(use, "--dpi" if dpi else f"{path}: resolution", lo, 20000)
    return use


def emit(data: dict, as_json: bool, lines: list[str]) -> None:
    from ..io.files import to_json

    if as_json:
        sys.stdout.write(to_json(data) + "\n")
    else:
        typer.echo("\n".join(lines))


def save_plot(fig, path: Path | None) -> None:
    if path is not None:
        from ..io.files import save_figure

        save_figure(fig, path)
        typer.echo(f"wrote {path}", err=True)


@command()
def ghosts(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    z: Annotated[str, typer.Option(help="object distances (mm), comma-separated")] = "0",
    rse_own: Annotated[
        float, typer.Option(help="target relative SE, own path", callback=_fraction)
    ] = RSE_OWN,
    rse_ghost: Annotated[
        float, typer.Option(help="target relative SE, ghosts", callback=_fraction)
    ] = RSE_GHOST,
    row: Annotated[str, typer.Option(help="pixel row, A or B")] = "A",
    detector_um: Annotated[
        float,
        typer.Option(
            help="half width of the virtual detector on the object plane (µm), (0, 1e6]",
            callback=number(0, 1e6, lo_open=True),
        ),
    ] = DETECTOR_HALF_UM,
    fresnel: FresnelOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Ghost (crosstalk) paths of one pixel: etendue, ghost fraction, where ghosts land."""
    from ..analysis.ghosts import analyse_ghosts
    from ..io.files import provenance

    d = open_design(design)
    if row not in ("A", "B") or (row == "B" and d.sensor.rows == 1):
        fail("--row: must be A, or B for a two-row design")
    zs = float_list(z, "--z", 0.0, 100.0)
    r = analyse_ghosts(
        d,
        pixel=("AB".index(row), 0),
        z_mm=zs,
        n_rays=None if rays is None else ray_count(rays, 0),
        rse_own=rse_own,
        rse_ghost=rse_ghost,
        seed=seed,
        fresnel=fresnel,
        detector_half_um=detector_um,
        progress=not as_json,
    )
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    lines = [f"design {d.name}: pixel {row}0, {r.n_rays:,} rays"]
    dark = r.own_etendue_bound is not None and r.etendue_ghost_um2sr == 0
    if r.own_etendue_bound == 0:  # no accepted ray reaches a hole: exactly no light
        lines.append(
            "no light reaches this pixel: no ray inside its acceptance cone "
            f"(±{d.sensor.acceptance_half_angle_deg:g}°) reaches a hole of the mask nearest "
            "the sensor (own-path and ghost etendue 0)"
        )
    elif dark:  # no ray carried light: a bound, not a row of zeros
        lines.append(
            "no light found reaching this pixel: own-path and ghost etendue each < "
            f"{r.own_etendue_bound:.2g} µm²·sr (95 % bound)"
        )
    elif r.own_etendue_bound is not None:
        lines.append(
            f"no own-path light found: own-path etendue < {r.own_etendue_bound:.2g} µm²·sr "
            "(95 % bound); the light found is ghost light"
        )
    else:
        lines.append(
            f"own-path etendue   {r.etendue_own_um2sr:.5g} ± {r.etendue_own_se:.2g} µm²·sr"
        )
    if dark:
        pass
    elif r.ghost_ratio_bound is not None:  # no ray carried ghost light: a bound, no rows of 0
        lines.append(f"no ghost light found: ghost/own < {r.ghost_ratio_bound:.2g} (95 % bound)")
    else:
        lines += [
            f"ghost etendue      {r.etendue_ghost_um2sr:.5g} ± {r.etendue_ghost_se:.2g} µm²·sr",
            f"ghost fraction     {r.ghost_fraction:.4g} ± {r.ghost_fraction_se:.2g}",
        ]
    for zk, v in r.landing.items() if r.ghost_ratio_bound is None and not dark else ():
        lines.append(
            f"Z = {zk} mm: nearest ghost light "
            + ("none" if v["nearest_um"] is None else f"{v['nearest_um'] / 1000:.2f} mm")
            + " from the axis, "
            f"{v['within_detector_um2sr']:.3g} µm²·sr inside ±{detector_um:g} µm"
        )
    for p in r.paths[:10]:
        hs = ", ".join(f"{h['mask']} {h['row']} {h['dk']:+d}" for h in p.holes)
        lines.append(
            f"  {p.etendue_um2sr:9.4g} µm²·sr  {p.share:6.1%}  [{hs}]  "
            f"{p.emission_angle_deg[0]:.1f}–{p.emission_angle_deg[1]:.1f}°"
        )
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_ghosts

        save_plot(plot_ghosts(r), plot)


@command()
def spots(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    z: Annotated[str, typer.Option(help="object distances (mm)")] = "0,1,2,3,4",
    no_ghosts: Annotated[bool, typer.Option("--no-ghosts", help="leave ghost light out")] = False,
    fresnel: FresnelOpt = False,
    optics: Annotated[
        str,
        typer.Option(
            "--optics",
            help="ray, wave (the wave engine in its band + the traced far ghosts) or auto "
            "(wave where the measured validity rule says ray optics is off)",
        ),
    ] = "auto",
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Responsivity map (spot) of one pixel on the object plane at each Z (paper Fig. 5)."""
    from ..analysis.spots import spots as run
    from ..io.files import provenance
    from .optics import optics_line

    d = open_design(design)
    r = run(
        d,
        z_mm=float_list(z, "--z", 0.0, 100.0),
        n_rays=ray_count(rays, RAYS_MAP),
        seed=seed,
        fresnel=fresnel,
        ghosts=not no_ghosts,
        progress=not as_json,
        optics=optics,
    )
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    wave = r.meta["optics"]["engine"] == "wave"
    lines = [
        f"design {d.name}: spots of pixel A0 ({r.n_rays:,} rays)",
        optics_line(r.meta["optics"]),
        f"Z (mm)  extent x/y (µm{', geometric' if wave else ''})   FWHM x/y (µm)   "
        "centre-cell fraction",
    ]
    for s in r.spots:
        lines.append(
            f"{s.z_mm:6g}  {s.extent_x_um:7.1f} {s.extent_y_um:7.1f}  "
            f"{s.fwhm_x_um:7.1f} {s.fwhm_y_um:7.1f}   {s.center_cell_fraction:.3f}"
        )
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_spots

        save_plot(plot_spots(r), plot)


@command()
def psf(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    z: Annotated[
        float, typer.Option(help="object distance Z (mm), 0 to 100", callback=_z_mm)
    ] = 1.0,
    x_obj: Annotated[
        float, typer.Option(help="object point x (µm), |x| ≤ 1e5", callback=_coordinate)
    ] = 0.0,
    y_obj: Annotated[
        float, typer.Option(help="object point y (µm), |y| ≤ 1e5", callback=_coordinate)
    ] = 0.0,
    fresnel: FresnelOpt = False,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Where light from a Lambertian object point lands on the sensor (paper Fig. 10)."""
    from ..analysis.spots import psf as run
    from ..io.files import provenance

    d = open_design(design)
    r = run(
        d,
        x_obj_um=x_obj,
        y_obj_um=y_obj,
        z_mm=z,
        n_rays=ray_count(rays, RAYS_MAP),
        seed=seed,
        fresnel=fresnel,
        progress=not as_json,
    )
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    lines = [
        f"design {d.name}: point ({x_obj:g}, {y_obj:g}) µm at Z = {z:g} mm",
        f"own pixel {r.own_pixel_id['row']}{r.own_pixel_id['k']}: {r.own_pixel:.4f}",
        f"neighbours, own-path blur: {r.neighbour_own_path:.4f}",
        f"ghosts: {r.neighbour_ghost:.4f}",
        f"insensitive area: {r.insensitive:.4f}",
        f"(fractions of the {r.reaching_sensor:.3g} of emitted power reaching the sensor)",
    ]
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_psf

        save_plot(plot_psf(r), plot)


@command()
def report(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    rays: RaysOpt = None,
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            help="output folder (replaced as a whole)",
            callback=writable(directory=True, marker="report.json"),
        ),
    ] = Path("report"),
    fresnel: FresnelOpt = False,
    spec: Annotated[
        str | None,
        typer.Option(
            "--spec",
            help="figures the design must meet, FIGURE>=NUMBER or FIGURE<=NUMBER, "
            "comma-separated, e.g. dof>=2.2,ghost_radius>=5. Figures and their units: "
            "ghost_radius (mm: the nearest ghost light on the object plane), dof (mm: depth "
            "of field), restored_dof (mm: after Wiener restoration), light (own-path light "
            "as a ratio to the paper's F/10 reference lens; the paper: 1/36 = 0.028), "
            "f_number (the working F-number; the paper: 60), vs_rod_lens (light as a ratio "
            "to a 1-row 12° rod-lens array; the paper: 0.01), thickness (mm, sensor to the "
            "reference plane), yield (tolerance yield, a fraction 0 to 1)",
        ),
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="print the report's verdict (summary) as JSON")
    ] = False,
    quick: Annotated[
        bool,
        typer.Option(
            "--quick",
            help="a first look in seconds: fewer rays, distances and scan pixels; no "
            "parameter study, design search, tolerance study or OCR (the page says so)",
        ),
    ] = False,
    z: Annotated[
        str | None,
        typer.Option(
            help="heights (mm) of the ghost landings and spots, comma-separated, 0 to 100 "
            "(default 0,1,2,3,4; the RMTF curves run at least as far)"
        ),
    ] = None,
    dpi: Annotated[
        float | None,
        typer.Option(
            help="chart (dpi) of the depth of field, the verdict, the search and the "
            "tolerance study, 50 to 2400 [default: 2/3 of the design's resolution: 200 for "
            "300 dpi, 400 for 600]",
            callback=number(50, 2400),
            show_default=False,
        ),
    ] = None,
    paper_sections: Annotated[
        str,
        typer.Option(
            help="the paper's own sections (Fig. 1 concepts, its unstated parameters, "
            "paper vs model): auto (only for the paper's presets), yes or no"
        ),
    ] = "auto",
    optics: Annotated[
        str,
        typer.Option(
            "--optics",
            help="engine of the headline RMTF, depth of field and light: ray, wave or auto "
            "(wave where the measured validity rule says ray optics is off by more than "
            "its tolerance)",
        ),
    ] = "auto",
    fit: Annotated[
        Path | None, typer.Option(help="opticalstamp fit --report's folder or its fit.json")
    ] = None,
) -> None:
    """Run every analysis and write JSON, PNG figures and one HTML page."""
    from ..report.build import build_report
    from ..report.fitsection import load_fit

    d = open_design(design)
    from ..report.summary import parse_report_spec

    parse_report_spec(spec)  # refused before any work
    if paper_sections not in ("auto", "yes", "no"):
        fail(f"--paper-sections: must be auto, yes or no (got {paper_sections!r})")
    zs = None if z is None else float_list(z, "--z", 0.0, 100.0)
    fit_data = None if fit is None else load_fit(fit)  # "model vs measurement"
    data = build_report(
        d,
        out,
        seed=seed,
        n_rays=ray_count(rays, RAYS_MAP),
        fresnel=fresnel,
        progress=not as_json,
        quick=quick,
        spec=spec,
        z_mm=zs,
        dpi=dpi,
        paper_sections=None if paper_sections == "auto" else paper_sections == "yes",
        optics=optics,
        fit=fit_data,
    )
    typer.echo(f"wrote {out / 'index.html'} and {out / 'report.json'}", err=as_json)
    if as_json:
        emit({"summary": data["summary"]}, True, [])


def main() -> None:  # pragma: no cover
    app()
