"""The separable wave engine against the independent 2-D path on the designs issue 23 names.

The separable path (``analysis/wave.py``: paraxial propagator, 1-D FFTs, a sum of
separable terms per sequence of rows) and the 2-D path (``analysis/wave2d.py``: the exact
angular spectrum slab by slab on a 2-D grid, 2-D masks, coherent modes by a randomized
range finder) share only the source model and the sampling rules. At one sampling per
design (a band narrower than the default so that the 2-D grid fits in memory and time)
this compares, for row A's pixel at each height: the light in the band, the FWHM of the x
line-spread function, the share in the central cell and the largest LSF difference
relative to its peak; and the 200-dpi-class RMTF against height and the depth of field at
the design's charts from each path's line-spread functions of rows A and B (the 2-D path's
through :func:`~opticalstamp.analysis.wave2dlsf.lsf_source_2d`). Writes
docs/wave-independent.json (or ``--out``) and prints a table.

    python scripts/wave_independent.py [--band 0.1 | --band default] [--z 0,1,2]
        [--device cpu|cuda] [--precision single|double] [--out FILE]

At the designs' default bands the 2-D path needs a GPU (``--device cuda``, CuPy).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from opticalstamp.analysis.rmtf import rmtf_from_lsf
from opticalstamp.analysis.spots import fwhm
from opticalstamp.analysis.wave import wave_response
from opticalstamp.analysis.wave2d import wave_response_2d
from opticalstamp.analysis.wave2dlsf import lsf_source_2d
from opticalstamp.analysis.wavebase import fresnel_numbers, wave_sampling
from opticalstamp.analysis.wavecompare import WaveFolds
from opticalstamp.analysis.wavespectral import SpectralLSFSource
from opticalstamp.design import load_design
from opticalstamp.design.resolution import chart_dpis
from opticalstamp.design.variants import scale_to_dpi, with_stack
from opticalstamp.units import period_of_dpi

Z19 = tuple(0.25 * i for i in range(19))

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


def _rmtf_difference(a, b) -> float:
    """Largest |RMTF_a - RMTF_b| over the charts at the 19 heights both have."""
    out = 0.0
    for k in a.rmtf_max:
        va = dict(zip(np.round(a.z_mm, 9), a.rmtf_max[k], strict=True))
        vb = dict(zip(np.round(b.z_mm, 9), b.rmtf_max[k], strict=True))
        out = max(out, max(abs(va[z] - vb[z]) for z in np.round(Z19, 9)))
    return float(out)


def dof_both(design, smp, device: str, precision: str) -> dict:
    """RMTF against height (19 Z) and depth of field at the design's charts from the
    separable path's LSFs and from the 2-D path's (rows A and B, one wavelength)."""
    dpis = list(chart_dpis(design))
    pers = [period_of_dpi(x) for x in dpis]
    sep = WaveFolds(design, max(Z19), sampling=smp, spectrum="mono")
    two = WaveFolds(design, max(Z19), sampling=smp, spectrum="mono")
    cyc = [2 * smp.band / smp.wavelength_um]
    two._sources = [
        SpectralLSFSource(
            [
                lsf_source_2d(
                    design, max(Z19), pixel=(r, 0), sampling=smp, device=device, precision=precision
                )
            ],  # fmt: skip
            np.array([1.0]),
            cyc,
        )
        for r in range(design.sensor.rows)
    ]
    a = rmtf_from_lsf(sep.folded(Z19, pers), design, dpi=dpis)
    b = rmtf_from_lsf(two.folded(Z19, pers), design, dpi=dpis)
    return {
        "dpi": dpis,
        "dof_separable_mm": a.dof_mm,
        "dof_2d_mm": b.dof_mm,
        "rmtf_max_difference": _rmtf_difference(a, b),
    }


def compare(design, zs, band: float | None, device: str = "cpu", precision="double") -> dict:
    smp = wave_sampling(design, band=band)
    t0 = time.perf_counter()
    sep = wave_response(design, zs, sampling=smp)
    t1 = time.perf_counter()
    two = wave_response_2d(
        design, zs, sampling=smp, propagator="exact", device=device, precision=precision
    )
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
        "band": smp.band,
        "step_um": smp.step_um,
        "device": device,
        "precision": precision,
        "seconds_separable": t1 - t0,
        "seconds_2d": t2 - t1,
        "rows": rows,
        "rmtf_dof": dof_both(design, smp, device, precision),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--band", default="0.1", help="a band, or 'default' (each design's)")
    ap.add_argument("--z", default="0,1,2")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--precision", default="double")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args()
    zs = [float(v) for v in args.z.split(",")]
    band = None if args.band == "default" else float(args.band)
    out = {}
    for name, d in designs().items():
        out[name] = r = compare(d, zs, band, args.device, args.precision)
        print(f"{name}: Fresnel {r['fresnel_numbers']}, separable {r['seconds_separable']:.1f}"
              f" s, 2-D {r['seconds_2d']:.1f} s")  # fmt: skip
        for row in r["rows"]:
            print(
                f"  Z {row['z_mm']:g}: light {row['light_difference']:+.2%}, FWHM "
                f"{row['fwhm_x_separable_um']:.1f}/{row['fwhm_x_2d_um']:.1f} um, centre "
                f"{row['center_cell_separable']:.4f}/{row['center_cell_2d']:.4f}, LSF "
                f"{row['lsf_max_difference_rel']:.2%}"
            )
        print(f"  RMTF/DOF: {r['rmtf_dof']}", flush=True)
    Path(args.out).write_text(json.dumps(out, indent=1, default=str))


if __name__ == "__main__":
    main()
