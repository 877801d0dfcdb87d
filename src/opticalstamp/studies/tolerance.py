"""Assembly and manufacturing tolerancing (paper §5: "misalignment ... at least 3 um").

Error sources, each Gaussian with its own sigma, drawn per sample from a generator keyed
by (seed, sample index) so that results do not depend on workers or order:

- x and y misregistration of each mask against the sensor (default 3 um);
- hole size of each mask (default 1 um);
- thickness of each slab, plates and air gaps (default 10 um);
- a tilt of the stack about the y axis (default 0.02 deg), taken at the end of the
  array, where it changes the air gap by (half the array length) x tan(tilt).

Each sample is evaluated like a search candidate (:mod:`evaluate`): RMTF at the chosen
dpi and distances, depth of field, light efficiency, ghost fraction. The optics (ray,
wave or auto) is resolved once, for the nominal design, and every sample is evaluated by
that engine: by wave optics with the search's wave estimator
(:func:`~opticalstamp.studies.waveestimate.evaluate_wave`), its nominal verified with the
exact wave figures. A one-at-a-time
sensitivity table (each error at +-1 sigma alone) ranks the sources; the yield is the
fraction of samples that meet a specification such as ``dof>=2.2,ghost<=0.2``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..analysis.responsivity import Optics, resolve_optics
from ..defaults import TOLERANCE_SAMPLES, TOLERANCE_SIGMAS
from ..design import Design, design_from_dict, stack_params, with_stack
from ..design.resolution import dof_chart_dpi
from ..device import run_device, using_device
from ..raytrace.stack import lattice_of
from ..validate import check_seed
from .evaluate import check_figures
from .runner import run_tasks, task_key
from .verify import ESTIMATORS, check_estimator, disagreements, evaluate_with, exact_figures
from .waveestimate import EXACT_WAVE, WAVE_ESTIMATE, exact_wave_figures, wave_disagreements

DEFAULT_SIGMAS = TOLERANCE_SIGMAS
SPEC_RE = re.compile(r"^(dof|ghost_radius|ghost|efficiency|rmtf@[0-9.]+)(>=|<=)(-?[0-9.]+)$")


def error_names(design: Design) -> list[str]:
    n_m, n_s = len(design.masks), len(design.slabs)
    """The errors' names, layers and slabs numbered from the object side (``dx1``: layer
    1's x misregistration; ``slab1``: the thickness of the object side's slab). The slabs
    come sensor first in this list (the order of the random draws, unchanged)."""
    names = [f"dx{i + 1}" for i in range(n_m)] + [f"dy{i + 1}" for i in range(n_m)]
    names += [f"hole{i + 1}" for i in range(n_m)] + [f"slab{n_s - j}" for j in range(n_s)]
    return names + ["tilt"]


def _sigma_vector(design: Design, sigmas: dict) -> np.ndarray:
    n_m, n_s = len(design.masks), len(design.slabs)
    return np.array(
        [sigmas["misregistration_um"]] * (2 * n_m)
        + [sigmas["hole_um"]] * n_m
        + [sigmas["thickness_um"]] * n_s
        + [sigmas["tilt_deg"]]
    )


def draw_errors(design: Design, index: int, seed: int, sigmas: dict) -> dict:
    """The errors of sample ``index`` (a dict by error name)."""
    rng = np.random.default_rng([seed, index, 31])
    v = rng.standard_normal(len(error_names(design))) * _sigma_vector(design, sigmas)
    return dict(zip(error_names(design), v.tolist(), strict=True))


def apply_errors(design: Design, errors: dict) -> Design:
    """The design built with the given errors (names of :func:`error_names`; the tilt
    lengthens the sensor's slab at the array's end). Misregistration errors add to the
    design's own mask offsets."""
    p = stack_params(design)  # object side first
    holes = [max(1.0, h + errors.get(f"hole{i + 1}", 0.0)) for i, h in enumerate(p["holes_um"])]
    ts = [max(1.0, t + errors.get(f"slab{j + 1}", 0.0)) for j, t in enumerate(p["thicknesses_um"])]
    lat = lattice_of(design)
    half_len = max(abs(lat.k_lo), abs(lat.k_hi)) * lat.pitch
    ts[-1] = max(1.0, ts[-1] + half_len * math.tan(math.radians(errors.get("tilt", 0.0))))
    offs = [
        (dx + errors.get(f"dx{i + 1}", 0.0), dy + errors.get(f"dy{i + 1}", 0.0))
        for i, (dx, dy) in enumerate(p["offsets_um"])
    ]
    return with_stack(design, holes_um=holes, thicknesses_um=ts, offsets_um=offs)


def _evaluate_payload(payload: dict) -> dict:
    """Worker entry: one sample's figures, its rays on the payload's device."""
    base = design_from_dict(payload["base"], "tolerance base")
    with using_device(payload.get("device", "cpu")):
        return evaluate_with(apply_errors(base, payload["errors"]), payload["options"])


def parse_spec(text: str | None, z_mm=None) -> list[tuple[str, str, float]]:
    """'dof>=2.2,ghost<=0.2,rmtf@2>=0.3,efficiency>=0.03,ghost_radius>=5' -> [(metric, op,
    value)]: depth of field (mm), ghost fraction, own light vs the F/10 lens, RMTF at Z mm,
    nearest ghost light on the object plane (mm). ``z_mm``: the distances of the RMTF; an
    rmtf@Z at another distance is refused."""
    if not text:
        return []
    out = []
    for part in text.replace(" ", "").split(","):
        m = SPEC_RE.match(part)
        try:  # "rmtf@1.2.3" and "dof>=..." match the pattern but are no numbers
            value = float(m.group(3)) if m else None
            z = float(m.group(1).split("@")[1]) if m and "@" in m.group(1) else None
        except ValueError:
            value = None
        if value is None:
            raise ValueError(
                f"spec: cannot read {part!r} (use dof, ghost, ghost_radius, efficiency or "
                "rmtf@Z with >= or <= and a number, comma-separated)"
            )
        zs = None if z_mm is None else [f"{float(v):g}" for v in z_mm]
        if z is not None and zs is not None and f"{z:g}" not in zs:
            raise ValueError(
                f"spec: {m.group(1)} asks for the RMTF at Z = {z:g} mm, not one of the "
                f"distances of the RMTF ({', '.join(zs)} mm)"
            )
        out.append((m.group(1), m.group(2), value))
    return out


def _metric(res: dict, name: str) -> float:
    if name == "dof":
        return res["dof_mm"]
    if name == "ghost":
        return res["ghost_fraction"]
    if name == "ghost_radius":  # mm; infinite where no ghost light lands at all
        near = res["nearest_ghost_mm"]
        return math.inf if near is None else near  # a journal writes infinity as null
    if name == "efficiency":
        return res["efficiency_ratio"]
    z = float(name.split("@")[1])
    return res["rmtf_at"][f"{z:g}"]


def meets(res: dict, spec) -> bool:
    return all(
        (_metric(res, m) >= v) if op == ">=" else (_metric(res, m) <= v) for m, op, v in spec
    )


@dataclass(frozen=True)
class ToleranceResult:
    design: str
    seed: int
    sigmas: dict
    dpi: float
    z_mm: list[float]
    nominal: dict
    errors: list[dict]
    samples: list[dict | None]  # evaluation per sample (None: failed, see failures)
    failures: list[dict]
    sensitivity: list[dict]
    spec: str
    yield_fraction: float | None
    meta: dict = field(default_factory=dict)

    def percentiles(self, q=(5, 25, 50, 75, 95)) -> dict:
        ok = [s for s in self.samples if s is not None]
        out = {"rmtf": {}, "dof_mm": {}, "efficiency_ratio": {}, "ghost_fraction": {}}
        for z in self.z_mm:
            v = np.array([s["rmtf_at"][f"{z:g}"] for s in ok])
            out["rmtf"][f"{z:g}"] = dict(
                zip([f"p{x}" for x in q], np.percentile(v, q).tolist(), strict=True)
            )
        for k in ("dof_mm", "efficiency_ratio", "ghost_fraction"):
            v = np.array([s[k] for s in ok])
            out[k] = dict(zip([f"p{x}" for x in q], np.percentile(v, q).tolist(), strict=True))
        return out

    def to_dict(self) -> dict:
        pct = self.percentiles()
        return {
            "design": self.design,
            "seed": self.seed,
            "sigmas": self.sigmas,
            "dpi": self.dpi,
            "z_mm": self.z_mm,
            "nominal": self.nominal,
            f"rmtf{self.dpi:g}": pct["rmtf"],
            "dof_mm": pct["dof_mm"],
            "efficiency_ratio": pct["efficiency_ratio"],
            "ghost_fraction": pct["ghost_fraction"],
            "sensitivity": self.sensitivity,
            "spec": self.spec,
            "yield": self.yield_fraction,
            "n_samples": len(self.samples),
            "n_failed": len(self.failures),
            "failures": self.failures,
            "meta": self.meta,
        }

    def to_dataset(self):
        """The study as an xarray Dataset on the coordinates ``sample``, ``error`` and
        ``z_mm`` (and the scalar coordinate ``dpi`` of the RMTF).

        Per sample: ``errors`` (sample, error), the drawn errors; ``ok`` (1 where the
        evaluation succeeded); ``rmtf`` (sample, z_mm), ``dof_mm``, ``efficiency_ratio``,
        ``efficiency_ratio_total``, ``ghost_fraction``, ``etendue_own_um2sr``,
        ``etendue_ghost_um2sr``, ``nearest_ghost_mm`` (NaN where the evaluation failed).
        The nominal design's values as ``nominal_*``. The sensitivity table (each error at
        +-1 sigma alone, mean absolute change) as ``sigma``, ``d_dof_mm``,
        ``d_efficiency_ratio``, ``d_ghost_fraction`` (error) and ``d_rmtf`` (error, z_mm),
        NaN for an error not in the table (sigma 0, or its evaluations failed);
        ``yield_fraction`` (NaN without a spec). Every variable has ``units`` (``errors``
        and ``sigma``: the coordinate ``error_units``, deg for the tilt, else um).
        Unlike :func:`tolerance_dataset` it needs no design (error names from the draws).
        """
        import xarray as xr

        nan = float("nan")
        names = list(self.errors[0]) if self.errors else []
        zk = [f"{z:g}" for z in self.z_mm]
        samples = self.samples

        def col(k: str) -> np.ndarray:
            return np.array([nan if s is None else s[k] for s in samples], dtype=np.float64)

        rm = np.array(
            [[nan] * len(zk) if s is None else [s["rmtf_at"][z] for z in zk] for s in samples],
            dtype=np.float64,
        ).reshape(len(samples), len(zk))
        sens = {row["error"]: row for row in self.sensitivity}

        def by_error(k: str) -> np.ndarray:
            return np.array([sens.get(n, {}).get(k, nan) for n in names], dtype=np.float64)

        d_rm = np.array(
            [[sens.get(n, {}).get(f"d_rmtf@{z}", nan) for z in zk] for n in names],
            dtype=np.float64,
        ).reshape(len(names), len(zk))
        one, mm = {"units": "1"}, {"units": "mm"}
        um2sr = {"units": "um^2 sr"}
        metrics = {
            "dof_mm": mm,
            "efficiency_ratio": one,
            "efficiency_ratio_total": one,
            "ghost_fraction": one,
            "etendue_own_um2sr": um2sr,
            "etendue_ghost_um2sr": um2sr,
            "nearest_ghost_mm": mm,
        }
        data = {
            "errors": (
                ("sample", "error"),
                np.array([[e[n] for n in names] for e in self.errors], dtype=np.float64).reshape(
                    len(self.errors), len(names)
                ),
                {"units": "see error_units"},
            ),
            "ok": ("sample", np.array([s is not None for s in samples], np.int8), one),
            "rmtf": (("sample", "z_mm"), rm, one),
        }
        for k, u in metrics.items():
            if any(s is not None and k in s for s in samples):
                data[k] = ("sample", col(k), u)
        data["nominal_rmtf"] = (
            "z_mm",
            np.array([self.nominal["rmtf_at"][z] for z in zk], dtype=np.float64),
            one,
        )
        for k, u in metrics.items():
            if k in self.nominal:
                data[f"nominal_{k}"] = ((), np.float64(self.nominal[k]), u)
        mean_abs = "mean |change| at +-1 sigma of this error alone"
        data |= {
            "sigma": ("error", by_error("sigma"), {"units": "see error_units"}),
            "d_dof_mm": ("error", by_error("d_dof_mm"), mm | {"long_name": mean_abs}),
            "d_efficiency_ratio": (
                "error",
                by_error("d_efficiency_ratio"),
                one | {"long_name": mean_abs},
            ),
            "d_ghost_fraction": (
                "error",
                by_error("d_ghost_fraction"),
                one | {"long_name": mean_abs},
            ),
            "d_rmtf": (("error", "z_mm"), d_rm, one | {"long_name": mean_abs}),
            "yield_fraction": (
                (),
                np.float64(nan if self.yield_fraction is None else self.yield_fraction),
                one,
            ),
        }
        attrs = {"design": self.design, "seed": self.seed, "spec": self.spec}
        attrs |= {f"sigma_{k}": float(v) for k, v in self.sigmas.items()}
        attrs |= {k: v for k, v in self.meta.items() if isinstance(v, int | float | str)}
        attrs |= optics_attrs(self.meta)
        return xr.Dataset(
            data,
            coords={
                "sample": ("sample", np.arange(len(samples))),
                "error": ("error", names),
                "error_units": ("error", ["deg" if n == "tilt" else "um" for n in names]),
                "z_mm": ("z_mm", np.asarray(self.z_mm, dtype=np.float64), mm),
                "dpi": ((), np.float64(self.dpi)),
            },
            attrs=attrs,
        )


def tolerance(
    design: Design,
    *,
    samples: int = TOLERANCE_SAMPLES,
    sigmas: dict | None = None,
    dpi: float | None = None,
    z_mm=(0.5, 1.0, 2.0, 3.0, 3.5),
    spec: str | None = None,
    seed: int = 0,
    ghost_rays: int = 1 << 16,
    workers: int | None = None,
    dask_address: str | None = None,
    journal=None,
    progress: bool = False,
    verify: bool = True,
    estimator: str = "surrogate",
    device: str | None = None,
    optics: str | Optics = "ray",
) -> ToleranceResult:
    """Monte Carlo of assembly errors, sensitivity table and yield (see module doc).

    ``dpi``: the chart of the RMTF and the depth of field (default: 2/3 of the design's
    resolution, :func:`~opticalstamp.design.resolution.dof_chart_dpi`).
    ``verify``: the nominal design is also traced exactly
    (:func:`~opticalstamp.studies.verify.exact_figures`); its figures are in
    ``meta["nominal_exact"]`` and the figures where the surrogate is off beyond its stated
    accuracy in ``meta["nominal_disagrees"]`` (the samples are the surrogate's).
    ``estimator``: "surrogate" or "trace" (every sample traced exactly,
    :func:`~opticalstamp.studies.verify.evaluate_exact`; the nominal then needs no
    re-verification).
    ``device``: where the samples trace their rays (:func:`~opticalstamp.device.run_device`,
    resolved once here; None: the device of the run in progress), handed to the workers in
    each task's payload.
    ``optics``: "ray", "wave" or "auto" (or a resolved
    :class:`~opticalstamp.analysis.responsivity.Optics`), resolved once for the nominal
    design (:func:`~opticalstamp.analysis.responsivity.resolve_optics`) and applied to
    every sample and every design of the sensitivity table: by wave optics each is
    evaluated by the search's wave estimator
    (:func:`~opticalstamp.studies.waveestimate.evaluate_wave`; with ``estimator`` "trace"
    the exact wave figures), and ``verify`` checks the nominal against the exact wave
    figures (:func:`~opticalstamp.studies.waveestimate.exact_wave_figures`) within the
    estimator's stated accuracy (``WAVE_ACCURACY``). ``meta["optics"]``: the resolved
    optics (:meth:`~opticalstamp.analysis.responsivity.Optics.to_dict`); each sample's
    figures name their engine (``"optics"``). A sample the wave engine cannot do (a hole
    perturbed until the pixel's acceptance cone cuts the band) is a failed sample.
    """
    check_estimator(estimator)
    check_seed(seed)
    opt = resolve_optics(design, optics)
    dpi = dof_chart_dpi(design) if dpi is None else float(dpi)
    sg = DEFAULT_SIGMAS | (sigmas or {})
    if any(v < 0 for v in sg.values()):
        raise ValueError("sigmas must be >= 0")
    if samples < 1:
        raise ValueError("samples must be >= 1")
    spec_l = parse_spec(spec, z_mm)
    base = design.model_dump(mode="json", exclude_none=True)
    options = {
        "dpi": dpi,
        "rmtf_z_mm": tuple(float(z) for z in z_mm),
        "ghost_rays": ghost_rays,
        "seed": seed,
    }
    if estimator == "trace":
        options["estimator"] = "trace"
    wave = opt.engine == "wave"
    if wave:  # absent for ray optics: the tasks' keys of earlier journals hold
        options["optics"] = "wave"

    where = run_device(device)

    def task(errors: dict) -> tuple[str, dict]:
        p = {"base": base, "errors": errors, "options": options, "device": where}
        return task_key(p), p

    nominal_key, nominal_p = task({})
    oat = []
    for name, s in zip(error_names(design), _sigma_vector(design, sg), strict=True):
        if s > 0:
            oat += [(name, +1, task({name: float(s)})), (name, -1, task({name: -float(s)}))]
    draws = [draw_errors(design, i, seed, sg) for i in range(samples)]
    mc = [task(e) for e in draws]
    tasks = [(nominal_key, nominal_p)] + [t for _, _, t in oat] + mc
    recs = run_tasks(
        _evaluate_payload,
        tasks,
        workers=workers,
        dask_address=dask_address,
        journal=journal,
        progress=progress,
        desc="tolerance",
        check=check_figures,
    )
    if not recs[nominal_key]["ok"]:
        raise ValueError(f"the nominal design could not be evaluated: {recs[nominal_key]['error']}")
    nominal = recs[nominal_key]["result"]
    sens = {}
    for name, _sign, (key, _) in oat:
        r = recs.get(key)
        if r is None or not r["ok"]:
            continue
        row = sens.setdefault(name, {"error": name, "sigma": None})
        row["sigma"] = float(_sigma_vector(design, sg)[error_names(design).index(name)])
        for k, v in (
            ("dof_mm", r["result"]["dof_mm"]),
            ("efficiency_ratio", r["result"]["efficiency_ratio"]),
            ("ghost_fraction", r["result"]["ghost_fraction"]),
        ):
            row.setdefault(f"d_{k}", []).append(v - nominal[k])
        for z in options["rmtf_z_mm"]:
            key_z = f"d_rmtf@{z:g}"
            row.setdefault(key_z, []).append(
                r["result"]["rmtf_at"][f"{z:g}"] - nominal["rmtf_at"][f"{z:g}"]
            )
    table = []
    for row in sens.values():
        out = {"error": row["error"], "sigma": row["sigma"]}
        for k, v in row.items():
            if k.startswith("d_"):
                out[k] = float(np.mean(np.abs(v)))  # mean |change| at +-1 sigma
        table.append(out)
    table.sort(key=lambda r: -r["d_dof_mm"])
    results, failures = [], []
    for (key, _p), e in zip(mc, draws, strict=True):
        r = recs.get(key)
        if r is not None and r["ok"]:
            results.append(r["result"])
        else:
            results.append(None)
            failures.append({"errors": e, "error": None if r is None else r.get("error")})
    ok = [r for r in results if r is not None]
    yld = None
    if spec_l and ok:
        yld = sum(meets(r, spec_l) for r in ok) / len(results)
    return ToleranceResult(
        design=design.name,
        seed=seed,
        sigmas=sg,
        dpi=dpi,
        z_mm=[float(z) for z in z_mm],
        nominal=nominal,
        errors=draws,
        samples=results,
        failures=failures,
        sensitivity=table,
        spec=spec or "",
        yield_fraction=yld,
        meta={
            "ghost_rays": ghost_rays,
            "estimator": _estimator_text(estimator, wave),
            "optics": opt.to_dict(),
        }
        | _nominal_exact(
            design, nominal, dpi, z_mm, seed, verify and estimator == "surrogate", wave
        ),
    )


def _estimator_text(estimator: str, wave: bool) -> str:
    """How each sample is evaluated, in words (the ray estimators of :data:`ESTIMATORS`,
    or their wave counterparts)."""
    if wave:
        return EXACT_WAVE if estimator == "trace" else WAVE_ESTIMATE
    return ESTIMATORS[estimator]


def _nominal_exact(
    design: Design, nominal: dict, dpi: float, z_mm, seed: int, verify: bool, wave: bool = False
):
    """The nominal design's exact figures beside the estimate's (see :func:`tolerance`):
    the exact tracer's, or by wave optics the exact wave figures."""
    if not verify:
        return {}
    zs = tuple(float(z) for z in z_mm)
    if wave:
        ex = exact_wave_figures(design, dpi=dpi, rmtf_z_mm=zs, seed=seed)
        return {"nominal_exact": ex, "nominal_disagrees": wave_disagreements(nominal, ex)}
    ex = exact_figures(design, dpi=dpi, rmtf_z_mm=zs, seed=seed)
    return {"nominal_exact": ex, "nominal_disagrees": disagreements(nominal, ex)}


def optics_attrs(meta: dict) -> dict:
    """A study's optics as a dataset's plain attributes: ``optics`` (the engine that gave
    the figures: "ray" or "wave"), ``optics_asked``, ``optics_reason`` (none for a study
    run before the optics was recorded)."""
    o = meta.get("optics")
    if not o:
        return {}
    return {"optics": o["engine"], "optics_asked": o["asked"], "optics_reason": o["reason"]}


def tolerance_dataset(res: ToleranceResult, design: Design):
    """Samples of a tolerance study as an xarray Dataset (dims: sample, error, z)."""
    import xarray as xr

    from .. import __version__

    names = error_names(design)
    ok = [s is not None for s in res.samples]
    nan = float("nan")

    def col(k):
        return np.array([s[k] if s is not None else nan for s in res.samples])

    rm = np.array(
        [[s["rmtf_at"][f"{z:g}"] if s is not None else nan for z in res.z_mm] for s in res.samples]
    )
    return xr.Dataset(
        {
            "errors": (("sample", "error"), np.array([[e[n] for n in names] for e in res.errors])),
            "ok": ("sample", np.array(ok, dtype=np.int8)),
            f"rmtf{res.dpi:g}": (("sample", "z_mm"), rm),
            "dof_mm": ("sample", col("dof_mm")),
            "efficiency_ratio": ("sample", col("efficiency_ratio")),
            "ghost_fraction": ("sample", col("ghost_fraction")),
        },
        coords={"sample": np.arange(len(res.samples)), "error": names, "z_mm": res.z_mm},
        attrs={
            "kind": "opticalstamp tolerance",
            "design": design.name,
            "design_fingerprint": design.fingerprint(),
            "seed": res.seed,
            "opticalstamp_version": __version__,
            "sigmas": res.sigmas,
            "spec": res.spec,
            "yield": res.yield_fraction,
            "sensitivity": res.sensitivity,
            "nominal": res.nominal,
        }
        | optics_attrs(res.meta),
    )
