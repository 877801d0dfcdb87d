"""Speed of the design search judged by wave optics (run on demand:
python benchmarks/bench_search_wave.py [POPULATION GENERATIONS [POP1200 GEN1200]]; 0 skips a part).

(1200 dpi runs first.)
1. ``opticalstamp search --dpi 600`` as a user runs it (default --optics auto: every
   candidate of the 600-dpi space is judged by the wave estimator where the validity
   rule says ray optics fails), 32 designs x 15 generations (480) on every core, the
   front and the base design verified with the exact wave figures and exported as
   design files (``--export-designs``). Timed whole.
2. The same at 1200 dpi (default the same 32 x 15 = 480 designs).
Both bases are the paper's design with every length scaled (``search_base``) and its
space the paper's 300-dpi space scaled to the resolution (``default_space``: slabs from
the Fresnel image of the thinnest to the geometric image of the thickest).
One run each, no journal (every design evaluated from scratch). Written as JSON to
benchmarks/bench_search_wave.json: times, the machine's load, the fronts (exact wave
figures, the estimates beside them, the flags) and what the constraints rejected.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

from typer.testing import CliRunner

from opticalstamp.cli import app


def run(dpi: int, population: int, generations: int, folder: Path) -> dict:
    args = [
        "search", "--dpi", str(dpi), "--population", str(population), "--generations",
        str(generations), "--json", "--export-designs", str(folder / f"front{dpi}"),
    ]  # fmt: skip
    load0 = os.getloadavg()[0]
    t = time.perf_counter()
    res = CliRunner().invoke(app, args)
    wall = time.perf_counter() - t
    if res.exit_code != 0:
        raise SystemExit(f"search --dpi {dpi} failed ({res.exit_code}): {res.output[-2000:]}")
    data = json.loads(res.stdout)
    keep = ("holes_um", "thicknesses_um", "efficiency_ratio", "dof_mm", "ghost_fraction",
            "diffraction_spill", "stack_um", "optics", "estimator", "disagrees",
            "exact_dominated_by")  # fmt: skip
    front = [
        {k: p.get(k) for k in keep}
        | {
            "estimate": {
                k: (p.get("surrogate") or {}).get(k)
                for k in ("efficiency_ratio", "dof_mm", "ghost_fraction", "rmtf_at")
            },
            "exact_rmtf_at": p.get("rmtf_at"),
        }  # fmt: skip
        for p in data["pareto"]
    ]
    files = sorted(x.name for x in (folder / f"front{dpi}").iterdir())
    out = {
        "command": "opticalstamp " + " ".join(a for a in args if not a.startswith(str(folder))),
        "designs": data["n_evaluations"],
        "feasible": data["n_feasible"],
        "failed": data["n_failed"],
        "wall_s": wall,
        "load_before": load0,
        "load_after": os.getloadavg()[0],
        "optics_used": data["meta"].get("optics_used"),
        "rejected_by": data["meta"].get("rejected_by"),
        "hole_bounds_um": data["meta"].get("hole_bounds_um"),
        "thickness_bounds_um": data["meta"].get("thickness_bounds_um"),
        "wave_accuracy": data["meta"].get("wave_accuracy"),
        "front": front,
        "reference": {k: (data["reference"] or {}).get(k) for k in keep},
        "exported": files,
    }
    print(
        f"search --dpi {dpi}: {out['designs']} designs ({out['optics_used']}), "
        f"{out['feasible']} feasible, front of {len(front)} verified and exported, "
        f"{wall:.0f} s (load {load0:.1f} -> {out['load_after']:.1f})",
        flush=True,
    )
    return out


def main(pop: int = 32, gen: int = 15, pop1200: int = 32, gen1200: int = 15) -> dict:
    """Run each part whose budget is not 0 (POP or GEN 0 skips the part, whose entry of
    the JSON written before is kept, marked ``"kept_from_earlier_run"``)."""
    path = Path(__file__).with_suffix(".json")
    earlier = json.loads(path.read_text()) if path.exists() else {}
    out = {"cores": os.cpu_count()}
    with tempfile.TemporaryDirectory() as tmp:
        for dpi, p, g in ((1200, pop1200, gen1200), (600, pop, gen)):
            if p * g == 0:
                if str(dpi) in earlier:
                    out[str(dpi)] = earlier[str(dpi)] | {"kept_from_earlier_run": True}
                continue
            out[str(dpi)] = run(dpi, p, g, Path(tmp))
            path.write_text(json.dumps(out | {k: v for k, v in earlier.items() if k not in out},
                                       indent=1) + "\n")  # fmt: skip
    path.write_text(json.dumps(out, indent=1) + "\n")
    return out


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:]))
