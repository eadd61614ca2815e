"""Views: where a live session's frames go.

Every view has one interface, :class:`View`: ``show(frame)`` presents one
:class:`LiveFrame` (a view may skip frames to keep to its own rate) and
``close()`` ends it.  A frame is plain arrays, so a view knows nothing of
the tissue model behind it.

Views: ``cutkit.live.window.WindowView`` (a VTK window, or off-screen) and
``cutkit.live.igtl.IGTLPolyDataView`` (OpenIGTLink POLYDATA to 3D Slicer).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from cutkit.errors import InputError

__all__ = ["LiveFrame", "View", "blade_quad", "compact_faces", "RATE_KEYS"]

#: Keys of :attr:`LiveFrame.rates` that views show.
RATE_KEYS = ("haptic_hz", "relax_passes_per_s", "fps")


@dataclass
class LiveFrame:
    """One frame of a live session.

    Attributes
    ----------
    points : (n, 3) float64
        Deformed node positions, mm.
    boundary_faces : (f, 3) int64
        The tissue's outer boundary triangles (without the cut surface), indices into ``points``.
    cut_faces : (c, 3) int64
        The cut surface's triangles (both lips), indices into ``points``.
    rgb : (n, 3) uint8 or None
        Texture colour per node; None = a plain tissue colour.  Not changed in place once
        shown: a window uploads the colours again only for another array or another size.
    tip, a, n : (3,) float64 or None
        Blade pose (trajectory convention: ``a`` handle to tip, ``n`` towards
        the edge); ``tip`` None = no blade to draw.
    blade_length, blade_breadth : float
        Blade size, mm.
    force : (3,) float64
        Force on the hand, N.
    rates : dict
        ``haptic_hz``, ``relax_passes_per_s``, ``fps`` (any may be missing).
    tets_cut : int
        Tetrahedra cut so far.
    t : float
        Session time, s.
    """

    points: np.ndarray
    boundary_faces: np.ndarray
    cut_faces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    rgb: np.ndarray | None = None
    tip: np.ndarray | None = None
    a: np.ndarray | None = None
    n: np.ndarray | None = None
    blade_length: float = 20.0
    blade_breadth: float = 5.0
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rates: dict = field(default_factory=dict)
    tets_cut: int = 0
    t: float = 0.0

    def check(self) -> "LiveFrame":
        """Check shapes, dtypes and indices; returns self.  Raises InputError naming the problem."""
        p = self.points
        if not (isinstance(p, np.ndarray) and p.ndim == 2 and p.shape[1] == 3 and p.dtype == np.float64):
            raise InputError(f"frame points must be an (n, 3) float64 array, got {_desc(p)}")
        n = p.shape[0]
        for name in ("boundary_faces", "cut_faces"):
            f = getattr(self, name)
            if not (isinstance(f, np.ndarray) and f.ndim == 2 and f.shape[1] == 3 and f.dtype == np.int64):
                raise InputError(f"frame {name} must be an (f, 3) int64 array, got {_desc(f)}")
            if f.size and (f.min() < 0 or f.max() >= n):
                raise InputError(f"frame {name} index out of range [0, {n})")
        if self.rgb is not None and not (isinstance(self.rgb, np.ndarray) and self.rgb.shape == (n, 3)
                                         and self.rgb.dtype == np.uint8):
            raise InputError(f"frame rgb must be an ({n}, 3) uint8 array or None, got {_desc(self.rgb)}")
        if self.tip is not None:
            for name in ("tip", "a", "n"):
                v = getattr(self, name)
                if v is None or np.shape(v) != (3,) or not np.all(np.isfinite(v)):
                    raise InputError(f"frame blade {name} must be a finite (3,) vector")
        if np.shape(self.force) != (3,):
            raise InputError("frame force must be a (3,) vector")
        return self


def _desc(x) -> str:
    if isinstance(x, np.ndarray):
        return f"{x.dtype} array of shape {x.shape}"
    return type(x).__name__


@runtime_checkable
class View(Protocol):
    """The interface every view has."""

    def show(self, frame: LiveFrame) -> None:
        """Present ``frame`` (or skip it to keep to the view's own rate)."""

    def close(self) -> None:
        """End the view (close windows and sockets)."""


def blade_quad(tip, a, n, length: float, breadth: float) -> np.ndarray:
    """Corners of the blade rectangle (docs/trajectory-format.md).

    Parameters
    ----------
    tip, a, n : (3,) float
        Tip, unit axis (handle to tip), unit edge direction.
    length, breadth : float
        mm.

    Returns
    -------
    (4, 3) float64
        tip, tip - length a, tip - length a - breadth n, tip - breadth n.
    """
    tip = np.asarray(tip, np.float64)
    la = length * np.asarray(a, np.float64)
    bn = breadth * np.asarray(n, np.float64)
    return np.array([tip, tip - la, tip - la - bn, tip - bn])


def compact_faces(points, faces) -> tuple[np.ndarray, np.ndarray]:
    """The points ``faces`` use and the faces renumbered over them.

    Parameters
    ----------
    points : (n, 3) float64
    faces : (f, 3) int64

    Returns
    -------
    points : (m, 3) float64
        The used points, in increasing original index.
    faces : (f, 3) int64
        Indices into the returned points.
    """
    if faces.size == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    used, inverse = np.unique(faces.ravel(), return_inverse=True)
    return points[used], inverse.reshape(-1, 3).astype(np.int64)
