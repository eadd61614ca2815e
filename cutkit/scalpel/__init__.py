"""The haptic scalpel force model of the paper's section 6."""

from cutkit.scalpel._kernels import (
    CUTTING,
    FREE,
    N_OUT,
    N_PARAMS,
    O_A,
    O_CUT,
    O_D_A,
    O_D_N,
    O_FORCE,
    O_N,
    O_PERP,
    STATE_NAMES,
    STATIC,
    WITHDRAWING,
)
from cutkit.scalpel.model import (
    CUT_FIELDS,
    DEFAULT_MATERIAL,
    HAPTIC_DT,
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
    "O_FORCE", "O_CUT", "O_PERP", "O_D_A", "O_D_N", "O_A", "O_N",
    "CUT_FIELDS", "DEFAULT_MATERIAL", "HAPTIC_DT",
    "ScalpelParams", "ScalpelState", "Control", "blade_breadth", "enter", "leave", "step",
]
