"""Generated incisions: straight or arc-shaped, with blade angle, speed and hand tremor.

One generator serves ``cutkit trajectory`` (a trajectory file for a single
run) and ``cutkit sweep`` (trajectories made from parameters on the
workers), so a sweep and a single run with the same parameters cut along
the same trajectory.  See ``docs/trajectory-format.md``.

The incision runs between two skin points, ``start`` and ``end``.  With a
model they are first moved to the nearest point of the model's boundary,
and the inward direction is the mean inward normal of the boundary there.
The tip starts ``approach`` mm outside ``start``, presses in along the
blade to ``depth`` mm below the skin in ``press_time`` seconds, then moves
along the path (straight, or a circular arc that bulges sideways by
``arc_height`` mm) at ``speed`` mm/s.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from cutkit.cutting.trajectory import DEFAULT_BLADE_BREADTH, DEFAULT_BLADE_LENGTH, Trajectory
from cutkit.errors import InputError

#: Largest blade angle, degrees: beyond it the blade lies almost flat on the skin.
MAX_BLADE_ANGLE = 80.0
#: With tremor the trajectory has at least this many rows per tremor period.
ROWS_PER_TREMOR_PERIOD = 20
#: ``start`` or ``end`` farther from the model's surface than this fraction of the model's
#: bounding-box diagonal is refused: such a point is a typo or another model's coordinates.
FAR_FROM_SURFACE_FRACTION = 0.5


@dataclass
class Incision:
    """Parameters of a generated incision (lengths mm, times s, angles degrees).

    Attributes
    ----------
    start, end : (3,) float
        Skin points where the incision starts and ends.
    inward : (3,) float or None
        Direction into the tissue; taken from the model's boundary when None.
    arc_height : float
        Sideways bulge of the path at its middle (the arc's sagitta); 0 is a
        straight incision.  Positive bulges towards ``inward x (end - start)``.
    depth : float
        Depth of the tip below the skin, measured along ``inward``.
    approach : float
        Distance along the blade outside the skin where the tip starts.
    blade_angle : float
        Tilt of the blade from the skin normal within the cutting plane;
        positive leans the handle back so the tip leads.
    speed : float
        Speed of the tip along the path while it cuts, mm/s.
    press_time : float
        Time to press the blade in, s.
    rate : float
        Rows per second (raised to ``20 * tremor_frequency`` with tremor).
    tremor_amplitude : float
        Amplitude of the hand's tremor across the path, mm (0: none).
    tremor_frequency : float
        Centre frequency of the tremor, Hz (physiological tremor: 8-12 Hz).
    seed : int
        Seed of the tremor's random frequencies and phases.
    blade_length, blade_breadth : float
        Blade size stored on the trajectory, mm.
    """

    start: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    end: list = field(default_factory=lambda: [10.0, 0.0, 0.0])
    inward: list | None = None
    arc_height: float = 0.0
    depth: float = 5.0
    approach: float = 3.0
    blade_angle: float = 0.0
    speed: float = 20.0
    press_time: float = 0.3
    rate: float = 100.0
    tremor_amplitude: float = 0.0
    tremor_frequency: float = 10.0
    seed: int = 0
    blade_length: float = DEFAULT_BLADE_LENGTH
    blade_breadth: float = DEFAULT_BLADE_BREADTH

    @classmethod
    def from_dict(cls, values: dict, where: str = "incision") -> "Incision":
        """Parameters from a dict (a TOML table); one-line error naming a bad key.

        Parameters
        ----------
        values : dict
            Any of the attribute names.
        where : str
            Prefix of error messages (e.g. ``"spec.toml: trajectories[0].incision"``).
        """
        known = {f.name for f in fields(cls)}
        for key in values:
            if key not in known:
                raise InputError(f"{where}.{key}: unknown incision parameter (known: {', '.join(sorted(known))})")
        out = cls(**values)
        out.check(where)
        return out

    def check(self, where: str = "incision") -> None:
        """Raise a one-line :class:`InputError` naming the first bad parameter."""
        for name in ("start", "end") + (("inward",) if self.inward is not None else ()):
            v = getattr(self, name)
            try:
                arr = np.asarray(v, dtype=np.float64)
            except (TypeError, ValueError):
                arr = np.zeros(0)
            if arr.shape != (3,) or not np.all(np.isfinite(arr)):
                raise InputError(f"{where}.{name}: must be three finite numbers, got {v!r}")
        for name in ("arc_height", "depth", "approach", "blade_angle", "speed", "press_time", "rate",
                     "tremor_amplitude", "tremor_frequency", "blade_length", "blade_breadth"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise InputError(f"{where}.{name}: must be a finite number, got {v!r}")
        for name in ("speed", "press_time", "rate", "tremor_frequency", "blade_length", "blade_breadth"):
            if getattr(self, name) <= 0:
                raise InputError(f"{where}.{name}: must be > 0, got {getattr(self, name)!r}")
        for name in ("depth", "approach", "tremor_amplitude"):
            if getattr(self, name) < 0:
                raise InputError(f"{where}.{name}: must be >= 0, got {getattr(self, name)!r}")
        if abs(self.blade_angle) > MAX_BLADE_ANGLE:
            raise InputError(f"{where}.blade_angle: must lie within +-{MAX_BLADE_ANGLE:g} degrees, "
                             f"got {self.blade_angle!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int):
            raise InputError(f"{where}.seed: must be a whole number, got {self.seed!r}")
        if np.linalg.norm(np.subtract(self.end, self.start)) == 0:
            raise InputError(f"{where}: start and end coincide")
        if abs(self.arc_height) * 2 > np.linalg.norm(np.subtract(self.end, self.start)):
            raise InputError(f"{where}.arc_height: at most half the distance from start to end, "
                             f"got {self.arc_height!r}")

    def to_dict(self) -> dict:
        """Plain values (lists and floats), e.g. for a trajectory file's comment or a sweep key."""
        d = asdict(self)
        for k in ("start", "end", "inward"):
            if d[k] is not None:
                d[k] = [float(x) for x in d[k]]
        return d


def closest_boundary_point(model, point) -> tuple[np.ndarray, np.ndarray]:
    """The point of the model's boundary nearest to ``point`` and the inward normal there.

    Parameters
    ----------
    model : TetModel
    point : (3,) float
        mm.

    Returns
    -------
    surface_point : (3,) float64
    inward : (3,) float64
        Unit inward normal of the nearest boundary triangle.
    """
    from cutkit.mesh.topology import boundary_faces

    faces, _ = boundary_faces(np.asarray(model.tets, np.int64))
    x = np.asarray(model.points, np.float64)[faces]  # (f, 3, 3)
    q, d2 = _closest_on_triangles(np.asarray(point, np.float64), x[:, 0], x[:, 1], x[:, 2])
    i = int(np.argmin(d2))
    normal = np.cross(x[i, 1] - x[i, 0], x[i, 2] - x[i, 0])  # boundary faces face outwards
    return q[i], -normal / np.linalg.norm(normal)


def _closest_on_triangles(p, a, b, c):
    """Closest points on triangles (a, b, c), each (f, 3), to the point p; and the squared distances."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 / (va + vb + vc)
        v = vb * denom
        w = vc * denom
        q = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        # edges
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    q = np.where(((vc <= 0) & (d1 >= 0) & (d3 <= 0))[:, None], a + ab * t_ab[:, None], q)
    q = np.where(((vb <= 0) & (d2 >= 0) & (d6 <= 0))[:, None], a + ac * t_ac[:, None], q)
    q = np.where(((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0))[:, None], b + (c - b) * t_bc[:, None], q)
    # vertices
    q = np.where(((d1 <= 0) & (d2 <= 0))[:, None], a, q)
    q = np.where(((d3 >= 0) & (d4 <= d3))[:, None], b, q)
    q = np.where(((d6 >= 0) & (d5 <= d6))[:, None], c, q)
    diff = q - p
    return q, np.einsum("ij,ij->i", diff, diff)


def _xyz(v) -> str:
    return ",".join(f"{float(x):g}" for x in np.asarray(v).reshape(-1))


def _ends_and_inward(params: Incision, model):
    """Start and end (3,) float64 (on the model's surface when a model is given) and the inward direction (3,)."""
    start = np.asarray(params.start, np.float64)
    end = np.asarray(params.end, np.float64)
    inward = None if params.inward is None else np.asarray(params.inward, np.float64)
    if inward is not None and not (np.all(np.isfinite(inward)) and np.linalg.norm(inward) > 0):
        raise InputError(f"incision: inward must be a non-zero direction, got {_xyz(inward)}")
    if model is not None:
        given = {"start": start, "end": end}
        start, n_start = closest_boundary_point(model, start)
        end, n_end = closest_boundary_point(model, end)
        pts = np.asarray(model.points, np.float64)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        far = FAR_FROM_SURFACE_FRACTION * float(np.linalg.norm(hi - lo))
        for name, on in (("start", start), ("end", end)):
            dist = float(np.linalg.norm(given[name] - on))
            if dist > far:
                raise InputError(f"incision: {name} {_xyz(given[name])} is {dist:.0f} mm from the model's surface "
                                 f"(the model spans {', '.join(f'{a:g}..{b:g}' for a, b in zip(lo, hi))} mm in "
                                 "x, y, z); give points on or near its skin")
        if inward is None:
            inward = n_start + n_end
    if inward is None:
        raise InputError("incision: inward direction needed (give inward, or a model to take it from)")
    return start, end, inward


def _with_tremor(params: Incision, t, tip, a0, tau):
    """The tip (k, 3) float64 with the hand's tremor added: two sines, along a0 x tau and along a0."""
    rng = np.random.default_rng(int(params.seed))
    f = float(params.tremor_frequency) * (1.0 + rng.uniform(-0.1, 0.1, 2))
    phase = rng.uniform(0.0, 2.0 * math.pi, 2)
    across = np.cross(a0, tau)
    tip = tip + float(params.tremor_amplitude) * (
        np.sin(2 * math.pi * f[0] * t + phase[0])[:, None] * across
        + np.sin(2 * math.pi * f[1] * t + phase[1])[:, None] * a0)
    return tip


def incision(params: Incision, model=None) -> Trajectory:
    """The blade trajectory of an incision.

    Parameters
    ----------
    params : Incision
    model : TetModel, optional
        When given, ``start`` and ``end`` move to the nearest boundary
        points and, unless ``params.inward`` is set, the inward direction is
        the mean of the boundary's inward normals there.

    Returns
    -------
    Trajectory
        Rows at ``t = i / rate`` from 0 to ``press_time + path length / speed``:
        ``t`` (k,), ``tip``, ``a``, ``n`` (k, 3) float64.

    Raises
    ------
    InputError
        Bad parameters, or no inward direction (neither ``inward`` nor a model).
    """
    params.check()
    start, end, inward = _ends_and_inward(params, model)
    chord = end - start
    length = float(np.linalg.norm(chord))
    if length == 0:
        raise InputError(f"incision: start and end both move to the model's surface point {_xyz(start)}; give "
                         "points farther apart" if model is not None else
                         f"incision: start and end are the same point {_xyz(start)}")
    along = chord / length
    a0 = inward - np.dot(inward, along) * along
    if np.linalg.norm(a0) < 1e-9 * max(1.0, np.linalg.norm(inward)):
        raise InputError("incision: inward is parallel to the incision")
    a0 /= np.linalg.norm(a0)
    side = np.cross(a0, along)

    h = float(params.arc_height)
    if h == 0.0:
        path_length = length
    else:
        theta = 4.0 * math.atan(2.0 * abs(h) / length)
        radius = (length * length / 4.0 + h * h) / (2.0 * abs(h))
        path_length = radius * theta

    rate = float(params.rate)
    if params.tremor_amplitude > 0:
        rate = max(rate, ROWS_PER_TREMOR_PERIOD * float(params.tremor_frequency))
    press, cut = float(params.press_time), path_length / float(params.speed)
    steps = int(round((press + cut) * rate))
    t = np.arange(steps + 1, dtype=np.float64) / rate
    s = np.clip((t - press) / cut, 0.0, 1.0)  # fraction of the path

    # surface point q and unit tangent tau along the path
    if h == 0.0:
        q = start + s[:, None] * chord
        tau = np.tile(along, (t.shape[0], 1))
    else:
        sgn = 1.0 if h > 0 else -1.0
        b = sgn * side
        centre = 0.5 * (start + end) - (radius - abs(h)) * b
        phi = (s - 0.5) * theta
        q = centre + radius * (np.sin(phi)[:, None] * along + np.cos(phi)[:, None] * b)
        tau = np.cos(phi)[:, None] * along - np.sin(phi)[:, None] * b
        q[-1] = end if s[-1] == 1.0 else q[-1]

    ang = math.radians(float(params.blade_angle))
    a = math.cos(ang) * a0 + math.sin(ang) * tau
    n = math.cos(ang) * tau - math.sin(ang) * a0
    reach = float(params.depth) / math.cos(ang)  # along the blade to the depth below the skin
    p_out = start - float(params.approach) * a[0]
    p_in = start + reach * a[0]
    w_press = np.clip(t / press, 0.0, 1.0)[:, None]
    tip = np.where(t[:, None] <= press, (1.0 - w_press) * p_out + w_press * p_in, q + reach * a)

    if params.tremor_amplitude > 0:
        tip = _with_tremor(params, t, tip, a0, tau)

    return Trajectory(t=t, tip=tip, a=a, n=n, blade_length=float(params.blade_length),
                      blade_breadth=float(params.blade_breadth))
