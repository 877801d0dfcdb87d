"""What a scanner is: the design model and its validation, design files, materials and
presets. The first stage: it imports nothing else of opticalstamp but ``validate``."""

from .model import (
    A4_WIDTH_UM,
    Design,
    DesignError,
    Gap,
    Mask,
    Sensor,
    Slab,
    design_from_dict,
    format_validation_error,
    load_design,
    preset_names,
)

__all__ = [
    "A4_WIDTH_UM",
    "Design",
    "DesignError",
    "Gap",
    "Mask",
    "Sensor",
    "Slab",
    "design_from_dict",
    "format_validation_error",
    "load_design",
    "preset_names",
]
