"""The haptic scalpel force model: the paper's section 6, or cutting as fracture."""

from cutkit.scalpel._kernels import (
    CUTTING,
    FRACTURE,
    FREE,
    N_OUT,
    N_PARAMS,
    O_A,
    O_CRACK,
    O_CUT,
    O_D_A,
    O_D_N,
    O_FORCE,
    O_N,
    O_PERP,
    PAPER,
    STATE_NAMES,
    STATIC,
    WITHDRAWING,
)
from cutkit.scalpel.model import (
    CUT_FIELDS,
    DEFAULT_MATERIAL,
    FRACTURE_FIELDS,
    HAPTIC_DT,
    SCALPEL_MODELS,
    Control,
    ScalpelParams,
    ScalpelState,
    blade_breadth,
    enter,
    leave,
    step,
)

__all__ = [
    "FREE", "STATIC", "CUTTING", "WITHDRAWING", "STATE_NAMES", "N_OUT", "N_PARAMS",
    "O_FORCE", "O_CUT", "O_PERP", "O_D_A", "O_D_N", "O_A", "O_N", "O_CRACK", "PAPER", "FRACTURE",
    "CUT_FIELDS", "FRACTURE_FIELDS", "SCALPEL_MODELS", "DEFAULT_MATERIAL", "HAPTIC_DT",
    "ScalpelParams", "ScalpelState", "Control", "blade_breadth", "enter", "leave", "step",
]
