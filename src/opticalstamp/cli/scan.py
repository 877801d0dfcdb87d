"""Commands of the scan simulation: scan, chart, ocr-eval."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..design.electronics import MIN_ILLUMINANCE_LUX
from ..units import pitch_of_dpi, um_to_mm
from ..validate import check_output_path, parse_numbers
from .common import (
    BOTH_KINDS,
    DesignOpt,
    FresnelOpt,
    JsonOpt,
    SeedOpt,
    command,
    emit,
    fail,
    float_list,
    number,
    open_design,
    resolution,
    writable,
)
from .metrics import DpiOpt, ImageArg
from .optics import OpticsOpt


def _document(path: Path, dpi: float | None, color: bool, min_px: int = 2):
    """A document checked from its header (``min_px`` pixels a side at least) and read."""
    from ..io.files import ImageError, read_document

    try:
        doc, file_dpi = read_document(path, color=color, dpi=dpi, min_px=min_px)
    except ImageError as err:
        fail(str(err))
    use = resolution(path, file_dpi, dpi, 50.0)
    if use < 600:
        typer.echo(
            f"warning: {path} is sampled at {use:g} dpi; at least 600 dpi is recommended "
            "(the document's own pixels blur the simulated 300-dpi scan)",
            err=True,
        )
    return doc, use


def _height(spec: str | None, z: float | None, doc_shape, dpi: float, seed: int):
    from ..imaging.heightmap import HeightMapError, load_height_map

    if (spec is None) == (z is None):
        fail("give exactly one of --z MM and --height-map FILE|SHAPE")
    if spec is None:  # --z itself is checked while parsing
        return None
    h_mm, w_mm = (um_to_mm(n * pitch_of_dpi(dpi)) for n in doc_shape[:2])
    try:
        return load_height_map(spec, h_mm, w_mm, seed)
    except HeightMapError as err:
        fail(str(err))


def _illumination_profile(path: Path) -> tuple:
    from ..io.files import read_illumination_profile
    from ..validate import InputError

    try:
        return read_illumination_profile(path)
    except InputError as err:
        fail(f"--illumination: {err}")


def _kernel_for(d, kernel: str, optics: str, fresnel: bool) -> tuple[str, list[str], dict]:
    """``--kernel auto`` for a stamp by ``--optics``, as the other commands choose: wave
    kernels where the design's optics is wave (``auto``: the measured validity rule),
    else the closed form or the tracer; any other ``--kernel``, and a rod-lens array's,
    as asked. Returns (the kernel source, the line saying which optics and why, the
    optics' record for the sidecar: empty where none was chosen)."""
    from ..design import Design

    if kernel != "auto" or not isinstance(d, Design):
        return kernel, [], {}
    from ..analysis.responsivity import resolve_optics
    from .optics import optics_line

    opt = resolve_optics(d, optics, fresnel=fresnel, channels=True).to_dict()
    return ("wave" if opt["engine"] == "wave" else "auto"), [optics_line(opt)], opt


def _settings(
    illumination: str,
    kernel: str,
    speed_error: float,
    surround: float,
    electronics,
    illuminance: float | None,
    exposure: float | None,
    fresnel: bool,
):
    """The scan's settings: the design's ``electronics`` with --illuminance-lux and
    --exposure-ms, where given, in place of its illuminance and exposure."""
    from pydantic import ValidationError

    from ..imaging.scan import KERNELS, ScanSettings
    from ..imaging.sensor import SensorModel

    if kernel not in KERNELS:
        fail(f"--kernel: expected one of {', '.join(KERNELS)} (got {kernel!r})")
    profile, source = None, illumination
    if illumination not in ("uniform", "ripple"):
        profile = _illumination_profile(Path(illumination))
        illumination = "uniform"
    try:
        given = {"illuminance_lux": illuminance, "exposure_ms": exposure}
        sensor = SensorModel.model_validate(
            electronics.model_dump() | {k: v for k, v in given.items() if v is not None}
        )
        return ScanSettings(
            sensor=sensor,
            illumination=illumination,
            illumination_profile=profile,
            kernel=kernel,
            speed_error=speed_error,
            surround=surround,
            fresnel=fresnel,
        )
    except ValidationError as err:
        e = err.errors()[0]
        if e["loc"] and e["loc"][0] == "illumination_profile":  # the file's values
            msg = e["msg"].removeprefix("Value error, ")
            fail(f"--illumination: illumination profile {source}: {msg}")
        name = {"illuminance_lux": "illuminance-lux", "exposure_ms": "exposure-ms"}.get(
            str(e["loc"][-1]), str(e["loc"][0]).replace("_", "-")
        )
        fail(f"--{name}: {e['msg']} (got {e.get('input')!r})")


def image_set_paths(output: Path) -> tuple[Path, Path, Path]:
    """The PNG, TIFF and JSON of an image set (a scan, a restoration); the name given with
    -o keeps its spelling; each checked as a writable -o."""
    png = output if output.suffix.lower() == ".png" else output.with_suffix(".png")
    tif = output if output.suffix.lower() != ".png" else output.with_suffix(".tif")
    sidecar = output.with_suffix(".json")
    for p in (png, tif, sidecar):
        check_output_path(p, "-o")
    return png, tif, sidecar


#: -o/--output of a command that writes an image set (PNG, TIFF and a JSON sidecar)
ImageSetOpt = Annotated[
    Path,
    typer.Option(
        "-o",
        "--output",
        help="output .png or .tif (the .png, .tif and .json beside it are written as a set)",
        callback=writable(".png", ".tif", ".tiff"),
    ),
]


@command()
def scan(
    image: ImageArg,
    output: ImageSetOpt,
    z: Annotated[
        float | None, typer.Option(help="float height (mm), 0 to 10", callback=number(0, 10))
    ] = None,
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
    illuminance_lux: Annotated[
        float | None,
        typer.Option(
            help="illuminance on the page (lux), 0.001 to 1e7; overrides the design's "
            "[electronics] illuminance_lux (default 10000)",
            callback=number(MIN_ILLUMINANCE_LUX, 1e7),
        ),
    ] = None,
    exposure_ms: Annotated[
        float | None,
        typer.Option(
            help="exposure per line (ms), (0, 10000]; overrides the design's [electronics] "
            "exposure_ms (default 1)",
            callback=number(0, 1e4, lo_open=True),
        ),
    ] = None,
    kernel: Annotated[
        str,
        typer.Option(
            help="auto (by --optics: wave kernels where the optics is wave, else paraxial "
            "or trace), paraxial, trace or wave (scalar diffraction)"
        ),
    ] = "auto",
    optics: OpticsOpt = "auto",
    speed_error: Annotated[
        float,
        typer.Option(
            help="relative scan-speed error, (-0.5, 0.5)",
            callback=number(-0.5, 0.5, lo_open=True, hi_open=True),
        ),
    ] = 0.0,
    surround: Annotated[
        float,
        typer.Option(
            help="reflectance outside the page, 0 to 1 (1: white, a page under the lid, as "
            "in the report; 0: an open lid)",
            callback=number(0, 1),
        ),
    ] = 1.0,
    fresnel: FresnelOpt = False,
    restore: Annotated[
        str | None,
        typer.Option(
            help="also restore the scan: wiener, rl or tv (written as NAME-restored.png, "
            ".tif, .json)"
        ),
    ] = None,
    as_json: JsonOpt = False,
) -> None:
    """Simulate the scanner's output for a document at a float height (paper Figs. 8, 9),
    with the design's illumination and sensor electronics (its [electronics] table)."""
    import json

    from ..imaging.scan import simulate_scan
    from ..io.files import encode_png, encode_tiff16, provenance, to_json, write_set
    from ..io.sidecar import relative_to_sidecar

    png, tif, sidecar = image_set_paths(output)
    if restore is not None:
        from ..imaging.restore import METHODS

        if restore not in METHODS:
            fail(f"--restore: must be one of {', '.join(METHODS)} (got {restore!r})")
        if color:
            fail("--restore: restoration takes a grey scan (not with --color)")
        restored_out = output.with_name(output.stem + "-restored" + output.suffix)
        image_set_paths(restored_out)
    d = open_design(design, kinds=BOTH_KINDS)
    if restore is not None:
        from .restore import check_stamp

        check_stamp(d, "--restore")
    kernel, said, chosen = _kernel_for(d, kernel, optics, fresnel)
    st = _settings(
        illumination,
        kernel,
        speed_error,
        surround,
        d.electronics,
        illuminance_lux,
        exposure_ms,
        fresnel,
    )
    doc, use = _document(image, dpi, color)
    hm = _height(height_map, z, doc.shape, use, seed)
    kernels = None
    try:
        if restore is not None:  # one kernel set for the scan and its restoration
            from ..imaging.scan import prepare_kernels

            kernels = prepare_kernels(
                d,
                z_mm=() if hm is not None else (z,),
                height_maps=() if hm is None else (hm,),
                settings=st,
                seed=seed,
                progress=True,
            )
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
            kernels=kernels,
        )
    except ValueError as err:
        fail(str(err))
    from ..imaging.kernels import kernel_source

    meta = provenance(d, seed) | {k: v for k, v in r.meta.items() if k != "settings"}
    meta |= {  # paths relative to the sidecar's folder, where restore looks for them
        "input": relative_to_sidecar(str(image), sidecar),
        "output_dpi": r.dpi,
        "settings": r.meta["settings"],
        "height_map_spec": relative_to_sidecar(height_map, sidecar),
        "design_source": relative_to_sidecar(design, sidecar),
        "kernel_used": kernel_source(d, kernel, fresnel),  # what auto meant here
    } | ({"optics": chosen} if chosen else {})
    write_set(
        {
            png: encode_png(r.image, r.dpi),
            tif: encode_tiff16(r.image, r.dpi, description=json.dumps(meta)),
        },
        sidecar,
        json.loads(to_json(meta)),
    )
    typer.echo(
        f"wrote {png} (8-bit sRGB), {tif} (16-bit linear) and {sidecar}: "
        f"{r.image.shape[1]} x {r.image.shape[0]} pixels at {r.dpi:.1f} dpi",
        err=True,
    )
    if restore is not None:
        from .restore import restore_and_write

        meta["restored"] = restore_and_write(
            r.image,
            r.dpi,
            d,
            z=z,
            hm=hm,
            method=restore,
            settings=st,
            seed=seed,
            kernels=kernels,
            output=restored_out,
            extra={"input": str(png), "design_source": design, "height_map_spec": height_map},
        )["restoration"]
    sg = r.meta["signal"]
    lines = said + [
        f"signal: {sg['electrons_white']:,.0f} e- at white (own path + the ghost light a white "
        f"page adds; {sg['full_well_fraction_white']:.0%} "
        f"of the full well), SNR {sg['snr_white']:.0f} at white, {sg['snr_grey18']:.0f} at 18 % "
        f"grey; SNR {sg['target_snr_white']:g} at white needs {sg['exposure_for_target_ms']:.3g} "
        f"ms per line (at most {sg['max_line_rate_for_target_hz']:,.0f} lines/s; the "
        "report's light section counts the own path alone, a longer exposure)"
    ]
    if sg["electrons_white"] == 0:  # a statement, not a row of zeros and infinities
        lines = said + [
            "signal: no light found reaching the pixels (0 e- at white): the scan shows only "
            "the sensor's dark signal and noise"
        ]
    if sg["saturated_white"]:
        lines.append(
            f"warning: white saturates the pixels (the scan clips); an exposure below "
            f"{sg['exposure_to_full_well_ms']:.3g} ms (--exposure-ms) or less light "
            "(--illuminance-lux, or the design's [electronics]) keeps it in range"
        )
    emit(json.loads(to_json(meta)), as_json, lines)


@command(traces=False)
def chart(
    kind: Annotated[str, typer.Argument(help="bars, edge, text or lines")],
    output: Annotated[
        Path, typer.Option("-o", "--output", help="output .png", callback=writable(".png"))
    ],
    dpi: Annotated[
        float, typer.Option(help="resolution of the chart, 100 to 4800", callback=number(100, 4800))
    ] = 1200.0,
    points: Annotated[
        float | None,
        typer.Option(
            help="text size (pt) of the text chart, 1 to 24 (default 8; 2.5 shows the "
            "prototype's depth of field)",
            callback=number(1, 24),
        ),
    ] = None,
    face: Annotated[
        str | None,
        typer.Option(help="type face of the text chart: sans (default) or serif (DejaVu Serif)"),
    ] = None,
    blocks: Annotated[
        str | None,
        typer.Option(
            help="the bar chart's blocks: chart resolutions in dpi, comma-separated (default "
            "100,150,200,247, the paper's; a 600-dpi design's depth-of-field chart is 400), "
            "each at most half of --dpi (two chart pixels a bar)"
        ),
    ] = None,
) -> None:
    """Write a built-in test chart (bar charts, slanted edge, text, fine lines); the text
    chart's ground truth goes beside it as .txt."""
    from ..imaging.charts import BAR_BLOCKS_DPI, KINDS, make_chart
    from ..io.files import write_atomic, write_png

    if kind not in KINDS:
        fail(f"KIND: must be one of {', '.join(KINDS)} (got {kind!r})")
    if kind != "text":
        for name, given in (("--points", points), ("--face", face)):
            if given is not None:
                fail(f"{name}: for the text chart only (got KIND {kind!r})")
    if kind != "bars" and blocks is not None:
        fail(f"--blocks: for the bar chart only (got KIND {kind!r})")
    bars = BAR_BLOCKS_DPI
    if blocks is not None:
        bars = parse_numbers(blocks, "--blocks", 10, 2400, max_count=12)
    if kind == "bars" and max(bars) > dpi / 2:
        name = "--blocks" if blocks is not None else "--dpi"
        fail(
            f"{name}: {max(bars):g}-dpi bars need a chart of at least {2 * max(bars):g} dpi "
            f"(two chart pixels a bar; got --dpi {dpi:g})"
            + ("" if blocks is not None else "; --blocks draws other blocks")
        )
    sizes, faces = _ocr_charts(f"{points if points is not None else 8.0:g}", face or "sans")
    if len(faces) != 1:
        fail(f"--face: one face for a chart (got {face!r})")
    img, text = make_chart(kind, dpi, sizes[0], faces[0], blocks=bars)
    write_png(output, img, dpi)
    if text is not None:
        write_atomic(output.with_suffix(".txt"), text + "\n")
    typer.echo(f"wrote {output} ({img.shape[1]} x {img.shape[0]} at {dpi:g} dpi)", err=True)


#: ocr-eval without IMAGE: the text sizes (pt) and faces of its built-in charts by default
#: (6 and 8 pt are read at every Z to 4.5 mm by the prototype; 2.5 pt shows its DOF).
OCR_POINTS = "2.5,6,8"
OCR_FACES = "sans,serif"
OCR_CHART_DPI = 1200.0


@command("ocr-eval")
def ocr_eval(
    image: Annotated[
        Path | None,
        typer.Argument(
            help="a text image (PNG, TIFF, JPEG), read against --text; without it, the "
            "built-in text charts of --points and --face are read"
        ),
    ] = None,
    text: Annotated[
        Path | None, typer.Option("--text", help="ground-truth text file of IMAGE")
    ] = None,
    points: Annotated[
        str | None,
        typer.Option(
            help="text sizes (pt) of the built-in charts, comma-separated, 1 to 24 "
            f"(default {OCR_POINTS}; not with IMAGE)"
        ),
    ] = None,
    face: Annotated[
        str | None,
        typer.Option(
            help="type faces of the built-in charts, comma-separated: sans (Pillow's "
            f"built-in font) or serif (DejaVu Serif) (default {OCR_FACES}; not with IMAGE)"
        ),
    ] = None,
    z: Annotated[
        str, typer.Option(help="float heights (mm), comma-separated, 0 to 10")
    ] = "0.5,1.5,2.5,3.5,4.5",
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    dpi: DpiOpt = None,
    noiseless: Annotated[bool, typer.Option("--noiseless", help="no sensor noise")] = False,
    optics: OpticsOpt = "auto",
    as_json: JsonOpt = False,
) -> None:
    """Scan text at each Z, read it with Tesseract, report the character error rate.

    Without IMAGE: the built-in text chart in each face and size (a table of CER per face,
    size and Z); 6- and 8-pt text is read at every Z up to 4.5 mm by the prototype, the
    2.5-pt sans text fails past its depth of field.
    """
    from ..imaging.charts import text_chart
    from ..imaging.ocr import OCRUnavailable, character_error_rate, recognise, require_tesseract
    from ..imaging.scan import ScanSettings, prepare_kernels, simulate_scan
    from ..io.files import linear_to_srgb, provenance

    d = open_design(design, kinds=BOTH_KINDS)
    # as `scan` scans it: the design's electronics, a white surround as in the report
    kernel, said, chosen = _kernel_for(d, "auto", optics, False)  # as scan's --kernel auto
    settings = ScanSettings(sensor=d.electronics, kernel=kernel)
    if image is None:
        for name, given in (("--text", text), ("--dpi", dpi)):
            if given is not None:
                fail(f"{name}: goes with IMAGE (without IMAGE the built-in text charts are read)")
        sizes, faces = _ocr_charts(points, face)
    else:
        for name, given in (("--points", points), ("--face", face)):
            if given is not None:
                fail(f"{name}: for the built-in text charts only (give no IMAGE)")
        if text is None:
            fail("--text: the ground-truth text file of IMAGE is required")
        try:
            truth = text.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as err:
            fail(f"--text: cannot read {text} ({err})")
        doc, use = _document(image, dpi, False, min_px=32)  # one 8-pt line at 600 dpi: ~65 px
    zs = float_list(z, "--z", 0.0, 10.0)
    try:
        require_tesseract()  # before the scans, not after the first
    except OCRUnavailable as err:
        fail(str(err))
    where = image if image is not None else f"design {design}"
    try:  # the kernels of every Z from one trace per pixel row
        kernels = prepare_kernels(d, z_mm=zs, seed=seed, settings=settings)
    except ValueError as err:
        fail(f"{where}: {err}")

    def read(doc, doc_dpi: float, truth: str) -> tuple[list[float], list[str]]:
        cer, got = [], []
        for zz in zs:
            try:
                r = simulate_scan(
                    doc,
                    doc_dpi,
                    d,
                    z_mm=zz,
                    seed=seed,
                    noiseless=noiseless,
                    settings=settings,
                    kernels=kernels,
                )
            except ValueError as err:
                fail(f"{where}: {err}")
            got.append(recognise(linear_to_srgb(r.image), r.dpi))
            cer.append(character_error_rate(truth, got[-1]))
        return cer, got

    if image is not None:
        cer, got = read(doc, use, truth)
        data = {"z_mm": list(zs), "cer": cer, "text": got, "provenance": provenance(d, seed)}
        data |= {"optics": chosen} if chosen else {}
        lines = said + [f"{image}: character error rate against {text}"]
        lines += [f"Z = {zz:g} mm: CER {c:.3f}" for zz, c in zip(zs, cer, strict=True)]
        emit(data, as_json, lines)
        return
    charts = []
    for f in faces:
        for p in sizes:
            chart, truth = text_chart(OCR_CHART_DPI, p, face=f)
            cer, got = read(chart, OCR_CHART_DPI, truth)
            charts.append({"face": f, "points": p, "cer": cer, "text": got})
    data = {
        "z_mm": list(zs),
        "chart_dpi": OCR_CHART_DPI,
        "charts": charts,
        "provenance": provenance(d, seed),
    } | ({"optics": chosen} if chosen else {})
    lines = said + [
        f"character error rate of the built-in text charts ({OCR_CHART_DPI:g} dpi) "
        f"scanned by design {design}, read by Tesseract",
        f"{'face':<6}{'points':>7}" + "".join(f"{f'Z {zz:g} mm':>10}" for zz in zs),
    ]
    lines += [
        f"{c['face']:<6}{c['points']:>7g}" + "".join(f"{v:>10.3f}" for v in c["cer"])
        for c in charts
    ]
    emit(data, as_json, lines)


def _ocr_charts(points: str | None, face: str | None) -> tuple[tuple[float, ...], tuple[str, ...]]:
    """The sizes and faces of ocr-eval's built-in charts (exit 2 naming the option)."""
    from ..imaging.charts import FACES, FontUnavailable, serif_font_path

    sizes = tuple(dict.fromkeys(float_list(points or OCR_POINTS, "--points", 1.0, 24.0)))
    spec = OCR_FACES if face is None else face
    names = [f.strip() for f in spec.split(",") if f.strip()]
    bad = [f for f in names if f not in FACES]
    if not names or bad:
        fail(
            f"--face: expected {' or '.join(FACES)}, comma-separated "
            f"(got {bad[0] if bad else spec!r})"
        )
    faces = tuple(dict.fromkeys(names))
    if "serif" in faces:
        try:
            serif_font_path()
        except FontUnavailable as err:
            fail(f"--face serif: {err}")
    return sizes, faces
