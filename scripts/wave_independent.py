"""The separable wave engine against the independent 2-D path on the designs issue 23 names.

The separable path (``analysis/wave.py``: paraxial propagator, 1-D FFTs, a sum of
separable terms per sequence of rows) and the 2-D path (``analysis/wave2d.py``: the exact
angular spectrum slab by slab on a 2-D grid, 2-D masks, coherent modes by a randomized
range finder) share only the source model and the sampling rules. At one sampling per
design (a band narrower than the default so that the 2-D grid fits in memory and time)
this compares, for row A's pixel at each height: the light in the band, the FWHM of the x
line-spread function, the share in the central cell and the largest LSF difference
relative to its peak. Writes docs/wave-independent.json and prints a table.

    python scripts/wave_independent.py [--band 0.1] [--z 0,1,2]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from opticalstamp.analysis.spots import fwhm
from opticalstamp.analysis.wave import wave_response
from opticalstamp.analysis.wave2d import wave_response_2d
from opticalstamp.analysis.wavebase import fresnel_numbers, wave_sampling
from opticalstamp.design import load_design
from opticalstamp.design.variants import scale_to_dpi, with_stack

OUT = Path(__file__).resolve().parents[1] / "docs" / "wave-independent.json"


def designs() -> dict:
    paper = load_design("paper2016")
    half = with_stack(scale_to_dpi(paper, 600), thicknesses_um=(500, 200, 225), name="half")
    return {
        "paper2016": paper,
        "half-scale 600-dpi copy": half,
        "holes halved over the prototype's plates": with_stack(
            paper, holes_um=(24.0, 20.0, 20.0), name="holes-halved"
        ),
        "thin-plate 600-dpi design": with_stack(
            scale_to_dpi(paper, 600), thicknesses_um=(300, 120, 150), name="thin-600"
        ),
    }


def compare(design, zs, band: float) -> dict:
    smp = wave_sampling(design, band=band)
    t0 = time.perf_counter()
    sep = wave_response(design, zs, sampling=smp)
    t1 = time.perf_counter()
    two = wave_response_2d(design, zs, sampling=smp, propagator="exact")
    t2 = time.perf_counter()
    rows = []
    for iz, z in enumerate(zs):
        a, b = sep.lsf_x[iz], np.interp(sep.x_um, two.x_um, two.lsf_x[iz])
        rows.append(
            {
                "z_mm": z,
                "light_separable": float(sep.etendue_um2sr[iz]),
                "light_2d": float(two.etendue_um2sr[iz]),
                "light_difference": float(two.etendue_um2sr[iz] / sep.etendue_um2sr[iz] - 1),
                "fwhm_x_separable_um": fwhm(a, sep.x_um),
                "fwhm_x_2d_um": fwhm(two.lsf_x[iz], two.x_um),
                "center_cell_separable": float(sep.center_cell_fraction[iz]),
                "center_cell_2d": float(two.center_cell_fraction[iz]),
                "lsf_max_difference_rel": float(np.abs(a - b).max() / a.max()),
            }
        )
    return {
        "fresnel_numbers": [round(f["fresnel_number"], 3) for f in fresnel_numbers(design)],
        "band": band,
        "step_um": smp.step_um,
        "seconds_separable": t1 - t0,
        "seconds_2d": t2 - t1,
        "rows": rows,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--band", type=float, default=0.1)
    ap.add_argument("--z", default="0,1,2")
    args = ap.parse_args()
    zs = [float(v) for v in args.z.split(",")]
    out = {}
    for name, d in designs().items():
        out[name] = r = compare(d, zs, args.band)
        print(f"{name}: Fresnel {r['fresnel_numbers']}, separable {r['seconds_separable']:.1f}"
              f" s, 2-D {r['seconds_2d']:.1f} s")  # fmt: skip
        for row in r["rows"]:
            print(
                f"  Z {row['z_mm']:g}: light {row['light_difference']:+.2%}, FWHM "
                f"{row['fwhm_x_separable_um']:.1f}/{row['fwhm_x_2d_um']:.1f} um, centre "
                f"{row['center_cell_separable']:.4f}/{row['center_cell_2d']:.4f}, LSF "
                f"{row['lsf_max_difference_rel']:.2%}"
            )
    OUT.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
