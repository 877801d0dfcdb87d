"""opticalstamp: design and analysis of lensless contact image scanners (optical stamps).

A Python API for scripts and notebooks (see docs/api.md)::

    import opticalstamp as osp

    d = osp.load_design("paper2016")
    r = osp.rmtf(d, dpi=(200,), z_mm=(0.5, 1.5, 2.5))
    r.dof_mm

The pipeline, one subpackage per stage (docs/architecture.md): ``design`` → ``io`` →
``raytrace`` → ``analysis`` → ``imaging`` → ``studies`` → ``report`` → ``cli``. The names
below are imported lazily on first use, so ``import opticalstamp`` stays cheap (no numba
compilation, no plotting library).
"""

from __future__ import annotations

import importlib
from types import MappingProxyType

__version__ = "0.1.0"

#: public name -> module that defines it
_EXPORTS = MappingProxyType(
    {
        # design
        "Design": "design.model",
        "DesignError": "design.model",
        "load_design": "design.files",
        "design_from_dict": "design.files",
        "preset_names": "design.files",
        "RodLensDesign": "design.rodlens",
        "InputError": "validate",
        # deriving a design from another (always validated)
        "replace": "design.variants",
        "with_stack": "design.variants",
        "stack_params": "design.variants",
        "scale_to_dpi": "design.variants",
        "with_sensitive_area": "design.variants",
        "with_hole_shape": "design.variants",
        "square_holes": "design.variants",
        "structural_variants": "design.variants",
        # analysis of one design
        "analyse_ghosts": "analysis.ghosts",
        "spots": "analysis.spots",
        "psf": "analysis.spots",
        "rmtf": "analysis.rmtf",
        "depth_of_field": "analysis.rmtf",
        "efficiency": "analysis.efficiency",
        "diffraction_budget": "analysis.diffraction",
        "design_slit_case": "analysis.diffraction",
        "parameter_study": "analysis.paper_study",
        # imaging
        "simulate_scan": "imaging.scan",
        "ScanSettings": "imaging.scan",
        "prepare_kernels": "imaging.scan",
        "make_chart": "imaging.charts",
        "measure_rmtf": "imaging.measure",
        "sfr": "imaging.measure",
        # many designs
        "search": "studies.search",
        "tolerance": "studies.tolerance",
        # files and the report
        "read_document": "io.files",
        "read_image": "io.files",
        "build_report": "report.build",
        # units
        "output_pitch": "raytrace.stack",
        "period_of_dpi": "units",
        "pitch_of_dpi": "units",
        "dpi_of_pitch": "units",
    }
)

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module 'opticalstamp' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
