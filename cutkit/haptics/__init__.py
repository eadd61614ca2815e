"""The 1 kHz haptic scalpel service, its wire protocol and a client."""

from cutkit.haptics.client import ForceFrame, HapticsClient, run_bench, spawned_server
from cutkit.haptics.priority import raise_priority
from cutkit.haptics.server import (
    WATCHDOG_RAMP_S,
    WATCHDOG_TIMEOUT_S,
    HapticsServer,
    material_from_model,
)

__all__ = ["HapticsServer", "HapticsClient", "ForceFrame", "run_bench", "spawned_server",
           "material_from_model", "raise_priority", "WATCHDOG_TIMEOUT_S", "WATCHDOG_RAMP_S"]
