"""OpenIGTLink: a tracked tool as a pose source, the cut tissue as POLYDATA.

3D Slicer (module *OpenIGTLinkIF*) or a PLUS server connects as a client to
the :class:`IGTLEndpoint` (``cutkit.live.igtl_server``, port 18944 by
default; several clients at once).  It sends the tool's TRANSFORM;
:class:`IGTLPoseSource` turns the newest one of its device name (from the
client that drives it) into a blade pose.  :class:`IGTLPolyDataView` sends
the deformed boundary and the cut surface back to every client as POLYDATA
messages with per-point normals and colours, at a capped rate, so Slicer
shows the cut, and the blade as a TRANSFORM.

Frames: Slicer and PLUS speak RAS (x towards the patient's Right, y
Anterior, z Superior); cutkit models are LPS (x Left, y Posterior, z
Superior), the frame of DICOM and of the volumes cutkit reads.
``frame="RAS"`` (default) flips x and y both ways; an optional
``registration`` (4x4, model LPS <- tracker frame after the flip; see
:func:`load_registration`) maps a tracker's space onto the model.  Units
are mm on both sides.

The wire format (headers, CRC64, STATUS, CAPABILITY, POLYDATA with
attributes) is ``cutkit.live.igtl_protocol``; its :class:`PolyDataMessage`
and :func:`decode_polydata` are what Python clients use to read the
surfaces (pyigtl 0.3 cannot unpack POLYDATA).
"""

from __future__ import annotations

import logging
import os
import time

import numpy as np
import pyigtl

from cutkit.errors import InputError
from cutkit.live.igtl_protocol import (
    POINT_NORMAL,
    POINT_RGBA,
    PolyDataAttribute,
    PolyDataMessage,
    decode_polydata,
    polydata_attributes,
)
from cutkit.live.igtl_server import DEFAULT_PORT, IGTLEndpoint
from cutkit.live.sources import Pose, make_pose
from cutkit.live.views import LiveFrame

__all__ = ["IGTLEndpoint", "IGTLPoseSource", "IGTLPolyDataView", "PolyDataMessage", "decode_polydata",
           "polydata_attributes", "pose_from_matrix", "tracker_to_model", "load_registration", "DEFAULT_PORT",
           "DEFAULT_TOOL", "RAS_TO_LPS", "FRAMES", "AXES"]

log = logging.getLogger("cutkit.live")

#: Default device name of the tracked blade's TRANSFORM (at most 20 bytes).
DEFAULT_TOOL = "ScalpelToReference"
#: RAS <-> LPS (its own inverse).
RAS_TO_LPS = np.diag([-1.0, -1.0, 1.0, 1.0])
#: Device names are at most this long on the wire (bytes).
MAX_NAME = 20
#: Coordinate frames a tracker may speak.
FRAMES = ("RAS", "LPS")
#: Tool axes the blade and its edge may follow.
AXES = ("x", "y", "z", "-x", "-y", "-z")
_AXES = {"x": 0, "y": 1, "z": 2}
#: Colour of the cut surface and of untextured tissue (cutkit.live.window's, repeated so that the
#: endpoint does not load VTK), RGBA in [0, 1] as POLYDATA's RGBA attribute holds it.
CUT_RGBA = (220 / 255, 30 / 255, 150 / 255, 1.0)
TISSUE_RGBA = (217 / 255, 153 / 255, 140 / 255, 1.0)
#: Names of the POLYDATA point attributes (Slicer lists them as the model's point arrays).
NORMALS_NAME, COLORS_NAME = "Normals", "Colors"


def _check_name(name: str, what: str) -> str:
    if not name or len(name.encode("utf-8")) > MAX_NAME:
        raise InputError(f"{what} {name!r} must be 1 to {MAX_NAME} bytes long")
    return name


def tracker_to_model(frame: str = "RAS", registration=None) -> np.ndarray:
    """The 4x4 map from the tracker's coordinates to the model's (LPS, mm).

    Parameters
    ----------
    frame : "RAS" or "LPS"
        Frame of the tracker's (or Slicer's) coordinates.
    registration : (4, 4) array-like, optional
        Model <- tracker registration applied after the frame change.

    Returns
    -------
    (4, 4) float64
    """
    if frame not in FRAMES:
        raise InputError(f"coordinate frame must be RAS or LPS, got {frame!r}")
    m = RAS_TO_LPS.copy() if frame == "RAS" else np.eye(4)
    if registration is not None:
        r = np.asarray(registration, np.float64)
        if r.shape != (4, 4) or not np.all(np.isfinite(r)) or abs(np.linalg.det(r[:3, :3])) < 1e-12:
            raise InputError("registration must be a finite, invertible 4x4 matrix")
        m = r @ m
    return m


def _axis(spec: str) -> tuple[int, float]:
    s = spec.strip().lower()
    sign = -1.0 if s.startswith("-") else 1.0
    col = _AXES.get(s.lstrip("+-"))
    if col is None:
        raise InputError(f"tool axis must be one of x, y, z, -x, -y, -z, got {spec!r}")
    return col, sign


def pose_from_matrix(matrix, axis: str = "-z", edge: str = "x", to_model=None):
    """Blade tip and directions from a tool's 4x4 pose matrix.

    Parameters
    ----------
    matrix : (4, 4) array-like
        Tool -> tracker transform (the TRANSFORM message's matrix), mm.
    axis : str
        Tool axis along the blade, handle to tip: ``"-z"`` (default), ``"z"``, ``"x"``, ...
    edge : str
        Tool axis the sharp edge faces (default ``"x"``); made perpendicular to ``axis``.
    to_model : (4, 4) array-like, optional
        Tracker -> model map (:func:`tracker_to_model`); default RAS -> LPS.

    Returns
    -------
    tip, a, n : (3,) float64
    """
    m = np.asarray(matrix, np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InputError("tool pose must be a finite 4x4 matrix")
    m = (RAS_TO_LPS if to_model is None else np.asarray(to_model, np.float64)) @ m
    ca, sa = _axis(axis)
    ce, se = _axis(edge)
    if ca == ce:
        raise InputError(f"tool axis {axis!r} and edge {edge!r} must be different axes")
    pose = make_pose(0.0, m[:3, 3], sa * m[:3, ca], se * m[:3, ce])
    return pose.tip, pose.a, pose.n


def load_registration(path) -> np.ndarray:
    """A 4x4 registration matrix from a file.

    Parameters
    ----------
    path : str or path-like
        ``.npy`` (a (4, 4) array), or text: 16 numbers in 4 rows (spaces or
        commas; ``#`` starts a comment), or 12 numbers (the last row taken as
        0 0 0 1).

    Returns
    -------
    (4, 4) float64
        Checked as :func:`tracker_to_model` checks it.

    Raises
    ------
    InputError
        A missing or unreadable file, or one that is not a finite invertible 4x4 matrix.
    """
    path = os.fspath(path)
    try:
        if path.lower().endswith(".npy"):
            m = np.load(path, allow_pickle=False)
        else:
            with open(path, encoding="utf-8") as f:
                text = [line.split("#", 1)[0].replace(",", " ") for line in f]
            m = np.array([float(x) for line in text for x in line.split()])
    except (OSError, ValueError, UnicodeDecodeError) as err:
        raise InputError(f"cannot read the registration {path}: {getattr(err, 'strerror', None) or err}") from None
    m = np.asarray(m, np.float64)
    if m.size == 12:
        m = np.vstack([m.reshape(3, 4), [0.0, 0.0, 0.0, 1.0]])
    if m.size != 16:
        raise InputError(f"registration {path} must hold a 4x4 matrix (16 numbers), not {m.size} numbers")
    m = m.reshape(4, 4)
    try:
        tracker_to_model("LPS", m)
    except InputError as err:
        raise InputError(f"registration {path}: {err}") from None
    return m


class _Owner:
    """Opens its own endpoint on ``port`` or shares ``endpoint``; closes only its own."""

    def _attach(self, port, endpoint, local_only, driver="first"):
        self._own = endpoint is None
        self.endpoint = IGTLEndpoint(port, local_only, driver=driver) if endpoint is None else endpoint

    def close(self) -> None:
        if self._own:
            self.endpoint.close()


class IGTLPoseSource(_Owner):
    """The blade pose from a tracked tool's OpenIGTLink TRANSFORM messages.

    Parameters
    ----------
    port : int
        Port of a new endpoint (ignored with ``endpoint``).
    device_name : str
        Device name of the tool's TRANSFORM (Slicer: the transform node's name).
    axis, edge : str
        Tool axes of the blade (handle to tip) and of the sharp edge; see
        :func:`pose_from_matrix`.
    frame : "RAS" or "LPS"
        Coordinates the tool's matrix is in (Slicer, PLUS: RAS).
    registration : (4, 4), optional
        Model <- tracker registration (:func:`tracker_to_model`).
    endpoint : IGTLEndpoint, optional
        Share an endpoint (with an :class:`IGTLPolyDataView`).
    local_only : bool
    driver : "first" or "latest"
        Which client drives the blade when several send ``device_name``
        (:class:`IGTLEndpoint`; ignored with ``endpoint``).
    clock : callable
        Wall clock stamped on each pose.
    """

    def __init__(self, port: int = DEFAULT_PORT, device_name: str = DEFAULT_TOOL, axis: str = "-z",
                 edge: str = "x", frame: str = "RAS", registration=None, endpoint: IGTLEndpoint | None = None,
                 local_only: bool = True, driver: str = "first", clock=time.time):
        self.device_name = _check_name(device_name, "tool device name")
        self.axis, self.edge = axis, edge
        if _axis(axis)[0] == _axis(edge)[0]:  # also checks both names
            raise InputError(f"tool axis {axis!r} and edge {edge!r} must be different axes")
        self.to_model = tracker_to_model(frame, registration)
        self.clock = clock
        self.finished = False
        self.rejected = 0  # TRANSFORMs that gave no pose
        self._attach(port, endpoint, local_only, driver)

    def poll(self) -> Pose | None:
        msg = self.endpoint.take(self.device_name)
        if msg is None or self.finished:
            return None
        if msg.message_type != "TRANSFORM":
            self.rejected += 1
            log.warning("OpenIGTLink: %s is a %s message, not a TRANSFORM; ignored", self.device_name,
                        msg.message_type)
            return None
        try:
            tip, a, n = pose_from_matrix(msg.matrix, self.axis, self.edge, self.to_model)
        except InputError as err:
            self.rejected += 1
            log.warning("OpenIGTLink: ignored a TRANSFORM of %s: %s", self.device_name, err)
            return None
        return Pose(float(self.clock()), tip, a, n, 0)

    def close(self) -> None:
        self.finished = True
        super().close()


#: The POLYDATA rate cap sends a frame that comes up to this share of a period before its slot:
#: the session's frames come at the same nominal rate (30 a second) with a jitter of a few ms, and a
#: cap measured from the last send skipped every frame that came a little early (gaps of two
#: periods, over 100 ms across a stroke's end).  The slots keep the cap's long-run rate.
SEND_EARLY_FRACTION = 0.25


class IGTLPolyDataView(_Owner):
    """Send the deformed boundary and the cut surface to every OpenIGTLink client (3D Slicer).

    Each shown frame (at most ``max_rate_hz`` a second on time slots one
    period apart, a frame up to :data:`SEND_EARLY_FRACTION` of a period
    early taking its slot; only while a client is connected) becomes two POLYDATA messages, ``tissue_name`` (the
    outer boundary) and ``cut_name`` (the cut surface), triangles over the
    points they use, in the client's frame, each point with two attributes:
    ``"Normals"`` (POINT NORMAL, unit, outward) and ``"Colors"`` (POINT RGBA
    in [0, 1]: the frame's texture colour or a plain tissue colour; the cut
    surface in the window's cut colour); plus a TRANSFORM ``blade_name``
    whose columns are the edge (x), ``n x a`` (y) and the blade's
    tip-to-handle direction (z), translation the tip, so that the same
    convention read back by :class:`IGTLPoseSource` (axis -z, edge x) gives
    the blade.  Messages not yet sent are replaced by newer ones.

    Parameters
    ----------
    port, endpoint, local_only : as for :class:`IGTLPoseSource`
    max_rate_hz : float
    tissue_name, cut_name, blade_name : str
        Device names (at most 20 bytes each).
    frame, registration : as for :class:`IGTLPoseSource` (the view sends the inverse map)
    driver : as for :class:`IGTLPoseSource`
    clock : callable
        Monotonic clock for the rate cap.
    """

    def __init__(self, port: int = DEFAULT_PORT, endpoint: IGTLEndpoint | None = None, max_rate_hz: float = 10.0,
                 tissue_name: str = "CutkitTissue", cut_name: str = "CutkitCutSurface",
                 blade_name: str = "CutkitBlade", frame: str = "RAS", registration=None,
                 local_only: bool = True, driver: str = "first", clock=time.monotonic):
        if not max_rate_hz > 0:
            raise InputError(f"POLYDATA rate must be positive, got {max_rate_hz}")
        self.names = tuple(_check_name(x, "device name") for x in (tissue_name, cut_name, blade_name))
        self.min_period = 1.0 / float(max_rate_hz)
        self.to_client = np.linalg.inv(tracker_to_model(frame, registration))
        self.clock = clock
        self.frames_sent = 0
        self._slot = -np.inf  # the rate cap's time slot of the last frame sent
        # compile (or load) the normals kernel now, not on a client thread while the session runs
        _SurfaceMessage("warm-up", np.eye(3), np.array([[0, 1, 2]]), None, None, np.eye(4)).content()
        self._attach(port, endpoint, local_only, driver)

    def show(self, frame: LiveFrame) -> None:
        now = self.clock()
        slot = self._slot + self.min_period
        if now < slot - SEND_EARLY_FRACTION * self.min_period or not self.endpoint.connected:
            return
        frame.check()
        self._slot = slot if slot >= now - self.min_period else now
        # copies (a few ms for 80k triangles): the surfaces are built and packed on the endpoint's
        # client threads, off the session's thread, from arrays the session may change
        points = frame.points.copy()
        rgb = None if frame.rgb is None else frame.rgb.copy()
        for name, faces, colour in zip(self.names[:2], (frame.boundary_faces, frame.cut_faces), (None, CUT_RGBA)):
            self.endpoint.send(_SurfaceMessage(name, points, faces.copy(), rgb, colour, self.to_client))
        if frame.tip is not None:
            m = np.eye(4)
            m[:3, 0], m[:3, 1], m[:3, 2] = frame.n, np.cross(frame.n, frame.a), -np.asarray(frame.a)
            m[:3, 3] = frame.tip
            self.endpoint.send(pyigtl.TransformMessage(self.to_client @ m, device_name=self.names[2]))
        self.frames_sent += 1


class _SurfaceMessage(PolyDataMessage):
    """A surface's POLYDATA, built (compacted, moved to the client's frame, normals, colours) when first packed.

    Parameters
    ----------
    name : str
        Device name.
    points : (n, 3) float64
        All the frame's points (model frame).
    faces : (f, 3) int64
        The surface's triangles, indices into ``points``.
    rgb : (n, 3) uint8 or None
        Texture colour per point.
    colour : 4 floats or None
        One RGBA for every point; None: ``rgb``, else the plain tissue colour.
    to_client : (4, 4)
        Model -> client map.
    """

    def __init__(self, name, points, faces, rgb, colour, to_client):
        super().__init__(device_name=name)
        self._parts = (points, faces, rgb, colour, np.asarray(to_client, np.float64))

    def content(self) -> bytes:
        if self._parts is not None:
            self._build(*self._parts)
            self._parts = None
        return super().content()

    def _build(self, points, faces, rgb, colour, to_client) -> None:
        from cutkit.live._kernels import vertex_normals

        used = np.zeros(points.shape[0], bool)
        used[faces.ravel()] = True
        index = np.flatnonzero(used)
        renumber = np.cumsum(used) - 1
        tris = np.ascontiguousarray(renumber[faces], np.int64)
        pts = np.ascontiguousarray(points[index])
        normals = np.empty((len(index), 3), np.float32)
        vertex_normals(pts, tris, normals)
        r, t = to_client[:3, :3], to_client[:3, 3]
        normals = normals @ np.linalg.inv(r).astype(np.float32)  # normals map by the inverse transpose
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)
        rgba = np.empty((len(index), 4), np.float32)
        if colour is None and rgb is not None:
            rgba[:, :3] = rgb[index] / np.float32(255.0)
            rgba[:, 3] = 1.0
        else:
            rgba[:] = TISSUE_RGBA if colour is None else colour
        cells = np.empty((tris.shape[0], 4), np.uint32)
        cells[:, 0] = 3
        cells[:, 1:] = tris
        self.points = (pts @ r.T + t).astype(np.float32)
        self.polygons = cells.ravel()
        self.attributes = [PolyDataAttribute(NORMALS_NAME, POINT_NORMAL, normals),
                           PolyDataAttribute(COLORS_NAME, POINT_RGBA, rgba)]
