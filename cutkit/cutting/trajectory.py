"""Scalpel trajectory files: the recorded pose of the blade over time.

A trajectory is a CSV file with a header naming the columns ``t`` (s),
``x, y, z`` (blade tip, mm, model coordinates), ``ax, ay, az`` (unit
vector along the blade, from the handle to the tip) and ``nx, ny, nz``
(unit vector in the blade plane, perpendicular to ``a``, pointing where
the sharp edge faces).  Lines starting with ``#`` are comments.  The
format is described in ``docs/trajectory-format.md``.

The blade itself is the rectangle spanned by ``-a`` (``blade_length``
back from the tip) and ``-n`` (``blade_breadth`` back from the edge); its
size is not in the file but an option of the reader.
"""

from __future__ import annotations

import csv
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cutkit.errors import InputError, TrajectoryError
from cutkit.io.atomic import atomic_output

__all__ = [
    "COLUMNS",
    "DEFAULT_BLADE_LENGTH",
    "DEFAULT_BLADE_BREADTH",
    "UNIT_EXACT",
    "NORMALIZE_TOLERANCE",
    "ORTHO_EXACT",
    "ORTHO_TOLERANCE",
    "Trajectory",
    "read_trajectory",
    "write_trajectory",
    "straight_incision",
]

#: Column names, in the order :func:`write_trajectory` writes them.
COLUMNS = ("t", "x", "y", "z", "ax", "ay", "az", "nx", "ny", "nz")

#: Default blade length along ``a`` (mm) and breadth along ``n`` (mm).
DEFAULT_BLADE_LENGTH = 20.0
DEFAULT_BLADE_BREADTH = 5.0

#: A direction whose length differs from 1 by at most this is taken as is
#: (rounding of a printed value); beyond it, up to ``normalize_tolerance``,
#: it is normalised with a warning; beyond that the row is an error.
UNIT_EXACT = 1e-9
#: Default ``normalize_tolerance`` of :func:`read_trajectory`: largest
#: accepted | |v| - 1 | of a direction before the row is rejected.
NORMALIZE_TOLERANCE = 1e-3

#: | a . n | at most this: taken as perpendicular; up to ``ORTHO_TOLERANCE``
#: n is re-orthogonalised against a with a warning; beyond it an error.
ORTHO_EXACT = 1e-9
ORTHO_TOLERANCE = 1e-3


@dataclass
class Trajectory:
    """Blade poses at increasing times (struct of arrays).

    Attributes
    ----------
    t : (k,) float64
        Strictly increasing times, s.
    tip : (k, 3) float64
        Blade tip, mm.
    a : (k, 3) float64
        Unit vector along the blade, handle to tip.
    n : (k, 3) float64
        Unit vector in the blade plane, perpendicular to ``a``, towards the
        sharp edge.
    blade_length, blade_breadth : float
        Size of the blade, mm.
    """

    t: np.ndarray
    tip: np.ndarray
    a: np.ndarray
    n: np.ndarray
    blade_length: float = DEFAULT_BLADE_LENGTH
    blade_breadth: float = DEFAULT_BLADE_BREADTH

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time from the first to the last row, s."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0

    def pose_at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Blade pose at time ``t``, interpolated between the two rows around it.

        The tip is interpolated linearly; ``a`` and ``n`` linearly and then
        renormalised, ``n`` re-orthogonalised against ``a`` (for the small
        rotations between rows at 100 Hz and more this is indistinguishable
        from spherical interpolation).  Times before the first or after the
        last row give the first or last pose.

        Returns
        -------
        tip, a, n : (3,) float64
        """
        if len(self) == 0:
            raise ValueError("empty trajectory")
        t = float(t)
        i = int(np.searchsorted(self.t, t, side="right")) - 1
        if i < 0:
            return self.tip[0].copy(), self.a[0].copy(), self.n[0].copy()
        if i >= len(self) - 1:
            return self.tip[-1].copy(), self.a[-1].copy(), self.n[-1].copy()
        w = (t - self.t[i]) / (self.t[i + 1] - self.t[i])
        tip = (1.0 - w) * self.tip[i] + w * self.tip[i + 1]
        near = i if w < 0.5 else i + 1
        a = (1.0 - w) * self.a[i] + w * self.a[i + 1]
        length = np.linalg.norm(a)
        if length < MIN_BLEND_LENGTH:
            # the axis turns by (nearly) half a turn between the rows: no rotation between them
            # is the shorter one, so the blade keeps the nearer row's axis and edge
            return tip, self.a[near].copy(), self.n[near].copy()
        a /= length
        n = (1.0 - w) * self.n[i] + w * self.n[i + 1]
        n -= np.dot(n, a) * a
        length = np.linalg.norm(n)
        if length < MIN_BLEND_LENGTH:
            # the edge direction reverses between the rows (a stroke drawn back): likewise
            n = self.n[near] - np.dot(self.n[near], a) * a
            length = np.linalg.norm(n)
        n /= length
        return tip, a, n


#: Below this length, the blend of two rows' unit vectors (the blade axis ``a`` or the edge
#: direction ``n``) has no direction worth normalising: the rows point (nearly) opposite ways,
#: a turn of more than about 179.9 degrees in one row interval, and the nearer row's vector is
#: used instead (:meth:`Trajectory.pose_at`).
MIN_BLEND_LENGTH = 1e-3


def _check_unit(v, name, where, tol):
    length = math.sqrt(float(np.dot(v, v)))
    dev = abs(length - 1.0)
    if dev <= UNIT_EXACT:
        return v
    if dev > tol:
        raise TrajectoryError(
            f"{where}: vector {name} has length {length:.6g}, expected 1 within {tol:g}"
        )
    warnings.warn(f"{where}: vector {name} has length {length:.9g}; normalised", stacklevel=5)
    return v / length


def read_trajectory(
    path: str | os.PathLike,
    normalize_tolerance: float = NORMALIZE_TOLERANCE,
    ortho_tolerance: float = ORTHO_TOLERANCE,
    blade_length: float = DEFAULT_BLADE_LENGTH,
    blade_breadth: float = DEFAULT_BLADE_BREADTH,
) -> Trajectory:
    """Read and check a trajectory CSV file.

    Parameters
    ----------
    path : path-like
        The CSV file (see ``docs/trajectory-format.md``).
    normalize_tolerance : float
        Largest accepted | |v| - 1 | of ``a`` and ``n``; directions off by
        more than :data:`UNIT_EXACT` but within it are normalised with a
        warning.
    ortho_tolerance : float
        Largest accepted | a . n | (after normalisation); ``n`` off by more
        than :data:`ORTHO_EXACT` but within it is re-orthogonalised against
        ``a`` with a warning.
    blade_length, blade_breadth : float
        Blade size, mm, stored on the result.

    Returns
    -------
    Trajectory

    Raises
    ------
    TrajectoryError
        One line naming the file and line number of the first bad header
        or row.
    """
    path = Path(path)
    if not (blade_length > 0 and blade_breadth > 0):
        raise TrajectoryError(
            f"{path}: blade length and breadth must be positive, got {blade_length} and {blade_breadth}"
        )
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise TrajectoryError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TrajectoryError(f"{path}: cannot read: {exc}") from None

    header = None
    cols = None
    rows = []
    prev_t = -math.inf
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        where = f"{path}:{lineno}"
        fields = [f.strip() for f in next(csv.reader([stripped]))]
        if header is None:
            header = fields
            cols = _header_columns(header, where)
            continue
        rows.append(_parse_row(fields, cols, where, prev_t, normalize_tolerance, ortho_tolerance))
        prev_t = rows[-1][0]
    if header is None:
        raise TrajectoryError(f"{path}: no header line (expected {','.join(COLUMNS)})")
    if not rows:
        raise TrajectoryError(f"{path}: no rows after the header")
    return Trajectory(
        t=np.array([r[0] for r in rows], dtype=np.float64),
        tip=np.array([r[1] for r in rows], dtype=np.float64),
        a=np.array([r[2] for r in rows], dtype=np.float64),
        n=np.array([r[3] for r in rows], dtype=np.float64),
        blade_length=float(blade_length),
        blade_breadth=float(blade_breadth),
    )


def _header_columns(header: list, where: str) -> list:
    """Index in ``header`` of each of :data:`COLUMNS`; one line naming what is wrong otherwise."""
    missing = [c for c in COLUMNS if c not in header]
    extra = [c for c in header if c not in COLUMNS]
    dup = sorted({c for c in header if header.count(c) > 1})
    if missing or extra or dup:
        parts = []
        if missing:
            parts.append("missing " + ", ".join(missing))
        if extra:
            parts.append("unknown " + ", ".join(extra))
        if dup:
            parts.append("repeated " + ", ".join(dup))
        raise TrajectoryError(
            f"{where}: header must name the columns {','.join(COLUMNS)} ({'; '.join(parts)})"
        )
    return [header.index(c) for c in COLUMNS]


def _parse_row(fields: list, cols: list, where: str, prev_t: float, normalize_tolerance: float,
               ortho_tolerance: float) -> tuple:
    """One checked row: (t, tip (3,), a (3,), n (3,)) with a and n unit and perpendicular."""
    if len(fields) != len(COLUMNS):
        raise TrajectoryError(f"{where}: expected {len(COLUMNS)} values, got {len(fields)}")
    try:
        values = [float(fields[c]) for c in cols]
    except ValueError:
        bad = next(fields[c] for c in cols if not _is_float(fields[c]))
        raise TrajectoryError(f"{where}: not a number: {bad!r}") from None
    for name, v in zip(COLUMNS, values):
        if not math.isfinite(v):
            raise TrajectoryError(f"{where}: {name} is not finite ({v})")
    t = values[0]
    if not t > prev_t:
        raise TrajectoryError(f"{where}: t = {t:g} does not increase (previous row t = {prev_t:g})")
    tip = np.array(values[1:4])
    a = _check_unit(np.array(values[4:7]), "a", where, normalize_tolerance)
    n = _check_unit(np.array(values[7:10]), "n", where, normalize_tolerance)
    dot = float(np.dot(a, n))
    if abs(dot) > ORTHO_EXACT:
        if abs(dot) > ortho_tolerance:
            raise TrajectoryError(
                f"{where}: a and n are not perpendicular (a.n = {dot:.6g}, tolerance {ortho_tolerance:g})"
            )
        warnings.warn(f"{where}: a.n = {dot:.3g}; n re-orthogonalised", stacklevel=3)
        n = n - dot * a
        n /= np.linalg.norm(n)
    return t, tip, a, n


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def write_trajectory(path: str | os.PathLike, traj: Trajectory, comment: str | None = None) -> None:
    """Write ``traj`` as a trajectory CSV file, atomically.

    Values are written with ``repr`` precision so that reading the file
    back gives the same floats.

    Parameters
    ----------
    path : path-like
    traj : Trajectory
    comment : str, optional
        Written as ``#`` lines before the header (one per line of text).
    """
    t = np.asarray(traj.t, dtype=np.float64)
    k = t.shape[0] if t.ndim == 1 else -1
    parts = [t.reshape(-1, 1)]
    for name in ("tip", "a", "n"):
        v = np.asarray(getattr(traj, name), dtype=np.float64)
        if v.shape != (k, 3):
            raise InputError(f"trajectory {name} must have shape ({k}, 3) to match t, got {v.shape}")
        parts.append(v)
    data = np.hstack(parts)
    if not np.all(np.isfinite(data)):
        raise InputError("trajectory contains NaN or infinite values")
    if k > 1 and not np.all(np.diff(t) > 0):
        raise InputError("trajectory times must increase strictly")
    lines = []
    if comment:
        lines += [f"# {c}".rstrip() for c in comment.splitlines()]
    lines.append(",".join(COLUMNS))
    lines += [",".join(repr(float(v)) for v in row) for row in data]
    with atomic_output(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")


def straight_incision(
    start,
    end,
    inward,
    depth: float = 10.0,
    approach: float = 5.0,
    press_time: float = 0.5,
    cut_time: float = 2.0,
    rate: float = 100.0,
    blade_length: float = DEFAULT_BLADE_LENGTH,
    blade_breadth: float = DEFAULT_BLADE_BREADTH,
) -> Trajectory:
    """A straight incision: press the blade in, then draw it along the skin.

    The blade is held perpendicular to the skin (``a`` = ``inward``) with
    its sharp edge facing the direction of the cut (``n`` along
    ``end - start``).  The tip starts ``approach`` mm outside the skin
    point ``start``, moves in to ``depth`` mm below it in ``press_time``
    seconds, then moves parallel to the skin to ``depth`` mm below ``end``
    in ``cut_time`` seconds, at constant speed in each phase.

    Parameters
    ----------
    start, end : (3,) float
        Skin points where the incision starts and ends, mm.
    inward : (3,) float
        Direction into the tissue (the inward skin normal); made
        perpendicular to ``end - start``.
    depth, approach : float
        mm.
    press_time, cut_time : float
        s.
    rate : float
        Rows per second.

    Returns
    -------
    Trajectory
        Rows at ``t = i / rate`` from 0 to ``press_time + cut_time``.
    """
    start = np.asarray(start, dtype=np.float64)
    end = np.asarray(end, dtype=np.float64)
    along = end - start
    length = np.linalg.norm(along)
    if length == 0:
        raise ValueError("start and end coincide")
    along /= length
    a = np.asarray(inward, dtype=np.float64)
    a = a - np.dot(a, along) * along
    if np.linalg.norm(a) == 0:
        raise ValueError("inward is parallel to the incision")
    a /= np.linalg.norm(a)
    total = press_time + cut_time
    steps = int(round(total * rate))
    t = np.arange(steps + 1, dtype=np.float64) / rate
    p_out = start - approach * a
    p_in = start + depth * a
    p_end = end + depth * a
    w_press = np.clip(t / press_time, 0.0, 1.0)[:, None]
    w_cut = np.clip((t - press_time) / cut_time, 0.0, 1.0)[:, None]
    tip = np.where(
        t[:, None] <= press_time,
        (1 - w_press) * p_out + w_press * p_in,
        (1 - w_cut) * p_in + w_cut * p_end,
    )
    k = t.shape[0]
    return Trajectory(
        t=t,
        tip=tip,
        a=np.tile(a, (k, 1)),
        n=np.tile(along, (k, 1)),
        blade_length=blade_length,
        blade_breadth=blade_breadth,
    )
