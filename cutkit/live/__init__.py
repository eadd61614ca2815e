"""Live cutting: pose sources that drive the blade and views that show the tissue.

``cutkit.live.sources`` and ``cutkit.live.views`` hold the two interfaces
(:class:`PoseSource`, :class:`View`) and the light sources;
``cutkit.live.window`` (pyvista) and ``cutkit.live.igtl`` (pyigtl) load
their libraries only when imported.
"""

from cutkit.live.sources import (
    HapticsPoseSource,
    MouseKeyboardPoseSource,
    Pose,
    PoseSource,
    TrajectoryPoseSource,
)
from cutkit.live.views import LiveFrame, View

__all__ = ["Pose", "PoseSource", "TrajectoryPoseSource", "MouseKeyboardPoseSource", "HapticsPoseSource",
           "LiveFrame", "View", "IGTLPoseSource", "IGTLPolyDataView", "IGTLEndpoint", "WindowView"]

_LAZY = {"IGTLPoseSource": "cutkit.live.igtl", "IGTLPolyDataView": "cutkit.live.igtl",
         "IGTLEndpoint": "cutkit.live.igtl", "WindowView": "cutkit.live.window"}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'cutkit.live' has no attribute {name!r}")
