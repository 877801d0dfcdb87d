"""`opticalstamp fit`: fit a design to a prototype's scans of the project's charts
(issue 24)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..validate import InputError
from .common import (
    DesignOpt,
    JsonOpt,
    SeedOpt,
    command,
    emit,
    fail,
    number,
    open_design,
    writable,
)
from .metrics import DpiOpt, LinearOpt, read_scan_image
from .optics import OpticsOpt


def _image_spec(text: str) -> tuple[Path, float, float | None]:
    """IMAGE:Z_MM[:CHART_DPI], the height in the modelled range and the resolution the
    chart was drawn at (None: an ideal chart)."""
    from ..imaging.heightmap import Z_RANGE_MM

    chart = None
    if text.endswith(":"):
        fail(
            f"{text}: an empty field after the last ':' (IMAGE:Z_MM or "
            "IMAGE:Z_MM:CHART_DPI: the chart's height above the scanner's top, mm; the dpi "
            "it was drawn at)"
        )
    parts = text.rsplit(":", 2)
    three = len(parts) == 3 and parts[0] and _is_number(parts[1]) and _is_number(parts[2])
    if three and not Path(parts[0]).exists() and Path(f"{parts[0]}:{parts[1]}").exists():
        three = False  # a file whose name ends in ':number' (IMAGE:Z_MM)
    if three:
        text_z, chart = f"{parts[0]}:{parts[1]}", float(parts[2])
        if not CHART_DPI[0] <= chart <= CHART_DPI[1]:
            fail(
                f"{text}: chart resolution {chart:g} dpi outside [{CHART_DPI[0]:g}, "
                f"{CHART_DPI[1]:g}] (IMAGE:Z_MM:CHART_DPI, the dpi the chart was drawn at)"
            )
    else:
        text_z = text
    path, sep, z = text_z.rpartition(":")
    if not sep or not path:
        fail(
            f"{text}: expected IMAGE:Z_MM or IMAGE:Z_MM:CHART_DPI (the chart's height above "
            "the scanner's top, mm; the dpi it was drawn at)"
        )
    try:
        zv = float(z)
    except ValueError:
        fail(f"{text}: the height {z!r} is not a number (IMAGE:Z_MM)")
    lo, hi = Z_RANGE_MM
    if not lo <= zv <= hi:
        fail(f"{text}: height {zv:g} mm outside the modelled range [{lo:g}, {hi:g}] mm")
    return Path(path), zv, chart


#: The resolutions (dpi) a chart may be said to be drawn at (IMAGE:Z_MM:CHART_DPI).
CHART_DPI = (100.0, 100000.0)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def starts_lines(starts: list[dict]) -> list[str]:
    """How the starts ended: how many reached the fast model's lowest minimum (chi2
    within 1) and, under wave optics, which the wave model judged best."""
    good = sum(1 for s in starts if s["delta_chi2"] is not None and s["delta_chi2"] < 1.0)
    out = [f"{good} of {len(starts)} starts reached the lowest minimum (delta chi2 < 1)"]
    best = next((s for s in starts if s.get("best")), None)
    if best is not None and best.get("wave_chi2") is not None:
        near = [
            s for s in starts if s is not best and s.get("wave_chi2") is not None
            and s["wave_chi2"] < best["wave_chi2"] + 1.0
        ]  # fmt: skip
        out.append(
            f"the wave model judged start {best['start']}'s minimum best (wave chi2 "
            f"{best['wave_chi2']:.1f} there, before the polish; {len(near)} more within 1)"
        )
    return out


def _names(text: str | None, option: str) -> list[str] | None:
    if text is None:
        return None
    out = [t.strip() for t in text.split(",") if t.strip()]
    if not out:
        fail(f"{option}: expected comma-separated parameter names")
    return out


def _pins(text: str | None) -> dict[str, float]:
    out = {}
    for item in _names(text, "--pin") or []:
        name, sep, value = item.partition("=")
        try:
            out[name.strip()] = float(value) if sep else float("nan")
        except ValueError:
            fail(f"--pin {item}: expected NAME=VALUE (um)")
        if not sep or out[name.strip()] != out[name.strip()]:
            fail(f"--pin {item}: expected NAME=VALUE (um)")
    return out


def _observations(specs, dpi, linear, calibration_lines):
    """Each image read and its chart found; one dpi, the design's merged line's, and one
    design (where the images carry scan sidecars)."""
    from ..imaging.heightmap import Z_RANGE_MM
    from ..io.sidecar import read_sidecar
    from ..studies.fitdata import observation

    obs, seen_dpi, designs = [], None, {}
    for text in specs:
        path, z, chart = _image_spec(text)
        img, use = read_scan_image(path, dpi, linear, min_px=16)
        if seen_dpi is not None and abs(use - seen_dpi) > 1e-6 * seen_dpi:
            fail(f"{text}: {use:g} dpi, the images before it {seen_dpi:g} dpi (one scanner)")
        seen_dpi = use
        try:
            side = read_sidecar(path, z_range_mm=Z_RANGE_MM)
        except InputError as err:
            fail(f"{text}: {err}")
        if side and side.get("design_fingerprint"):
            designs[text] = side["design_fingerprint"]
        try:
            obs.append(
                observation(
                    img, use, z, name=path.name, calibration_lines=calibration_lines,
                    chart_dpi=chart,
                )
            )  # fmt: skip
        except ValueError as err:
            fail(f"{text}: {err}")
    if len(set(designs.values())) > 1:
        listed = ", ".join(f"{k} ({v})" for k, v in designs.items())
        fail(f"IMAGE: the images are scans of different designs: {listed}")
    return obs, seen_dpi


def _write_report(folder: Path, res, obs, specs, dpi, linear, data: dict) -> None:
    """fit.json, rmtf.png (measured points, nominal and fitted curves) and residuals.png."""
    from ..io.atomic import write_atomic
    from ..io.files import save_figure, to_json
    from ..report.plotting.fit import plot_fit_residuals, plot_fit_rmtf
    from ..studies.fitcompare import residuals, rmtf_comparison

    folder.mkdir(parents=True, exist_ok=True)
    imgs = {}
    for text in specs:
        path = _image_spec(text)[0]
        imgs[path.name] = read_scan_image(path, dpi, linear, min_px=16)[0]
    comp = rmtf_comparison(res, obs, imgs)
    res_items = residuals(res, obs)
    keep = ("name", "kind", "z_mm", "residual")  # what `report --fit` shows
    data = data | {"rmtf": comp, "residuals": [{k: r[k] for k in keep} for r in res_items]}
    write_atomic(folder / "fit.json", to_json(data) + "\n")
    if comp["points"]:
        save_figure(plot_fit_rmtf(comp), folder / "rmtf.png")
    save_figure(plot_fit_residuals(res_items), folder / "residuals.png")
    typer.echo(f"wrote {folder}/fit.json and its figures", err=True)


def result_lines(res) -> list[str]:
    """The fit as text: estimates with errors, parameters held at nominal, chi2, starts,
    degeneracies."""
    from ..studies.fit import HELD
    from ..studies.fitresult import fit_optics, optics_words

    lines = [
        f"fit of {res.design.name}: chi2 {res.chi2:.1f} for {res.dof} degrees of freedom "
        f"(reduced {res.chi2 / max(res.dof, 1):.2f}; errors scaled by {res.error_scale:.2f})",
        f"{'parameter':12s} {'nominal':>10s} {'fitted':>10s} {'error':>9s}",
    ]
    for n, v, e, m in zip(res.names, res.values, res.errors, res.nominal, strict=True):
        err = "undet." if e is None else f"{e:9.3g}"
        lines.append(f"{n:12s} {m:10.3f} {v:10.3f} {err:>9s}")
    for n, v in res.held.items():
        lines.append(f"{n:12s} {v:10.3f} {v:10.3f}    {HELD}")
    for c in res.held_combinations:
        terms = " ".join(f"{v:+.2f} {n}" for n, v in c.items())
        lines.append(f"combination {terms} (assembly scales): {HELD}")
    for n, v in res.pinned.items():
        lines.append(f"{n:12s} pinned at {v:g}")
    lines += starts_lines(res.starts)
    lines.append(optics_words(res.optics))
    lines += [f"warning: {m}" for m in res.degeneracies]
    warning = fit_optics(res.design, res.optics)
    if warning:
        lines.append(f"warning: {warning}")
    return lines


@command("fit", traces=False)
def fit_cmd(
    images: Annotated[
        list[str],
        typer.Argument(
            help="IMAGE:Z_MM[:CHART_DPI], a scan of a bar chart (chart bars) or a slanted "
            "square (chart edge), its height above the scanner's top surface (mm) and, for "
            "a slanted square, optionally the resolution it was drawn at (its pixels' blur "
            "is then modelled; default an ideal edge)",
            show_default=False,
        ),
    ],
    output: Annotated[
        Path,
        typer.Option("--output", "-o", help="fitted design file", callback=writable(".toml")),
    ],
    design: DesignOpt = "paper2016",
    free: Annotated[
        str | None,
        typer.Option(help="parameters to fit, comma-separated [default: every one not pinned]"),
    ] = None,
    pin: Annotated[
        str | None, typer.Option(help="parameters held, NAME=VALUE (um), comma-separated")
    ] = None,
    starts: Annotated[
        int, typer.Option(help="local fits (the nominal first)", callback=number(1, 50))
    ] = 3,
    calibration_lines: Annotated[
        int,
        typer.Option(
            help="lines of the scanner's white and dark references", callback=number(1, 1e6)
        ),
    ] = 32,
    seed: SeedOpt = 0,
    optics: OpticsOpt = "auto",
    dpi: DpiOpt = None,
    linear: LinearOpt = None,
    as_json: JsonOpt = False,
    report: Annotated[
        Path | None,
        typer.Option(
            help="folder for the figures and fit.json",
            callback=writable(directory=True),
        ),
    ] = None,
) -> None:
    """Fit the design to scans of charts: misregistration, thicknesses, holes, sensitive
    area and the true reference plane, with errors and the degeneracies named. The optics
    is chosen once, for the nominal design, as the other commands choose it."""
    from ..analysis.responsivity import resolve_optics
    from ..design.files import design_toml
    from ..design.model import Design
    from ..imaging.kernels import kernel_source
    from ..io.atomic import write_atomic
    from ..studies.fit import FitError, fit

    d = open_design(design)
    if not isinstance(d, Design):  # pragma: no cover - open_design refuses others
        fail(f"--design {design}: not a stamp")
    try:
        src = kernel_source(d, "auto")
    except ValueError as err:
        fail(f"--design {design}: {err}")
    if src != "paraxial":
        fail(
            f"--design {design}: fit uses the paraxial closed form of the own path, which "
            "this design does not admit (circular holes, or own-path rays steeper than "
            "the paraxial limit); make its holes square (opticalstamp.design.square_holes)"
        )
    try:  # once, for the nominal design; a bad or impossible optics before any work
        opt = resolve_optics(d, optics)
    except ValueError as err:
        fail(f"--{err}")
    obs, use = _observations(images, dpi, linear, calibration_lines)
    from ..imaging.scan import scan_pitch
    from ..units import dpi_of_pitch

    want = dpi_of_pitch(scan_pitch(d))
    if abs(use - want) > 0.01 * want:
        fail(f"IMAGE: {use:g} dpi, the design's merged line is {want:g} dpi (--design {design})")
    try:
        res = fit(
            d,
            obs,
            free=_names(free, "--free"),
            pinned=_pins(pin),
            starts=starts,
            seed=seed,
            optics=opt,
        )
    except FitError as err:
        fail(str(err))
    text = design_toml(
        res.fitted,
        comments=(
            f"fitted by opticalstamp fit to {len(obs)} images from {d.name} "
            f"({d.fingerprint()}); errors in the JSON (--json, --report)",
        ),
    )
    write_atomic(output, text)
    data = res.to_dict() | {"output": str(output), "images": list(images)}
    if report is not None:
        _write_report(report, res, obs, images, dpi, linear, data)
    emit(data, as_json, result_lines(res) + [f"wrote {output}"])
