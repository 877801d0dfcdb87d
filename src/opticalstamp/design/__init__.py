"""What a scanner is: the design model and its validation, design files, materials,
derived designs (variants) and presets; two kinds: the optical stamp and the
gradient-index rod-lens array it is compared with. The first stage: it imports nothing else of
opticalstamp but ``validate``."""

from .files import (
    KINDS,
    AnyDesign,
    design_from_dict,
    design_toml,
    format_validation_error,
    load_design,
    preset_names,
    preset_text,
)
from .model import A4_WIDTH_UM, Design, DesignError, Gap, Mask, Sensor, Slab
from .rodlens import CoverGlass, RodArray, RodLensDesign, RodSensor
from .variants import (
    drop_mask,
    one_row,
    replace,
    scale_to_dpi,
    square_holes,
    stack_params,
    structural_variants,
    with_glass_index,
    with_hole_shape,
    with_layers,
    with_sensitive_area,
    with_stack,
    with_unstated,
)

__all__ = [
    "A4_WIDTH_UM",
    "KINDS",
    "AnyDesign",
    "CoverGlass",
    "RodArray",
    "RodLensDesign",
    "RodSensor",
    "Design",
    "DesignError",
    "Gap",
    "Mask",
    "Sensor",
    "Slab",
    "design_from_dict",
    "design_toml",
    "drop_mask",
    "format_validation_error",
    "load_design",
    "one_row",
    "preset_names",
    "preset_text",
    "replace",
    "scale_to_dpi",
    "square_holes",
    "stack_params",
    "structural_variants",
    "with_glass_index",
    "with_hole_shape",
    "with_layers",
    "with_sensitive_area",
    "with_stack",
    "with_unstated",
]
