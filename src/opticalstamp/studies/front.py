"""A search's front re-verified by the exact tracer (or, for the points judged by wave
optics, by the exact wave figures), and its points exported as designs of their own."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..design import design_from_dict, replace, with_stack
from ..device import run_device, using_device
from .evaluate import SURROGATE, check_figures
from .runner import run_tasks, task_key
from .searchresult import FIGURES, SearchResult, depth_key
from .verify import (
    EXACT,
    EXACT_GHOST_RAYS,
    EXACT_LSF_RAYS,
    SURROGATE_ACCURACY,
    disagreements,
    exact_figures,
)
from .waveestimate import (
    EXACT_WAVE,
    EXACT_WAVE_GHOST_RAYS,
    EXACT_WAVE_LSF_RAYS,
    WAVE_ACCURACY,
    WAVE_ESTIMATE,
    exact_wave_figures,
    wave_disagreements,
)


def _exact_payload(payload: dict) -> dict:
    """Worker entry: the exact tracer's figures of a candidate built from plain data, its
    rays on the payload's device."""
    base = design_from_dict(payload["base"], "search base")
    d = with_stack(base, holes_um=payload["holes_um"], thicknesses_um=payload["thicknesses_um"])
    opts = dict(payload["options"])
    if opts.pop("optics", "ray") == "wave":
        opts["ghost_rays"] = opts.pop("wave_ghost_rays")
        opts["lsf_rays"] = opts.pop("wave_lsf_rays")
        return exact_wave_figures(d, **opts)
    opts.pop("wave_ghost_rays", None)
    opts.pop("wave_lsf_rays", None)
    with using_device(payload.get("device", "cpu")):
        return exact_figures(d, **opts) | {"optics": "ray"}


def _verified(row: dict, exact: dict | None) -> dict:
    """A record with the exact figures as its figures of record (the exact tracer's, or
    for a point judged by wave optics the exact wave figures): the estimate's kept under
    ``surrogate``, the exact ones under ``exact``, and ``disagrees`` naming the figures
    that differ by more than the estimator's stated accuracy (``SURROGATE_ACCURACY``, or
    ``WAVE_ACCURACY`` for the wave estimator)."""
    wave = row.get("optics") == "wave"
    if exact is None:
        est = WAVE_ESTIMATE if wave else SURROGATE
        return row | {"estimator": est, "exact": None, "disagrees": None}
    sur = {k: row[k] for k in (*FIGURES, "rmtf_at")}
    out = row | {
        "estimator": EXACT_WAVE if wave else EXACT,
        "surrogate": sur,
        "exact": exact,
        "disagrees": wave_disagreements(sur, exact) if wave else disagreements(sur, exact),
    }
    for k in ("efficiency_ratio", "dof_mm", "ghost_fraction", "nearest_ghost_mm", "rmtf_at"):
        out[k] = exact[k]
    return out


def verify_front(
    res: SearchResult,
    *,
    ghost_rays: int = EXACT_GHOST_RAYS,
    lsf_rays: int = EXACT_LSF_RAYS,
    workers: int | None = None,
    dask_address: str | None = None,
    journal: Path | None = None,
    progress: bool = False,
    device: str | None = None,
    wave_ghost_rays: int = EXACT_WAVE_GHOST_RAYS,
    wave_lsf_rays: int = EXACT_WAVE_LSF_RAYS,
) -> SearchResult:
    """The search's front and base design re-verified by the exact tracer, or where a
    point was judged by wave optics (its ``optics``) by the exact wave figures
    (:func:`~opticalstamp.studies.waveestimate.exact_wave_figures`: efficiency and rmtf
    with optics wave, ``wave_ghost_rays`` and ``wave_lsf_rays`` for their traced part;
    the wave estimator's accuracy ``WAVE_ACCURACY`` flags its points).

    Each point of the front (and the base design) is traced exactly
    (:func:`~opticalstamp.studies.verify.exact_figures`, the search's seed and chart):
    its exact figures become the figures of record, the surrogate's are kept beside them,
    and ``disagrees`` names the figures where the two differ by more than
    ``SURROGATE_ACCURACY``. ``exact_dominated_by``: how many other points of the front
    dominate it in the exact figures (the surrogate ranked it on the front; 0 where the
    exact tracer agrees). Runs on the search's workers and journal, so it resumes;
    ``device`` as in :func:`search`.
    """
    if res.design is None:
        raise ValueError("verify_front: the search result carries no design")
    base_json = res.design.model_dump(mode="json", exclude_none=True)
    options = {
        "dpi": res.meta["dof_dpi"],
        "near_mm": res.meta["near_mm"],
        "ghost_rays": ghost_rays,
        "lsf_rays": lsf_rays,
        "seed": res.seed,
    }
    rows = list(res.pareto) + ([res.reference] if res.reference else [])
    where = run_device(device)
    tasks = []
    wave_options = options | {
        "optics": "wave",
        "wave_ghost_rays": wave_ghost_rays,
        "wave_lsf_rays": wave_lsf_rays,
    }
    for r in rows:
        p = {
            "base": base_json,
            "holes_um": r["holes_um"],
            "thicknesses_um": r["thicknesses_um"],
            "options": wave_options if r.get("optics") == "wave" else options,
            "exact": True,
            "device": where,
        }
        tasks.append((task_key(p), p))
    recs = run_tasks(
        _exact_payload,
        tasks,
        workers=workers,
        dask_address=dask_address,
        journal=journal,
        progress=progress,
        desc="exact re-verification",
        check=check_figures,
    )

    def exact_of(i: int) -> dict | None:
        rec = recs.get(tasks[i][0])
        return rec["result"] if rec is not None and rec["ok"] else None

    front = [_verified(r, exact_of(i)) for i, r in enumerate(res.pareto)]
    depth = depth_key(res)
    pts = np.array([[r["efficiency_ratio"], r[depth]] for r in front]).reshape(-1, 2)
    for r, p in zip(front, pts, strict=True):
        r["exact_dominated_by"] = int((np.all(pts >= p, axis=1) & np.any(pts > p, axis=1)).sum())
    reference = res.reference
    if reference is not None:
        reference = _verified(reference, exact_of(len(rows) - 1))
    meta = res.meta | {
        "verified_by": EXACT,
        "surrogate_accuracy": dict(SURROGATE_ACCURACY),
        "wave_verified_by": EXACT_WAVE,
        "wave_accuracy": dict(WAVE_ACCURACY),
        "exact_ghost_rays": ghost_rays,
        "exact_lsf_rays": lsf_rays,
    }
    return dataclasses.replace(res, pareto=front, reference=reference, meta=meta)


def front_designs(results: dict[str, SearchResult], front: list[dict]) -> list[dict]:
    """Every point of ``front`` (rows of :func:`merged_front` or of one search's
    ``pareto``) as a design of its own: ``{"name", "file", "design", "row", "provenance"}``.

    The design is the searched base (of the point's variant) with the point's holes and
    slabs; its name is the base's with ``-pNN`` (NN: the point's rank by depth of field,
    from 01), its description says where it comes from; ``file`` is the name of the file
    it is written to, ``STEM-pNN.toml`` with STEM the base's name as a file stem without
    spaces (:func:`~opticalstamp.io.files.file_stem`: ``paper2016-p01.toml``,
    ``paper2016-600dpi-p01.toml`` for the base ``paper2016 at 600 dpi``; unique, as NN
    is); ``provenance`` lists the search's settings and the point's surrogate and exact
    figures (the lines a design file writes as comments).
    """
    from .. import __version__
    from ..io.files import file_stem

    out = []
    for i, row in enumerate(front, start=1):
        res = results[row["variant"]] if "variant" in row else next(iter(results.values()))
        base = res.design
        name = f"{base.name}-p{i:02d}"
        desc = (
            f"Pareto point {i} of {len(front)} of a design search of {base.name} "
            f"(seed {res.seed}, {res.dpi:g} dpi, depth of field at "
            f"{res.meta['dof_dpi']:g} dpi): holes {row['holes_um']} um (layer 1 first), "
            f"slabs {row['thicknesses_um']} um (object side first)"
        )
        d = with_stack(base, holes_um=row["holes_um"], thicknesses_um=row["thicknesses_um"])
        d = replace(d, name=name, description=desc)
        sur = row.get("surrogate") or {k: row[k] for k in (*FIGURES, "rmtf_at")}
        wave = row.get("optics") == "wave"
        est = "wave estimator" if wave else "surrogate"
        prov = [
            f"exported by opticalstamp {__version__} search --export-designs",
            f"search: base {base.name} (fingerprint {base.fingerprint()}), seed {res.seed}, "
            f"{res.dpi:g} dpi, {len(res.records)} designs, optics "
            f"{res.meta.get('optics', 'ray')}, constraints near_mm "
            f"{res.meta['near_mm']:g}, budget_mm {res.meta['budget_mm']:g}"
            + (f", max_ghost {res.meta['max_ghost']:g}" if res.meta["max_ghost"] else ""),
            f"point {i} of {len(front)}"
            + (f" (variant {row['variant']})" if "variant" in row else ""),
            "{}: efficiency {:.5f}, DOF {:.3f} mm, ghost fraction {:.4f}".format(
                est, sur["efficiency_ratio"], sur["dof_mm"], sur["ghost_fraction"]
            ),
        ]
        if row.get("exact"):
            e = row["exact"]
            prov.append(
                "{} (figure of record): efficiency {:.5f}, DOF {:.3f} mm, ghost "
                "fraction {:.4f}{}".format(
                    "exact wave figures" if wave else "exact tracer",
                    e["efficiency_ratio"],
                    e["dof_mm"],
                    e["ghost_fraction"],
                    f"; differs from the {est} in {', '.join(row['disagrees'])}"
                    if row["disagrees"]
                    else "",
                )
            )
        file = f"{file_stem(base.name)}-p{i:02d}.toml"
        out.append({"name": name, "file": file, "design": d, "row": row, "provenance": prov})
    return out
