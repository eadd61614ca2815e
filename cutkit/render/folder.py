"""Read what a simulate run wrote: frame series, cut-surface series, blade path, summary."""

from __future__ import annotations

import csv
import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cutkit.errors import InputError


#: A picture's title calls the blade at rest when its tip moved less than this, mm ...
REST_TOLERANCE_MM = 1e-6
#: ... over this many seconds before the picture (the scalpel model keeps the state it had,
#: "cutting", while the hand holds still after a stroke).
REST_WINDOW_S = 0.05


@dataclass
class Folder:
    """An output folder of ``cutkit simulate``.

    Attributes
    ----------
    path : Path
    frames : list of (float, Path)
        Time (s) and ``.vtu`` file of each tissue frame, in time order.
    surfaces : list of (float, Path)
        Time and ``.vtp`` file of the cut surface at each frame (may be empty).
    path_t : (k,) float64
        Times of the blade's path, s (1 kHz rows of ``forces.csv``).
    path_tip : (k, 3) float64
        Blade tip, mm.
    path_state : list of str
        Scalpel state at each row (``free``, ``touching``, ``cutting``, ...).
    force : (k,) float64
        Magnitude of the force on the hand, N.
    summary : dict
        ``summary.json`` (empty when missing).
    label_names : dict
        Material name of each tissue label, from the folder's ``model.h5`` (empty when missing).
    """

    path: Path
    frames: list = field(default_factory=list)
    surfaces: list = field(default_factory=list)
    path_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    path_tip: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    path_state: list = field(default_factory=list)
    force: np.ndarray = field(default_factory=lambda: np.zeros(0))
    summary: dict = field(default_factory=dict)
    label_names: dict = field(default_factory=dict)

    def surface_at(self, t: float) -> Path | None:
        """The cut-surface file of the frame at time ``t`` (the last one not after it)."""
        best = None
        for ts, p in self.surfaces:
            if ts <= t + 1e-9:
                best = p
        return best

    def path_until(self, t: float) -> np.ndarray:
        """Blade tips up to time ``t``, (k, 3)."""
        return self.path_tip[self.path_t <= t + 1e-9]

    def state_at(self, t: float) -> str:
        if not self.path_state:
            return ""
        i = int(np.searchsorted(self.path_t, t + 1e-9)) - 1
        return self.path_state[max(i, 0)]

    def at_rest(self, t: float, window_s: float = REST_WINDOW_S) -> bool:
        """Whether the blade tip has not moved (by more than :data:`REST_TOLERANCE_MM`) over the
        ``window_s`` seconds up to ``t``: a hand that holds still after its stroke."""
        if self.path_t.size == 0 or t - float(self.path_t[0]) < window_s:
            return False
        recent = self.path_tip[(self.path_t >= t - window_s - 1e-9) & (self.path_t <= t + 1e-9)]
        return bool(recent.shape[0] > 1 and np.ptp(recent, axis=0).max() <= REST_TOLERANCE_MM)

    def force_at(self, t: float) -> float:
        if self.force.size == 0:
            return 0.0
        i = int(np.searchsorted(self.path_t, t + 1e-9)) - 1
        return float(self.force[max(i, 0)])


def _read_pvd(path: Path) -> list:
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise InputError(f"{path}: not a readable ParaView collection ({exc})") from None
    out = []
    for ds in root.iter("DataSet"):
        f = path.parent / ds.get("file", "")
        if f.is_file():
            out.append((float(ds.get("timestep", "0")), f))
    out.sort(key=lambda e: e[0])
    return out


def read_folder(path) -> Folder:
    """Read an output folder of ``cutkit simulate`` / ``cutkit demo``.

    Raises
    ------
    InputError
        Not a folder, or no ``cut.pvd`` with at least one frame in it.
    """
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"{path}: no such folder")
    pvd = path / "cut.pvd"
    if not pvd.is_file():
        raise InputError(f"{path}: not an output folder of cutkit simulate (no cut.pvd)")
    folder = Folder(path=path, frames=_read_pvd(pvd))
    if not folder.frames:
        raise InputError(f"{pvd}: the collection lists no frame")
    if (path / "cut_surface.pvd").is_file():
        folder.surfaces = _read_pvd(path / "cut_surface.pvd")
    forces = path / "forces.csv"
    if forces.is_file():
        with open(forces, newline="") as fh:
            rows = list(csv.reader(fh))
        if len(rows) > 1:
            head = rows[0]
            try:
                ti, si = head.index("t"), head.index("state")
                xi = [head.index(c) for c in ("tip_x", "tip_y", "tip_z")]
                fi = [head.index(c) for c in ("F_ext_x", "F_ext_y", "F_ext_z")]
                body = rows[1:]
                folder.path_t = np.array([float(r[ti]) for r in body])
                folder.path_tip = np.array([[float(r[i]) for i in xi] for r in body])
                folder.path_state = [r[si] for r in body]
                folder.force = np.linalg.norm(np.array([[float(r[i]) for i in fi] for r in body]), axis=1)
            except (ValueError, IndexError):
                raise InputError(f"{forces}: unexpected columns or values") from None
    if (path / "summary.json").is_file():
        try:
            folder.summary = json.loads((path / "summary.json").read_text())
        except ValueError:
            folder.summary = {}
    folder.label_names = _label_names(path / "model.h5")
    return folder


def _label_names(model_path: Path) -> dict:
    """``{label: material name}`` of a model file; empty when it is missing or unreadable."""
    if not model_path.is_file():
        return {}
    from cutkit.errors import CutkitError
    from cutkit.io.model_h5 import read_model

    try:
        mat = read_model(model_path).materials
    except (CutkitError, OSError):
        return {}
    return {int(lab): str(name) for lab, name in zip(mat.label, mat.name)}
