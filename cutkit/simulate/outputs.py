"""What ``cutkit simulate`` writes: frames, the cut surface, forces, pictures.

Every file is written to a temporary name and renamed, and the ``.pvd``
collections are rewritten after each frame, so an interrupted run leaves
complete frames and valid collections for what was written.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from cutkit.io.atomic import atomic_output, write_text_atomic
from cutkit.io.series import write_pvd

#: Columns of forces.csv (N, mm, s); see docs/simulate.md.
FORCE_COLUMNS = ("t", "state", "F_ext_x", "F_ext_y", "F_ext_z", "F_cut_a", "F_cut_n", "d_a",
                 "tip_x", "tip_y", "tip_z", "proxy_x", "proxy_y", "proxy_z")


class SurfaceSeries:
    """``<out>/surface/NNNN.vtp`` and ``<out>/<name>.pvd``: the cut surface per frame (polydata)."""

    def __init__(self, out_dir, name: str = "cut_surface"):
        self.out_dir = Path(out_dir)
        self.dir = self.out_dir / "surface"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.pvd_path = self.out_dir / f"{name}.pvd"
        self._entries: list[tuple[float, str]] = []

    def write(self, time: float, points: np.ndarray, faces: np.ndarray, point_data: dict | None = None) -> Path:
        """Write the triangles ``faces`` (k, 3) int64 over ``points`` (n, 3) float64 (unused points dropped)."""
        import pyvista as pv

        used, inverse = np.unique(faces.ravel(), return_inverse=True)
        tri = inverse.reshape(-1, 3)
        cells = np.hstack([np.full((tri.shape[0], 1), 3), tri]).astype(np.int64).ravel()
        poly = pv.PolyData(np.ascontiguousarray(points[used], np.float64), cells if tri.size else None)
        for key, arr in (point_data or {}).items() if used.size else ():
            poly.point_data[key] = np.asarray(arr)[used]
        path = self.dir / f"{len(self._entries):04d}.vtp"
        with atomic_output(path) as tmp:
            poly.save(str(tmp))
        self._entries.append((float(time), f"surface/{path.name}"))
        self._write_pvd()
        return path

    def _write_pvd(self) -> None:
        write_pvd(self.pvd_path, self._entries)

    def close(self) -> None:
        self._write_pvd()


class ForceLog:
    """Rows of :data:`FORCE_COLUMNS`, kept in preallocated arrays and written as CSV."""

    def __init__(self, capacity: int):
        self.values = np.zeros((max(int(capacity), 1), len(FORCE_COLUMNS)))
        self.n = 0

    def add(self, t, state, f_ext, f_cut_a, f_cut_n, d_a, tip, proxy) -> None:
        if self.n == self.values.shape[0]:
            self.values = np.concatenate([self.values, np.zeros_like(self.values)])
        row = self.values[self.n]
        row[0] = t
        row[1] = state
        row[2:5] = f_ext
        row[5] = f_cut_a
        row[6] = f_cut_n
        row[7] = d_a
        row[8:11] = tip
        row[11:14] = proxy
        self.n += 1

    @property
    def rows(self) -> np.ndarray:
        return self.values[:self.n]

    def write(self, path) -> None:
        from cutkit.scalpel import STATE_NAMES

        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(FORCE_COLUMNS)
        for r in self.rows:
            w.writerow([f"{r[0]:.4f}", STATE_NAMES[int(r[1])]] + [f"{v:.6g}" for v in r[2:]])
        write_text_atomic(path, buf.getvalue())


def render_picture(path, points: np.ndarray, tets: np.ndarray, rgb: np.ndarray | None, focal, view_dir, up,
                   distance: float, title: str | None = None, size=(1200, 900)) -> None:
    """Off-screen picture of the tissue surface, coloured by its texture.

    Parameters
    ----------
    points : (n, 3) float64
    tets : (m, 4) int64
    rgb : (n, 3) uint8 or None
        Texture colour per node; a flat tissue colour without.
    focal : (3,) float
        Point looked at, mm.
    view_dir : (3,) float
        Direction the camera looks along.
    up : (3,) float
    distance : float
        Camera distance from ``focal``, mm.
    """
    import pyvista as pv
    import vtk

    pv.OFF_SCREEN = True
    # Without a display VTK tries X first and logs a warning before it falls
    # back to off-screen rendering; the picture is fine, so keep stderr quiet.
    vtk.vtkLogger.SetStderrVerbosity(vtk.vtkLogger.VERBOSITY_ERROR)
    grid = pv.UnstructuredGrid({pv.CellType.TETRA: np.ascontiguousarray(tets, np.int64)},
                               np.ascontiguousarray(points, np.float64))
    if rgb is not None:
        grid.point_data["texture_rgb"] = np.asarray(rgb, np.uint8)
    try:
        surf = grid.extract_surface(algorithm="dataset_surface")
    except TypeError:  # pyvista before the keyword existed
        surf = grid.extract_surface()
    pl = pv.Plotter(off_screen=True, window_size=list(size))
    pl.set_background("white")
    if rgb is not None:
        pl.add_mesh(surf, scalars="texture_rgb", rgb=True, smooth_shading=False)
    else:
        pl.add_mesh(surf, color=(0.85, 0.6, 0.55))
    if title:
        pl.add_text(title, font_size=10, color="black")
    view_dir = np.asarray(view_dir, np.float64)
    view_dir = view_dir / np.linalg.norm(view_dir)
    focal = np.asarray(focal, np.float64)
    pl.camera_position = [tuple(focal - distance * view_dir), tuple(focal), tuple(np.asarray(up, np.float64))]
    with atomic_output(path) as tmp:
        pl.screenshot(str(tmp))
    pl.close()


__all__ = ["SurfaceSeries", "ForceLog", "FORCE_COLUMNS", "render_picture"]
