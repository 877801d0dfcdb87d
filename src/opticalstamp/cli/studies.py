"""Commands of the design studies: search, tolerance."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..defaults import (
    SEARCH_BUDGET_MM,
    SEARCH_GENERATIONS,
    SEARCH_NEAR_MM,
    SEARCH_POPULATION,
    TOLERANCE_SAMPLES,
    TOLERANCE_SIGMAS,
)
from ..validate import check_number
from .common import (
    BOTH_KINDS,
    DesignOpt,
    FresnelOpt,
    JsonOpt,
    PlotOpt,
    SeedOpt,
    command,
    emit,
    fail,
    float_list,
    number,
    open_design,
    save_plot,
    writable,
)
from .optics import OpticsOpt, optics_line

DaskOpt = Annotated[
    str | None, typer.Option("--dask", help="Dask scheduler address, tcp://HOST:PORT")
]
WorkersOpt = Annotated[
    int | None,
    typer.Option(
        "--workers",
        help="local worker processes, 1 to 1024 (default: all cores)",
        callback=number(1, 1024, integer=True),
    ),
]
OutputOpt = Annotated[
    Path | None,
    typer.Option("-o", "--output", help="results .nc", callback=writable(".nc")),
]
_DPI = number(50, 2400)


def _check_dask(address: str | None) -> None:
    if address is not None and not address.startswith(("tcp://", "tls://", "inproc://")):
        fail(f"--dask: expected tcp://HOST:PORT (got {address!r})")


def _layer_counts(value: str | None) -> tuple[int, ...] | None:
    if value is None:
        return None
    try:
        counts = tuple(int(v) for v in value.split(","))
    except ValueError:
        msg = f"expected comma-separated integers such as 2,3 (got {value!r})"
        raise typer.BadParameter(msg) from None
    if any(not 1 <= n <= 16 for n in counts):
        raise typer.BadParameter(f"numbers of layers must lie in [1, 16] (got {value!r})")
    return counts


def _staggers(value: str | None) -> tuple[str, ...] | None:
    if value is None:
        return None
    styles = tuple(v.strip() for v in value.split(","))
    if any(v not in ("yes", "no") for v in styles):
        raise typer.BadParameter(f"expected yes, no or yes,no (got {value!r})")
    return styles


def _pins(text: str | None) -> dict:
    if not text:
        return {}
    out = {}
    for part in text.split(","):
        k, _, v = part.partition("=")
        try:
            out[k.strip()] = float(v)
        except ValueError:
            fail(f"--pin: expected NAME=VALUE pairs such as hole1=48,slab1=1000 (got {part!r})")
        check_number(out[k.strip()], f"--pin {part.strip()}")
    return out


EstimatorOpt = Annotated[
    str,
    typer.Option(
        help="surrogate (closed form with a uniform ghost background, fast) or trace "
        "(every design traced exactly: ghosts, light, RMTF, depth of field; on the GPU "
        "with --device cuda)"
    ),
]


def _check_estimator(name: str) -> None:
    from ..studies.verify import check_estimator

    try:
        check_estimator(name)
    except ValueError as err:
        fail(f"--{err}")


@command()
def search(
    dpi: Annotated[
        float | None,
        typer.Option(
            help="rescale the design to this resolution of the merged line (dpi), 50 to "
            "2400 [default: the design's own; a design is rescaled only when asked]",
            callback=_DPI,
            show_default=False,
        ),
    ] = None,
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    dof_dpi: Annotated[
        float | None,
        typer.Option(
            help="chart dpi of the depth of field, 50 to 2400 [default: 2/3 of the searched "
            "resolution: 200 for 300 dpi, 400 for 600]",
            callback=_DPI,
            show_default=False,
        ),
    ] = None,
    budget_mm: Annotated[
        float,
        typer.Option(help="total stack thickness budget (mm), 0.2 to 20", callback=number(0.2, 20)),
    ] = SEARCH_BUDGET_MM,
    near_mm: Annotated[
        float,
        typer.Option(
            help="no ghost light within this distance (mm), 0 to 100", callback=number(0, 100)
        ),
    ] = SEARCH_NEAR_MM,
    max_ghost: Annotated[
        float | None,
        typer.Option(help="bound on the ghost fraction, 0 to 1", callback=number(0, 1)),
    ] = None,
    population: Annotated[
        int,
        typer.Option(
            help="designs per generation, 4 to 1000", callback=number(4, 1000, integer=True)
        ),
    ] = SEARCH_POPULATION,
    generations: Annotated[
        int,
        typer.Option(help="NSGA-II generations, 1 to 1000", callback=number(1, 1000, integer=True)),
    ] = SEARCH_GENERATIONS,
    pin: Annotated[
        str | None,
        typer.Option(
            help="fixed variables, numbered from the object side: hole1 (layer 1's hole), "
            "slab1 (the slab under layer 1), ...; e.g. hole1=48,slab1=1000"
        ),
    ] = None,
    layers: Annotated[
        str | None,
        typer.Option(
            help="also search other numbers of mask layers, e.g. 2,3", callback=_layer_counts
        ),
    ] = None,
    stagger: Annotated[
        str | None,
        typer.Option(help="stagger patterns to search: yes, no or yes,no", callback=_staggers),
    ] = None,
    workers: WorkersOpt = None,
    dask: DaskOpt = None,
    output: OutputOpt = None,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
    verify: Annotated[
        bool,
        typer.Option(
            "--verify/--no-verify",
            help="re-verify the front and the base design with the exact tracer (the "
            "figures of record; points where the surrogate is off beyond its stated "
            "accuracy are flagged)",
        ),
    ] = True,
    estimator: EstimatorOpt = "surrogate",
    optics: OpticsOpt = "auto",
    objective: Annotated[
        str,
        typer.Option(
            help="the depth maximised with the light: dof (the depth of field) or "
            "restored-dof (after Wiener restoration with the known blur, closed form)"
        ),
    ] = "dof",
    export_designs: Annotated[
        Path | None,
        typer.Option(
            "--export-designs",
            help="folder to write every Pareto point into as a design file (STEM-pNN.toml, "
            "STEM the base design's name without spaces: paper2016-p01.toml, "
            "paper2016-600dpi-p01.toml at --dpi 600; with its provenance) and front.json "
            "(replaced as a whole)",
            callback=writable(directory=True, marker="front.json"),
        ),
    ] = None,
) -> None:
    """Search hole sizes and gaps for ghost-free, bright, deep designs (paper §3)."""
    from ..io.files import provenance, save_dataset
    from ..studies.search import (
        OBJECTIVES,
        journal_of,
        merged_front,
        search_base,
        search_dataset,
        search_variants,
        variant_path,
        verify_front,
    )
    from ..studies.searchspace import rejection_text, rejections
    from ..studies.waveestimate import optics_used_text

    if objective not in OBJECTIVES:
        fail(f"--objective: must be one of {', '.join(OBJECTIVES)} (got {objective!r})")
    _check_estimator(estimator)
    _check_dask(dask)
    d = open_design(design)
    base = search_base(d, dpi)
    try:
        results = search_variants(
            d,
            dpi=dpi,
            layers=layers,
            stagger=stagger,
            results_path=output,
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
            progress=not as_json,
            objective=objective,
            estimator=estimator,
            optics=optics,
        )
        if verify:
            results = {
                name: verify_front(
                    res,
                    workers=workers,
                    dask_address=dask,
                    journal=journal_of(variant_path(output, i, len(results))),
                    progress=not as_json,
                )
                for i, (name, res) in enumerate(results.items())
            }
    except (ValueError, OSError) as err:
        fail(str(err))
    if output is not None:
        for i, res in enumerate(results.values()):
            save_dataset(
                search_dataset(res, res.design, seed), variant_path(output, i, len(results))
            )
    from ..design.resolution import nominal_dpi

    r = next(iter(results.values()))
    data = r.to_dict() | {"provenance": provenance(base, seed)}
    if len(results) > 1:
        data["pareto"] = merged_front(results)
        data["variants"] = {k: v.to_dict() for k, v in results.items()}
    lines = [
        f"{base.name} ({nominal_dpi(base):g} dpi): "
        f"{sum(len(v.records) for v in results.values())} designs in "
        f"{len(results)} variant(s); depth of field on the {r.meta['dof_dpi']:g}-dpi chart "
        "(RMTF ≥ 0.3); Pareto front (holes and slabs in µm, object side first)"
        + (
            "; every design traced exactly (--estimator trace):"
            if estimator == "trace"
            else "; figures of record from the exact tracer or, for designs judged by wave "
            "optics, the exact wave figures; the estimate's in brackets:"
            if verify
            else "; figures from the surrogate (--no-verify):"
        )
    ]
    lines.append("  " + optics_used_text(results))
    if not data["pareto"]:
        recs = [x for v in results.values() for x in v.records]
        counts = rejections(recs, budget_mm * 1000.0, max_ghost)
        data["rejected_by"] = counts
        lines.append(
            "  "
            + rejection_text(
                counts, len(recs), near_mm=near_mm, budget_mm=budget_mm, max_ghost=max_ghost
            )
        )
    for i, p in enumerate(data["pareto"], start=1):
        tag = f" [{p['variant']}]" if "variant" in p else ""
        s = p.get("surrogate")
        was = (
            ""
            if not s
            else f" (1/{1 / s['efficiency_ratio']:.0f}, {s['dof_mm']:.2f} mm, "
            f"{s['ghost_fraction']:.3f})"
        )
        flag = ""
        if p.get("disagrees"):
            flag += f"  ! surrogate off in {', '.join(p['disagrees'])}"
        if p.get("exact_dominated_by"):
            flag += f"  ! dominated by {p['exact_dominated_by']} front point(s) when exact"
        restored = (
            f", restored DOF {p['restored_dof_mm']:.2f} mm"
            if objective == "restored-dof" and p.get("restored_dof_mm") is not None
            else ""
        )
        lines.append(
            f"  p{i:02d} holes {_nums(p['holes_um'])} slabs {_nums(p['thicknesses_um'])}: "
            f"efficiency 1/{1 / p['efficiency_ratio']:.0f}, DOF {p['dof_mm']:.2f} mm"
            f"{restored}, ghosts {p['ghost_fraction']:.3f}{was}{tag}{flag}"
        )
    for name, res in results.items():
        ref = res.reference
        if ref:
            lines.append(
                f"base {name}: efficiency 1/{1 / ref['efficiency_ratio']:.0f}, DOF "
                f"{ref['dof_mm']:.2f} mm, ghosts {ref['ghost_fraction']:.3f}, dominated by "
                f"{ref.get('dominated_by', 0)} of its variant's designs"
            )
    if export_designs is not None:
        _export(results, data["pareto"], export_designs)
        lines.append(f"wrote {len(data['pareto'])} design files and front.json to {export_designs}")
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_pareto, plot_pareto_variants

        save_plot(plot_pareto(r) if len(results) == 1 else plot_pareto_variants(results), plot)


def _nums(values) -> str:
    """[48.0, 40.0] -> "48/40"."""
    return "/".join(f"{v:g}" for v in values)


def _export(results: dict, front: list[dict], folder: Path) -> None:
    """Every point of ``front`` as a design file, and front.json listing them; the folder
    is written as a whole or not at all."""
    from ..design import design_toml
    from ..io.atomic import replace_folder
    from ..io.files import to_json, write_atomic
    from ..studies.search import front_designs

    points = front_designs(results, front)
    with replace_folder(folder) as tmp:
        index = []
        for p in points:
            file = p["file"]  # a stem without spaces: STEM-pNN.toml
            write_atomic(tmp / file, design_toml(p["design"], tuple(p["provenance"])))
            index.append(
                {
                    "file": file,
                    "fingerprint": p["design"].fingerprint(),
                    "provenance": p["provenance"],
                }
                | p["row"]
            )
        write_atomic(tmp / "front.json", to_json({"points": index}))


@command()
def tolerance(
    design: DesignOpt = "paper2016",
    seed: SeedOpt = 0,
    misregistration_um: Annotated[
        float,
        typer.Option(help="sigma of x/y misregistration (µm), 0 to 100", callback=number(0, 100)),
    ] = TOLERANCE_SIGMAS["misregistration_um"],
    hole_um: Annotated[
        float, typer.Option(help="sigma of the hole sizes (µm), 0 to 100", callback=number(0, 100))
    ] = TOLERANCE_SIGMAS["hole_um"],
    thickness_um: Annotated[
        float,
        typer.Option(help="sigma of plates and gaps (µm), 0 to 1000", callback=number(0, 1000)),
    ] = TOLERANCE_SIGMAS["thickness_um"],
    tilt_deg: Annotated[
        float, typer.Option(help="sigma of the stack tilt (°), 0 to 5", callback=number(0, 5))
    ] = TOLERANCE_SIGMAS["tilt_deg"],
    samples: Annotated[
        int,
        typer.Option(help="Monte Carlo samples, 1 to 1e6", callback=number(1, 1e6, integer=True)),
    ] = TOLERANCE_SAMPLES,
    dpi: Annotated[
        float | None,
        typer.Option(
            help="chart dpi of the RMTF and the depth of field, 50 to 2400 [default: 2/3 of "
            "the design's resolution: 200 for 300 dpi, 400 for 600]",
            callback=_DPI,
            show_default=False,
        ),
    ] = None,
    z: Annotated[str, typer.Option(help="distances of the RMTF (mm)")] = "0.5,1,2,3,3.5",
    spec: Annotated[
        str | None,
        typer.Option(
            help="what a good part must meet, for the yield: FIGURE>=NUMBER or "
            "FIGURE<=NUMBER, comma-separated, e.g. dof>=2.2,ghost<=0.2,rmtf@2>=0.35. "
            "Figures and their units: dof (mm: depth of field at --dpi), ghost (a fraction "
            "0 to 1: the ghost light's share of the pixel's light), ghost_radius (mm: the "
            "nearest ghost light on the object plane), efficiency (own-path light as a "
            "ratio to the paper's F/10 reference lens; the paper: 1/36 = 0.028), rmtf@Z "
            "(RMTF at --dpi, 0 to 1, at Z mm; Z one of --z)"
        ),
    ] = None,
    estimator: EstimatorOpt = "surrogate",
    optics: OpticsOpt = "auto",
    workers: WorkersOpt = None,
    dask: DaskOpt = None,
    output: OutputOpt = None,
    as_json: JsonOpt = False,
    plot: PlotOpt = None,
) -> None:
    """Monte Carlo of assembly errors: RMTF, DOF, efficiency, ghosts, sensitivity, yield.
    The optics is chosen once, for the nominal design, and every sample follows it."""
    from ..analysis.responsivity import resolve_optics
    from ..io.files import provenance, save_dataset
    from ..studies.search import journal_of
    from ..studies.tolerance import parse_spec, tolerance_dataset
    from ..studies.tolerance import tolerance as run
    from ..studies.waveestimate import wave_estimator_text

    _check_estimator(estimator)
    _check_dask(dask)
    d = open_design(design)
    try:  # once, for the nominal design; a bad or impossible optics before any work
        opt = resolve_optics(d, optics)
    except ValueError as err:
        fail(f"--{err}")
    zs = float_list(z, "--z", 0.0, 10.0)
    try:
        parse_spec(spec, zs)
    except ValueError as err:
        fail(f"--spec: {str(err).removeprefix('spec: ')}")
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
            journal=journal_of(output),
            progress=not as_json,
            estimator=estimator,
            optics=opt,
        )
    except (ValueError, OSError) as err:
        fail(str(err))
    data = r.to_dict() | {"provenance": provenance(d, seed)}
    if output is not None:
        save_dataset(tolerance_dataset(r, d), output)
    dpi = r.dpi
    key = f"rmtf{dpi:g}"
    wave = opt.engine == "wave"
    lines = [
        f"{d.name}: {samples} samples ({data['n_failed']} failed)",
        "  "
        + optics_line(r.meta["optics"])
        + "; every sample by the same optics"
        + (f" (the search's {wave_estimator_text()})" if wave and estimator == "surrogate" else ""),
    ]
    for zz, pc in data[key].items():
        lines.append(
            f"  RMTF {dpi:g} dpi at Z = {zz} mm: median {pc['p50']:.3f} "
            f"(5-95 %: {pc['p5']:.3f}-{pc['p95']:.3f}), nominal "
            f"{r.nominal['rmtf_at'][zz]:.3f}"
        )
    dp = data["dof_mm"]
    lines.append(
        f"  DOF median {dp['p50']:.2f} mm (5-95 %: {dp['p5']:.2f}-{dp['p95']:.2f}), "
        f"nominal {r.nominal['dof_mm']:.2f} " + _estimator_tag(estimator, wave)
    )
    ex = r.meta.get("nominal_exact")
    if ex:
        off = r.meta["nominal_disagrees"]
        est = "wave estimator" if wave else "surrogate"
        lines.append(
            f"  nominal by the {'exact wave figures' if wave else 'exact tracer'} (figure of "
            f"record): DOF {ex['dof_mm']:.2f} mm, efficiency 1/{1 / ex['efficiency_ratio']:.0f}"
            f", ghosts {ex['ghost_fraction']:.3f}"
            + (
                f"; the {est} is off beyond its stated accuracy in {', '.join(off)}"
                if off
                else f"; the {est} agrees within its stated accuracy"
            )
        )
    lines.append(
        "  most sensitive: "
        + ", ".join(
            f"{row['error']} ({row['d_dof_mm']:.3f} mm DOF per sigma)" for row in r.sensitivity[:5]
        )
    )
    if r.yield_fraction is not None:
        lines.append(f"  yield for {spec}: {r.yield_fraction:.1%}")
    emit(data, as_json, lines)
    if plot:
        from ..report.plotting import plot_tolerance

        save_plot(plot_tolerance(r), plot)


def _estimator_tag(estimator: str, wave: bool) -> str:
    """What the samples' figures come from, in brackets."""
    if estimator == "trace":
        return "(exact wave figures)" if wave else "(exact tracer)"
    return "(wave estimator)" if wave else "(surrogate)"


@command()
def compare(
    designs: Annotated[
        list[str],
        typer.Argument(help="two or more presets or design files, stamps or rod-lens arrays"),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            help="output folder (replaced as a whole): index.html, compare.json, PNGs",
            callback=writable(directory=True, marker="compare.json"),
        ),
    ] = Path("compare"),
    seed: SeedOpt = 0,
    fresnel: FresnelOpt = False,
    optics: OpticsOpt = "auto",
    as_json: JsonOpt = False,
) -> None:
    """Designs side by side: light vs F/10, working F-number, thickness, depth of field on
    one chart (the first design's, 2/3 of its resolution: 200 dpi for 300), ghost
    fraction, and contrast vs height on one axis (paper §4: the stamp has ~1/100 of a
    rod-lens array's light; a rod-lens scanner is ≥ 15 mm thick). Each stamp's figures
    by ``--optics`` (auto: each by its own validity rule; the row says which)."""
    from ..report.compare import wave_cells, write_comparison

    if len(designs) < 2:
        fail("compare: give at least two designs")
    ds = [open_design(s, kinds=BOTH_KINDS) for s in designs]
    rows = write_comparison(ds, out, seed=seed, fresnel=fresnel, optics=optics)
    dof_head = f"DOF{rows[0]['dof_dpi']:g} mm (low..high)"
    lines = [
        f"{'design':<22} {'kind':<15} {'light/F10':>10} {'vs first':>9} {'F_w':>6} "
        f"{'thick mm':>8} {dof_head:>22} {'ghost':>6}"
    ]
    for r in rows:
        lines.append(
            f"{r['name']:<22} {r['kind']:<15} {r['light_vs_f10']:>10.4g} "
            f"{r['light_vs_first']:>9.3g} {r['working_f_number']:>6.1f} "
            f"{r['thickness_mm']:>8.2f} {r['dof_mm'][0]:>10.2f} .. {r['dof_mm'][1]:<9.2f} "
            f"{r['ghost_fraction']:>6.3f}"
        )
    for r in rows:
        if r.get("optics"):
            lines.append(f"  {r['name']:<22} {optics_line(r['optics'])}")
    lines.append(
        f"ray vs wave optics (own path and near crosstalk, {rows[0]['dof_dpi']:g}-dpi chart):"
    )
    for r in rows:
        fres, ratio, dof, holds = wave_cells(r)
        lines.append(
            f"  {r['name']:<22} Fresnel min {fres:>5}  light wave/ray {ratio:>6}  "
            f"DOF wave/ray {dof} mm  {holds}"
            if dof != "-"
            else f"  {r['name']:<22} Fresnel min {fres:>5}  {ratio}"
        )
    lines.append(f"wrote {out / 'index.html'} and {out / 'compare.json'}")
    emit({"designs": rows}, as_json, lines)
