"""``restore``: a scan deconvolved with the scanner's own blur."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from ..units import pitch_of_dpi, um_to_mm
from .common import BOTH_KINDS, JsonOpt, command, emit, fail, number, open_design
from .metrics import ImageArg, LinearOpt, read_scan_image
from .scan import ImageSetOpt, image_set_paths

MethodOpt = Annotated[
    str,
    typer.Option(
        help="wiener (linear, the noise model's optimum for a 1/f^2 page), rl "
        "(Richardson-Lucy, 30 iterations) or tv (total variation, ADMM)"
    ),
]


def _sidecar(scan: Path) -> dict:
    """The scan's sidecar, its fields checked (io/sidecar.py; {} where there is none),
    with a warning naming both files where it records other images than ``scan``."""
    from ..imaging.heightmap import Z_RANGE_MM
    from ..io.sidecar import read_sidecar, sidecar_matches, sidecar_of

    side = read_sidecar(scan, z_range_mm=Z_RANGE_MM)
    if side is None:
        return {}
    if "restoration" not in side and sidecar_matches(scan, side) is False:
        typer.echo(
            f"warning: {sidecar_of(scan)} belongs to another image: it records "
            f"{', '.join(side['files'])} and {scan} is none of them (SHA-256); what it "
            "states (height, design, seed, settings) is used where the command line does "
            "not say otherwise (--z, --height-map, --design)",
            err=True,
        )
    return side


def check_stamp(d, option: str) -> None:
    """Restoration kernels exist for stamps only: refuse a rod-lens array up front."""
    from ..imaging.kinds import scanner_of

    why = scanner_of(d).not_restorable
    if why is not None:
        fail(
            f"{option}: {d.name} is a rod-lens array; restoration kernels are built for "
            f"aperture-array stamps ({why})"
        )


def restore_and_write(
    img: np.ndarray,
    dpi: float,
    d,
    *,
    z: float | None,
    hm: np.ndarray | None,
    method: str,
    settings,
    seed: int,
    output: Path,
    extra: dict,
    kernels=None,
) -> dict:
    """Restore ``img`` and write the set (PNG, 16-bit TIFF, JSON sidecar); its metadata.
    ``kernels``: the scan kernels built for ``img``'s scan (a KernelCache), not built
    again; None builds them."""
    from ..imaging.restore import restore_scan
    from ..io.files import encode_png, encode_tiff16, provenance, to_json, write_set
    from ..io.sidecar import relative_to_sidecar

    png, tif, sidecar = image_set_paths(output)
    extra = extra | {  # paths relative to the sidecar's folder
        k: relative_to_sidecar(extra[k], sidecar)
        for k in ("input", "design_source", "height_map_spec")
        if k in extra
    }
    try:
        r = restore_scan(
            img,
            d,
            z_mm=z,
            height_map=hm,
            method=method,
            settings=settings,
            seed=seed,
            kernels=kernels,
        )
    except ValueError as err:
        msg = str(err).replace("z_mm:", "--z:").replace("height_map:", "--height-map:")
        fail(msg.replace("design:", "--design:"))
    meta = provenance(d, seed) | {"restoration": r.meta, "output_dpi": dpi} | extra
    # overshoot past black or white by more than 5 % of white, clipped in the files
    meta["clipped_fraction"] = float(np.mean((r.image < -0.05) | (r.image > 1.05)))
    out = np.clip(r.image, 0.0, 1.0)
    write_set(
        {
            png: encode_png(out, dpi),
            tif: encode_tiff16(out, dpi, description=json.dumps(json.loads(to_json(meta)))),
        },
        sidecar,
        json.loads(to_json(meta)),
    )
    typer.echo(f"wrote {png} (8-bit sRGB), {tif} (16-bit linear) and {sidecar}", err=True)
    return meta


@command()
def restore(
    scan: ImageArg,
    output: ImageSetOpt,
    method: MethodOpt = "wiener",
    z: Annotated[
        float | None,
        typer.Option(
            help="float height (mm), 0 to 10 (default: the scan's sidecar)",
            callback=number(0, 10),
        ),
    ] = None,
    height_map: Annotated[
        str | None,
        typer.Option(help="height map: .npy/.tif in mm, or tilt/gutter/crumple (as for scan)"),
    ] = None,
    design: Annotated[
        str | None,
        typer.Option(
            "--design",
            "-d",
            help="preset name or design TOML file (default: the sidecar's, else paper2016)",
        ),
    ] = None,
    estimate_height: Annotated[
        bool,
        typer.Option(
            "--estimate-height",
            help="find the height from the scan itself (black-and-white pages; refused where "
            "the evidence is weak) instead of --z or the sidecar's",
        ),
    ] = False,
    linear: LinearOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Restore a scan by deconvolving it with the scanner's own blur at its height (a known
    height: --z, a height map, or the scan's sidecar from `scan`)."""
    from pydantic import ValidationError

    from ..imaging.heightmap import HeightMapError, load_height_map
    from ..imaging.restore import METHODS
    from ..imaging.scan import ScanSettings

    if method not in METHODS:
        fail(f"--method: must be one of {', '.join(METHODS)} (got {method!r})")
    inputs = {scan.resolve(), scan.with_suffix(".json").resolve()}
    if any(p.resolve() in inputs for p in image_set_paths(output)):
        fail(f"-o: {output} would overwrite the scan {scan} or its sidecar; choose another name")
    side = _sidecar(scan)
    if "restoration" in side:
        side = {}  # a restoration's sidecar: it states no scan to restore (see below)
        restored_before = True
    else:
        restored_before = False
    if side.get("color"):
        fail(f"{scan}: a colour scan (its sidecar says so); restoration takes a grey scan")
    img, dpi = read_scan_image(scan, None, linear, min_px=4)
    if img.ndim != 2:
        fail(f"{scan}: restoration takes a grey scan (got {img.shape[2]} channels)")
    spec = design or side.get("design_source") or side.get("design") or "paper2016"
    d = open_design(spec, kinds=BOTH_KINDS)
    check_stamp(d, "--design")
    if design is None and side.get("design_fingerprint") not in (None, d.fingerprint()):
        fail(
            f"--design: {spec} is not the design the scan was made with (fingerprint "
            f"{side.get('design_fingerprint')}); give --design"
        )
    seed = side.get("seed") or 0  # checked: an integer in [0, 2^63 - 1]
    try:
        st = ScanSettings.model_validate(side["settings"]) if "settings" in side else None
    except ValidationError as err:
        fail(f"{scan.with_suffix('.json')}: settings: {err.errors()[0]['msg']}")
    if st is None:
        st = ScanSettings(sensor=d.electronics)
    hm = None
    estimate = None
    if estimate_height:
        from ..imaging.restore import estimate_height as find_height

        if z is not None or height_map is not None:
            fail("--estimate-height: not with --z or --height-map")
        if side.get("height_map"):
            fail(
                "--estimate-height: the scan was made over a height map (one height cannot "
                "stand for it); give --height-map, or none to use the sidecar's"
            )
        try:
            est = find_height(img, d, settings=st, seed=seed)
        except ValueError as err:
            fail(f"{scan}: {err}")
        if est.refused:
            fail(f"--estimate-height: {est.refused}; give --z")
        z = est.z_mm
        estimate = {"z_mm": est.z_mm, "contrast": est.contrast}
    elif height_map is None and z is None:
        if side.get("height_map"):
            height_map = side.get("height_map_spec")
            if height_map is None:
                fail("--height-map: the scan was made over a height map; give it")
        else:
            z = side.get("z_mm")
            if z is None:
                why = (
                    "its sidecar is a restoration's, which states no scan height"
                    if restored_before
                    else "the scan has no sidecar stating it"
                )
                fail(f"--z: the float height is needed ({why}; or --estimate-height)")
    elif height_map is not None and z is not None:
        fail("--height-map: not with --z (give one of them)")
    if height_map is not None:
        p = pitch_of_dpi(dpi)
        try:
            hm = load_height_map(
                height_map, um_to_mm(img.shape[0] * p), um_to_mm(img.shape[1] * p), seed
            )
        except HeightMapError as err:
            fail(str(err))
    extra = {
        "input": str(scan),
        "design_source": spec,
        "height_map_spec": height_map,
        "height_estimate": estimate,
    }
    meta = restore_and_write(
        img, dpi, d, z=z, hm=hm, method=method, settings=st, seed=seed, output=output, extra=extra
    )
    r = meta["restoration"]
    lines = [
        f"restored {scan} ({method}) at "
        + (
            f"Z = {z:.2f} mm" + (" (estimated from the scan)" if estimate else "")
            if hm is None
            else f"heights {r['levels_mm'][0]:g}-{r['levels_mm'][-1]:g} mm"
        )
        + f" with design {d.name}, regularised for the scan's noise of {r['sigma']:.4f} per "
        f"pixel (sensor at mid-grey and model error {r['model_error']:g}); "
        f"{meta['clipped_fraction']:.1%} of the restored pixels overshoot white or black by "
        "more than 5 % (clipped in the files)"
    ]
    emit(meta, as_json, lines)
