"""Where a live view's camera looks: at the blade and the wound (``follow``), the whole model, or fixed.

``follow`` (the default of ``cutkit live``) aims at the blade's tip while
there is a blade, else at the cut surface, else at the whole model; it
frames a sphere around that point a little larger than the blade
(:data:`FOLLOW_BLADES`) together with the wound, and looks from the
handle's side, tilted across the blade plane and back along the cut
(:data:`FOLLOW_TILT`), so that one wall of the wound faces the camera.
Each frame moves the camera a fraction :data:`FOLLOW_EASE` of the way to
that view, so the hand's tremor does not shake the picture.
``model`` frames the whole tissue at every frame (the user may turn it);
``fixed`` leaves the camera where it was put (``camera_position`` or the
whole model at the start) and to the user's mouse.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cutkit.errors import InputError

__all__ = ["CAMERA_MODES", "CameraPose", "CameraRig", "follow_view", "FOLLOW_BLADES", "FOLLOW_TILT",
           "FOLLOW_EASE", "VIEW_ANGLE_DEG"]

#: The camera modes of a live window.
CAMERA_MODES = ("follow", "model", "fixed")
#: ``follow`` frames a sphere of this many blade lengths around the blade's tip (and the whole wound).
FOLLOW_BLADES = 0.6
#: ``follow``'s view direction, camera from the focus, in the blade's frame: weights of the handle's
#: side (``-a``), across the blade plane (``n x a``) and back along the cut (``-n``).  About 37
#: degrees across and 15 back: the wound's wall on one side faces the camera.
FOLLOW_TILT = (1.0, 0.8, 0.35)
#: Fraction of the way to the target view the camera moves at each frame.
FOLLOW_EASE = 0.25
#: Vertical view angle of the window's camera, degrees (VTK's default).
VIEW_ANGLE_DEG = 30.0


@dataclass
class CameraPose:
    """A camera: its position, the point it looks at and its up direction, (3,) float64 each, mm."""

    position: np.ndarray
    focal_point: np.ndarray
    up: np.ndarray

    def as_list(self) -> list:
        """``[position, focal_point, up]`` as tuples (pyvista's ``camera_position``)."""
        return [tuple(map(float, v)) for v in (self.position, self.focal_point, self.up)]


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 0 else v


def follow_view(tip, a, n, wound: np.ndarray | None, blade_length: float,
                view_angle_deg: float = VIEW_ANGLE_DEG) -> CameraPose:
    """The ``follow`` camera for a blade at ``tip`` (axis ``a``, edge ``n``) and a wound.

    Parameters
    ----------
    tip, a, n : (3,) float64
        The blade's tip, unit axis (handle to tip) and edge direction.
    wound : (k, 3) float64 or None
        Points of the cut surface (may be empty).
    blade_length : float
        mm.
    view_angle_deg : float
        The camera's vertical view angle.

    Returns
    -------
    CameraPose
        Looking at the point halfway between the tip and the wound's centre
        (the tip without a wound), moved a little up the blade, from far
        enough that a sphere around it holding the tip, the handle's end
        (where the window draws the force), every wound point and at least
        :data:`FOLLOW_BLADES` blade lengths fits the view.
    """
    tip, a, n = (np.asarray(v, np.float64) for v in (tip, a, n))
    focus = tip
    if wound is not None and len(wound):
        focus = 0.5 * (tip + 0.5 * (wound.min(axis=0) + wound.max(axis=0)))
    # up the blade: the skin around the wound, not its floor, in the middle of the picture
    focus = focus - 0.25 * FOLLOW_BLADES * float(blade_length) * a
    handle = tip - float(blade_length) * a  # where the force on the hand is drawn
    radius = max(FOLLOW_BLADES * float(blade_length), float(np.linalg.norm(tip - focus)),
                 float(np.linalg.norm(handle - focus)))
    if wound is not None and len(wound):
        radius = max(radius, float(np.sqrt(((wound - focus) ** 2).sum(axis=1).max())))
    w_out, w_across, w_back = FOLLOW_TILT
    b = _unit(np.cross(n, a))
    direction = _unit(-w_out * a + w_across * b - w_back * n)
    distance = radius / np.sin(np.radians(view_angle_deg) / 2.0)
    up = _unit(b - np.dot(b, direction) * direction)
    return CameraPose(focus + distance * direction, focus, up)


def _ease(old: CameraPose, new: CameraPose, weight: float) -> CameraPose:
    """``weight`` of the way from ``old`` to ``new``: focus, then the offset's direction and length."""
    focus = old.focal_point + weight * (new.focal_point - old.focal_point)
    off_old, off_new = old.position - old.focal_point, new.position - new.focal_point
    length = (1 - weight) * np.linalg.norm(off_old) + weight * np.linalg.norm(off_new)
    direction = _unit((1 - weight) * _unit(off_old) + weight * _unit(off_new))
    if not np.any(direction):
        direction = _unit(off_new)
    up = _unit((1 - weight) * old.up + weight * new.up)
    up = _unit(up - np.dot(up, direction) * direction)
    return CameraPose(focus + length * direction, focus, up if np.any(up) else new.up)


class CameraRig:
    """The camera of a live view, frame by frame.

    Parameters
    ----------
    mode : {"follow", "model", "fixed"}
    ease : float
        ``follow``: fraction of the way to the target view per frame (1: jump).

    Notes
    -----
    :meth:`update` returns what the view should do with its camera: a
    :class:`CameraPose` to set, ``"fit"`` to frame the whole model, or None
    to leave it.
    """

    def __init__(self, mode: str = "follow", ease: float = FOLLOW_EASE):
        if mode not in CAMERA_MODES:
            raise InputError(f"camera must be one of {', '.join(CAMERA_MODES)}, got {mode!r}")
        if not 0.0 < ease <= 1.0:
            raise InputError(f"camera ease must be in (0, 1], got {ease}")
        self.mode, self.ease = mode, float(ease)
        self.pose: CameraPose | None = None  # follow: the camera set last

    def update(self, frame):
        """The camera for ``frame`` (a :class:`~cutkit.live.views.LiveFrame`)."""
        if self.mode == "fixed":
            return None
        if self.mode == "model":
            return "fit"
        wound = frame.points[frame.cut_faces.ravel()] if frame.cut_faces.size else None
        if frame.tip is None:
            if wound is None:
                return "fit" if self.pose is None else None
            centre = 0.5 * (wound.min(axis=0) + wound.max(axis=0))
            target = CameraPose(centre + (self.pose.position - self.pose.focal_point), centre, self.pose.up) \
                if self.pose is not None else None
            if target is None:
                return "fit"
        else:
            target = follow_view(frame.tip, frame.a, frame.n, wound, frame.blade_length)
        self.pose = target if self.pose is None else _ease(self.pose, target, self.ease)
        return self.pose
