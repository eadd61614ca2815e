"""Cut and relax a model along a blade trajectory (the paper's Fig. 1 tasks joined)."""

from cutkit.simulate.run import HAPTIC_DT, SimulateOptions, simulate

__all__ = ["simulate", "SimulateOptions", "HAPTIC_DT"]
