"""Study of the paper's unstated parameters (hole shape, sensitive area, reference gap
medium, Fresnel losses, glass index): efficiency, depth of field and ghost fraction for
each combination, and which combinations agree with the paper's light-efficiency ratio
1/36 (working F 60, §5) and its measured 3.5 mm depth of field (§5, Fig. 11).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from types import MappingProxyType

import numpy as np

from ..design import Design, with_unstated
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
        return [r for r in self.rows if r["consistent_efficiency"] and r["consistent_dof"]]


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
    """
    fac = dict(DEFAULT_FACTORS if factors is None else factors)
    names = list(fac)
    g_ref = reference_etendue(output_pitch(design))
    rows = []
    combos = list(itertools.product(*(fac[n] for n in names)))
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
        reuse = (known or {}).get((d.fingerprint(), combo["fresnel"]))
        if reuse is not None:
            g, r = reuse
        else:
            g = analyse_ghosts(d, seed=seed, n_rays=n_rays, fresnel=combo["fresnel"])
            r = rmtf(d, dpi=(200.0,), seed=seed, n_rays=n_rays, fresnel=combo["fresnel"])
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
