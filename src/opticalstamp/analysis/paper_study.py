"""Study of the paper's unstated parameters (hole shape, sensitive area, reference gap
medium, Fresnel losses, glass index): efficiency, depth of field and ghost fraction for
each combination, and which combinations agree with the paper's light-efficiency ratio
1/36 (working F 60, §5) and its measured 3.5 mm depth of field (§5, Fig. 11).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from types import MappingProxyType

import numpy as np

from ..design import Design, with_unstated
from ..raytrace.pixel import PixelTracer
from ..raytrace.stack import output_pitch
from .efficiency import reference_etendue, reference_f_number
from .ghosts import analyse_ghosts
from .rmtf import rmtf

#: What the paper states (§5): efficiency ratio, working F-number, depth of field.
PAPER_RATIO = 1 / 36
PAPER_F_NUMBER = 60.0
PAPER_DOF_MM = 3.5

DEFAULT_FACTORS = MappingProxyType(
    {
        "hole_shape": ("square", "circle"),
        "sensitive_um": (42.3, 32.0),
        "gap_medium": ("air", 1.49),
        "fresnel": (False, True),
        "glass_index": (1.52, 1.46),
    }
)


@dataclass(frozen=True)
class StudyResult:
    design: str
    seed: int
    factors: dict
    rows: list[dict]
    paper: dict
    meta: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)

    @property
    def consistent(self) -> list[dict]:
        return [r for r in self.rows if r.get("consistent_efficiency") and r.get("consistent_dof")]


def _row(combo: dict, g, r, g_ref: float, f_tol: float, dof_tol: float, source: str) -> dict:
    """One study row from a combination's ghost analysis ``g`` and RMTF ``r`` (``g_ref``: the
    reference lens's etendue)."""
    f_ref = reference_f_number()
    tot = g.etendue_own_um2sr + g.etendue_ghost_um2sr
    ratio = tot / g_ref
    f_w = f_ref / math.sqrt(ratio)
    dof = r.dof_mm["200"]
    z = np.asarray(r.z_mm)
    return combo | {
        "etendue_um2sr": tot,
        "ratio": ratio,
        "inverse_ratio": 1 / ratio,
        "working_f_number": f_w,
        "ghost_fraction": g.ghost_fraction,
        "dof_mm": dof,
        "rmtf200_at_3_5mm": float(np.interp(3.5, z, r.rmtf_max["200"])),
        "consistent_efficiency": abs(f_w - PAPER_F_NUMBER) <= f_tol,
        "consistent_dof": dof >= PAPER_DOF_MM - dof_tol,
        "source": source,
    }


def with_headline(study: StudyResult, design: Design, ghosts, rmtf_result, fresnel: bool):
    """The study with the row that *is* ``design`` (same fingerprint and Fresnel setting)
    rebuilt from the design's headline analyses, so a report gives the design one depth of
    field; that row says ``"source": "headline"``."""
    g_ref = reference_etendue(output_pitch(design))
    rows = []
    for row in study.rows:
        combo = {k: row[k] for k in study.factors}
        d = with_unstated(
            design,
            hole_shape=combo["hole_shape"],
            sensitive_um=combo["sensitive_um"],
            gap_medium=combo["gap_medium"],
            glass_index=combo["glass_index"],
        )
        if d.fingerprint() == design.fingerprint() and combo["fresnel"] == fresnel:
            tol = (study.meta["f_tolerance"], study.meta["dof_tolerance_mm"])
            row = _row(combo, ghosts, rmtf_result, g_ref, *tol, "headline")
        rows.append(row)
    return dataclasses.replace(study, rows=rows)


def parameter_study(
    design: Design,
    *,
    factors: dict | None = None,
    seed: int = 0,
    n_rays: int = 1 << 19,
    f_tolerance: float = 5.0,
    dof_tolerance_mm: float = 0.25,
    progress: bool = False,
    known: Mapping | None = None,
    deferred: Collection = (),
    part: tuple[int, int] = (0, 1),
) -> StudyResult:
    """Every combination of ``factors`` (default :data:`DEFAULT_FACTORS`).

    A combination is consistent with the paper's efficiency when its working F-number
    (ghost light included) is within ``f_tolerance`` of 60, and with its depth of field
    when RMTF(200 dpi) >= 0.3 reaches at least 3.5 mm - ``dof_tolerance_mm`` (the
    measured RMTF, which misalignment can only lower, stayed above 0.3 at 3.5 mm).

    ``known`` maps (a design's fingerprint, Fresnel on/off) to its (GhostResult, RMTFResult)
    already computed (the report passes its headline analyses):
    a combination that *is* that design reuses them, so one design has one depth of field
    in a report. Such rows say ``"source": "headline"``, the others ``"study"``.

    ``deferred`` holds (a design's fingerprint, Fresnel on/off) whose analyses are left to
    the caller: a combination that is one of them is not analysed and gets a row of its
    factors with ``"source": "deferred"`` and no figures, for :func:`with_headline` to
    fill (the report passes its design, whose headline analyses run at the same time).

    The ghost analysis and the RMTF of a combination share one tracer (its pixel's pilot
    run, and the rays of the pixel both trace, are computed once).

    ``part`` = (i, n): only combinations i, i + n, i + 2n, ... (every combination carries
    its own seed, so a part's rows are those of the whole study); :func:`join_parts`
    puts the n parts back together, e.g. after running them on n processes.
    """
    fac = dict(DEFAULT_FACTORS if factors is None else factors)
    names = list(fac)
    g_ref = reference_etendue(output_pitch(design))
    rows = []
    i_part, n_parts = part
    if not (isinstance(n_parts, int) and n_parts >= 1 and 0 <= i_part < n_parts):
        raise ValueError(f"part: expected (i, n) with 0 <= i < n (got {part!r})")
    combos = list(itertools.product(*(fac[n] for n in names)))[i_part::n_parts]
    it = combos
    if progress:
        from tqdm import tqdm

        it = tqdm(combos, desc="parameter study", unit="design")
    for values in it:
        combo = dict(zip(names, values, strict=True))
        d = with_unstated(
            design,
            hole_shape=combo["hole_shape"],
            sensitive_um=combo["sensitive_um"],
            gap_medium=combo["gap_medium"],
            glass_index=combo["glass_index"],
        )
        key = (d.fingerprint(), combo["fresnel"])
        if key in deferred:
            rows.append(combo | {"source": "deferred"})
            continue
        reuse = (known or {}).get(key)
        if reuse is not None:
            g, r = reuse
        else:
            fr = combo["fresnel"]
            tr = PixelTracer(d, replay=True)  # one pilot, and (0, 0)'s rays traced once
            g = analyse_ghosts(d, seed=seed, n_rays=n_rays, fresnel=fr, tracer=tr)
            r = rmtf(d, dpi=(200.0,), seed=seed, n_rays=n_rays, fresnel=fr, tracer=tr)
        source = "study" if reuse is None else "headline"
        rows.append(_row(combo, g, r, g_ref, f_tolerance, dof_tolerance_mm, source))
    return StudyResult(
        design=design.name,
        seed=seed,
        factors={k: list(v) for k, v in fac.items()},
        rows=rows,
        paper={"ratio": PAPER_RATIO, "working_f_number": PAPER_F_NUMBER, "dof_mm": PAPER_DOF_MM},
        meta={"n_rays": n_rays, "f_tolerance": f_tolerance, "dof_tolerance_mm": dof_tolerance_mm},
    )


def join_parts(parts: Sequence[StudyResult]) -> StudyResult:
    """The study whose parts (``part`` = (0, n), (1, n), ... (n - 1, n) of
    :func:`parameter_study`, in that order) are ``parts``: their rows interleaved back into
    the order of the combinations."""
    if not parts:
        raise ValueError("parts: no parts to join")
    first = parts[0]
    rows = []
    for i in range(max(len(p.rows) for p in parts)):
        rows.extend(p.rows[i] for p in parts if i < len(p.rows))
    return dataclasses.replace(first, rows=rows)
