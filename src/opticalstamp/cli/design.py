"""Commands about a design itself: the presets to start from and the mask artwork."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..design import RodLensDesign, load_design, preset_names
from .common import app, command, fail, open_design, writable

presets_app = typer.Typer(
    help="Built-in designs to start from: list them, or print one as a design file.",
    no_args_is_help=False,
    invoke_without_command=True,
    rich_markup_mode=None,
)


@presets_app.callback()
def presets(ctx: typer.Context) -> None:
    """List the built-in designs, one line each (kind, name, description)."""
    if ctx.invoked_subcommand is not None:
        return
    for name in preset_names():
        d = load_design(name)
        kind = "rod-lens-array" if isinstance(d, RodLensDesign) else "stamp"
        typer.echo(f"{name:<24} {kind:<15} {d.description.split(':')[0][:70]}")


@presets_app.command("show")
def presets_show(name: Annotated[str, typer.Argument(help="a preset name")]) -> None:
    """Print a preset as TOML, to start a design file from (> my_design.toml)."""
    from importlib import resources

    if name not in preset_names():
        fail(f"presets show: no preset {name!r}; the presets are {', '.join(preset_names())}")
    text = (resources.files("opticalstamp.design") / "presets" / f"{name}.toml").read_text()
    typer.echo(text, nl=False)


app.add_typer(presets_app, name="presets")


@command()
def masks(
    design: Annotated[str, typer.Argument(help="preset name or design TOML file (a stamp)")],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            help="artwork file: .gds (GDSII) or .dxf",
            callback=writable(".gds", ".dxf"),
        ),
    ] = Path("masks.gds"),
    fmt: Annotated[
        str | None,
        typer.Option("--format", help="gds or dxf (default: the output's suffix)"),
    ] = None,
) -> None:
    """Mask artwork for lithography: one layer per mask (layer 1 = the object side, as the
    paper numbers them), the holes of the whole sensor line as array references, designed
    misregistration applied, alignment marks, a label with the design's fingerprint."""
    from ..io.artwork import FORMATS, mask_layouts, write_masks

    if fmt is not None and fmt.lower() not in FORMATS:
        fail(f"--format: must be one of {', '.join(FORMATS)} (got {fmt!r})")
    d = open_design(design)
    path = write_masks(d, output, fmt)
    for m in mask_layouts(d):
        typer.echo(
            f"layer {m.layer} ({m.name}): {len(m.rows)} x {m.count} {m.shape} holes "
            f"{m.width_um:g} x {m.height_um:g} um, pitch {m.pitch_um:g} um"
        )
    typer.echo(f"wrote {path} ({path.stat().st_size:,} bytes, fingerprint {d.fingerprint()})")
