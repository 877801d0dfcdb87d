"""Commands about a design itself: the presets to start from and the mask artwork."""

from __future__ import annotations

from pathlib import Path
from textwrap import shorten
from typing import Annotated

import typer

from ..design import RodLensDesign, load_design, preset_names, preset_text
from .common import (
    BOTH_KINDS,
    JsonOpt,
    PlotOpt,
    app,
    command,
    emit,
    fail,
    open_design,
    save_plot,
    writable,
)

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
        summary = d.description.split(":")[0]  # the part before the details
        typer.echo(f"{name:<24} {kind:<15} {shorten(summary, 70, placeholder='…')}")


@presets_app.command("show")
def presets_show(name: Annotated[str, typer.Argument(help="a preset name")]) -> None:
    """Print a preset as TOML, to start a design file from (> my_design.toml)."""
    if name not in preset_names():
        fail(f"presets show: no preset {name!r}; the presets are {', '.join(preset_names())}")
    typer.echo(preset_text(name), nl=False)


app.add_typer(presets_app, name="presets")


@command(traces=False)
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
    misregistration applied, alignment marks, a label with the design's fingerprint.

    Tone: the drawn polygons are the holes, clear openings in the absorbing layer
    (chrome): a dark-field mask, drawn = clear; the alignment crosses (datatype 1) are
    clear too.

    Grid: GDSII user unit 1 µm, database unit 1 nm; every length drawn is a whole number
    of nm (hole sizes of 2 nm, as holes are centred), so the arrays read back exactly. A
    design whose row pitch, row-B stagger, misregistration or hole sizes are off that
    grid is refused (exit 2) with the nearest values and what snapping would cost, not
    snapped; designs from search --dpi are on the grid."""
    from ..io.artwork import FORMATS, mask_layouts, write_masks

    if fmt is not None and fmt.lower() not in FORMATS:
        fail(f"--format: must be one of {', '.join(FORMATS)} (got {fmt!r})")
    d = open_design(design)
    path = write_masks(d, output, fmt)
    for m in mask_layouts(d):
        typer.echo(
            f"layer {m.layer} ({m.name}): {len(m.rows)} × {m.count} {m.shape} holes "
            f"{m.width_um:g} × {m.height_um:g} µm, pitch {m.pitch_um:g} µm"
        )
    typer.echo(f"wrote {path} ({path.stat().st_size:,} bytes, fingerprint {d.fingerprint()})")


def _derived(key: str, value: float) -> str:
    """A derived figure as a line: its JSON key's unit written as a unit
    (``g_per_mm`` -> ``g: 0.3 mm⁻¹``, ``rod_length_mm`` -> ``rod length: 4.2 mm``)."""
    name, unit = key, ""
    for suffix, written in (("_per_mm", " mm⁻¹"), ("_mm", " mm")):
        if key.endswith(suffix):
            name, unit = key.removesuffix(suffix), written
            break
    return f"  {name.replace('_', ' ')}: {value:.4g}{unit}"


@command(traces=False)
def show(
    design: Annotated[str, typer.Argument(help="preset name or design TOML file")],
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """The design as built: its stack as a table (layer 1 = the object side, as the paper
    numbers them), its pixel lattice and, with --plot, a to-scale cross-section."""
    from ..io.files import provenance

    d = open_design(design, kinds=BOTH_KINDS)
    if isinstance(d, RodLensDesign):
        if plot is not None:
            fail("--plot: the cross-section is drawn for stamps")
        a = d.array
        data = {
            "design": d.model_dump(mode="json"),
            "derived": {
                "numerical_aperture": a.na,
                "g_per_mm": a.g_per_um * 1000,
                "pitch_length_mm": a.pitch_length_um / 1000,
                "view_radius_mm": a.view_radius_um / 1000,
                "overlap_degree": a.overlap_degree,
                "rod_length_mm": a.length_um / 1000,
                "working_distance_mm": a.working_um / 1000,
                "conjugate_length_mm": a.conjugate_um / 1000,
                "sensor_to_document_mm": d.reference_plane_um / 1000,
            },
        } | {"provenance": provenance(d, None, traced=False)}
        lines = [f"{d.name}: rod-lens array, {a.rows} row(s) of rods R = {a.rod_radius_um:g} µm"]
        lines += [_derived(k, v) for k, v in data["derived"].items()]
        emit(data, as_json, lines)
        return
    from ..design.describe import stack_rows
    from ..raytrace.stack import output_pitch
    from ..units import dpi_of_pitch

    rows = stack_rows(d)
    s = d.sensor
    pitch = output_pitch(d)
    data = {
        "design": d.name,
        "stack": rows,
        "output_pitch_um": pitch,
        "output_dpi": dpi_of_pitch(pitch),
        "reference_plane_um": d.reference_plane_um,
        "provenance": provenance(d, None, traced=False),
    }
    lines = [
        f"{d.name}: {len(d.masks)} aperture layers, {s.rows} row(s) of used pixels every "
        f"{s.row_pitch_um:g} µm ({dpi_of_pitch(pitch):.0f} dpi merged), reference plane "
        f"{d.reference_plane_um / 1000:.3f} mm above the sensor",
        "object side",
        f"{'layer':>5}  {'medium':<12}{'n':>7}{'thick µm':>10}{'z top µm':>10}  hole",
    ]
    for r in rows:
        m = r["mask"]
        hole = "" if m is None else f"{m['shape']} {m['width_um']:g} × {m['height_um']:g} µm"
        if m is not None and (m["offset_x_um"] or m["offset_y_um"]):
            hole += f", offset ({m['offset_x_um']:g}, {m['offset_y_um']:g}) µm"
        if r.get("reference_gap"):
            hole = "(reference gap)"
        layer = "" if r["layer"] is None else str(r["layer"])
        lines.append(
            f"{layer:>5}  {str(r['medium']):<12}{r['index']:>7.4f}{r['thickness_um']:>10g}"
            f"{r['z_top_um']:>10g}  {hole}"
        )
    lines.append("sensor side")
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting.stack import plot_stack

        save_plot(plot_stack(d), plot)
