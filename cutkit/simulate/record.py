"""Recording a session: frames and cut surface, forces, the poses acted on, the summary, the cut model.

Each recorder is a view of the :class:`~cutkit.simulate.session.Session`:
it reads the one mesh store and writes files, atomically (every file goes
to a temporary name and is renamed; the ``.pvd`` collections are valid
after every frame), so a session stopped at any point leaves a valid
recording.
"""

from __future__ import annotations

import json
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path

import numpy as np


#: Frames handed to the writer thread and not yet written, at most (each holds a copy of the tissue's
#: arrays, about 10 MB on the demo knee): the next frame waits for the oldest.
FRAMES_IN_FLIGHT = 2


class FrameRecorder:
    """``frames/NNNN.vtu`` + ``cut.pvd`` and ``surface/NNNN.vtp`` + ``cut_surface.pvd``.

    :meth:`show` copies the tissue's arrays under the session's lock and hands them to one writer
    thread, which writes the frames in order while the session goes on: VTK compresses a frame
    (zlib) without holding the GIL, about 150 ms for the demo knee's 172k tets, most of a run's
    output time.  What is written is the copy, so writing never changes what is simulated.
    :meth:`close` waits for every frame; a write that failed raises there or at the next
    :meth:`show`.
    """

    def __init__(self, session, out_dir):
        from cutkit.io.series import SeriesWriter
        from cutkit.simulate.outputs import SurfaceSeries

        self.session = session
        self.series = SeriesWriter(Path(out_dir), "cut")
        self.surface = SurfaceSeries(out_dir)
        self.colours = NodeColours(session.model, session.cut_mesh)
        self._writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cutkit-frames")
        self._pending: deque = deque()
        self._failed = False

    @property
    def n_frames(self) -> int:
        """Frames written so far (all of them after :meth:`close`)."""
        return self.series.n_frames

    def show(self, t: float) -> None:
        """Write the tissue and its cut surface at time ``t`` (handed to the writer thread)."""
        from cutkit.cutting import compact_nodes, cut_surface_faces

        s = self.session
        t1 = time.perf_counter()
        tis, cm = s.tis, s.cut_mesh
        with s.lock:
            tets, ids = tis.alive_tets()
            n = tis.n_nodes
            rgb = self.colours.get(n)
            pd = {"displacement": tis.displacement.copy(), "velocity": tis.velocities.copy(),
                  "fixed": tis.fixed.astype(np.uint8), **tis.point_data()}
            positions = tis.positions.copy()
            labels = cm.labels[cm.tet_origins[ids]].astype(np.int32)
            surf_faces = cut_surface_faces(cm)
            made = cm.store.made_by_cut(ids)  # in any stroke
        if rgb is not None:
            pd["texture_rgb"] = rgb
        cd = {"label": labels, "new_tet": made.astype(np.uint8)}
        kept, new_index = compact_nodes(tets, n)  # no orphan node in a frame
        spd = {"displacement": pd["displacement"]}
        if rgb is not None:
            spd["texture_rgb"] = rgb  # NodeColours grows by a new array: this one stays as it is
        frame = (t, positions[kept], new_index[tets], {k: v[kept] for k, v in pd.items()}, cd)
        self._wait(FRAMES_IN_FLIGHT - 1)
        self._pending.append(self._writer.submit(self._write, frame, (t, positions, surf_faces, spd)))
        s.task_s["output"] += time.perf_counter() - t1

    def _write(self, frame, surface) -> None:
        """The writer thread: one frame of the tissue and of its cut surface; none after one failed
        (the recording ends with the last frame written whole)."""
        if self._failed:
            return
        try:
            t, points, tets, point_data, cell_data = frame
            self.series.write(t, points, tets, point_data=point_data, cell_data=cell_data)
            self.surface.write(*surface)
        except BaseException:
            self._failed = True
            raise

    def _wait(self, keep: int) -> None:
        """Wait until at most ``keep`` frames are pending; re-raises a failed write."""
        while len(self._pending) > keep:
            self._pending.popleft().result()

    def close(self) -> None:
        """Wait for every frame, then write the collections."""
        try:
            self._wait(0)
        finally:
            self._writer.shutdown(wait=True, cancel_futures=True)
            self.series.close()
            self.surface.close()


class NodeColours:
    """Texture colours per node, extended as cuts add nodes (None for an untextured model)."""

    def __init__(self, model, cm):
        self.cm = cm
        tex = model.texture if (model.texture is not None and model.texcoords is not None) else None
        self.texture = tex
        n0 = cm.n_orig_points
        self.rgb = np.asarray(tex.sample_rgb(cm.texcoords[:n0])) if tex is not None else None

    def get(self, n: int):
        if self.rgb is not None and self.rgb.shape[0] < n:
            extra = np.asarray(self.texture.sample_rgb(self.cm.texcoords[self.rgb.shape[0]:n]))
            self.rgb = np.concatenate([self.rgb, extra])
        return None if self.rgb is None else self.rgb[:n]


class ForceRecorder:
    """One row of ``forces.csv`` per haptic tick (:data:`cutkit.simulate.outputs.FORCE_COLUMNS`)."""

    def __init__(self, capacity: int = 1024):
        from cutkit.simulate.outputs import ForceLog

        self.log = ForceLog(capacity)

    def add(self, t, code, out, tip, proxy) -> None:
        from cutkit.scalpel import O_A, O_CUT, O_D_A, O_FORCE, O_N

        fa, fn, cut = out[O_A:O_A + 3], out[O_N:O_N + 3], out[O_CUT:O_CUT + 3]
        self.log.add(t, code, -out[O_FORCE:O_FORCE + 3], float(cut @ fa), float(cut @ fn), out[O_D_A], tip, proxy)

    def max_force(self) -> float:
        return float(np.linalg.norm(self.log.rows[:, 2:5], axis=1).max(initial=0.0))

    def write(self, path) -> None:
        self.log.write(path)


class PoseRecorder:
    """The poses a session acted on, as a trajectory file (docs/trajectory-format.md).

    Times are session seconds from the first pose; a pose at the same time
    as the previous one replaces it (trajectory times strictly increase).
    """

    def __init__(self, blade_length: float, blade_breadth: float):
        self.blade_length, self.blade_breadth = float(blade_length), float(blade_breadth)
        self.rows: list[np.ndarray] = []
        self.t0 = None

    def add(self, t: float, tip, a, n) -> None:
        if self.t0 is None:
            self.t0 = float(t)
        row = np.concatenate([[float(t) - self.t0], tip, a, n])
        if self.rows and row[0] <= self.rows[-1][0] + 1e-6:
            row[0] = self.rows[-1][0]  # the newer pose at the earlier time
            self.rows[-1] = row
            return
        self.rows.append(row)

    def trajectory(self):
        from cutkit.cutting.trajectory import Trajectory

        r = np.array(self.rows) if self.rows else np.zeros((0, 10))
        return Trajectory(t=r[:, 0], tip=r[:, 1:4], a=r[:, 4:7], n=r[:, 7:10], blade_length=self.blade_length,
                          blade_breadth=self.blade_breadth)

    def write(self, path) -> bool:
        """Write ``trajectory.csv`` (atomically); False when fewer than two poses came."""
        from cutkit.cutting.trajectory import write_trajectory

        if len(self.rows) < 2:
            return False
        write_trajectory(path, self.trajectory())
        return True


def volume_change(tis) -> float:
    """Deformed total volume of the live tets over their rest volume, minus 1 (a cut keeps the rest volume)."""
    from cutkit.mesh.quality import signed_volumes

    tets = tis.store.tets
    if len(tets) == 0:
        return 0.0
    rest = float(signed_volumes(tis.rest_positions, tets).sum())
    return float(signed_volumes(tis.positions, tets).sum()) / rest - 1.0 if rest > 0 else 0.0


def crumbs_report(cm) -> dict:
    """``summary.json``'s crumb keys: crumbs removed (count, rest volume mm^3), pieces left loose (mm^3 each).

    ``loose_pieces_mm3`` lists the rest volume of every piece but the largest
    (tets joined by shared nodes; :func:`cutkit.cutting.crumbs.loose_pieces`).
    """
    from cutkit.cutting.crumbs import crumb_volume, loose_pieces

    return {"crumbs_removed": int(cm.crumb_count), "crumb_volume_mm3": crumb_volume(cm),
            "loose_pieces_mm3": [float(v) for v in loose_pieces(cm)[1:]]}


def summary(session, *, model_path, loop_wall: float, t_traj_end, opening_at_traj_end, frames: int,
            forces: ForceRecorder, interrupted: bool, rates: bool) -> dict:
    """What ``summary.json`` holds (docs/simulate.md)."""
    tis, counts, task_s, opt = session.tis, session.counts, session.task_s, session.opt
    cm = session.cut_mesh
    simulated = tis.time
    n_cut, new_tets = session.tets_cut, session.new_tets  # summed over the strokes
    opening = session.opening()
    loop_wall = max(loop_wall, 1e-12)
    work = task_s["haptics"] + task_s["collision_and_cut"] + task_s["relaxation"]
    out = {
        "model": model_path,
        "tets_initial": int(cm.n_model_tets),
        "nodes_initial": int(cm.n_model_points),
        "tets_final": int(cm.tet_alive.sum()),
        "nodes_final": tis.n_nodes,
        "material_model": session.material_model,
        "settle": session.settle_info,
        "cut_tets": n_cut,
        "new_tets": new_tets,
        "new_tets_per_cut_tet": (new_tets / n_cut) if n_cut else 0.0,
        "rebases": int(session.cut_before["rebases"]),
        "edges_left_uncut": int(cm.edges_left_uncut()),
        "edges_followed": int(cm.edges_followed()),
        **crumbs_report(cm),
        "states": list(session.states_seen),
        "frames": int(frames),
        "pictures": [],
        "simulated_s": simulated,
        "wall_s": loop_wall,
        "simulated_per_wall": simulated / loop_wall,
        "simulated_per_wall_without_output": simulated / max(work, 1e-12),
        "time_per_task_s": dict(task_s),
        "cut_step_ms": _cut_step_ms(session.cut),
        "counts": dict(counts),
        "cut_opening_mm": {
            "at_trajectory_end": opening_at_traj_end,
            "final_mean": float(opening.mean()) if opening.size else 0.0,
            "final_max": float(opening.max()) if opening.size else 0.0,
        },
        "inverted_tets_deformed": count_inverted(tis.positions, cm.tets),
        "volume_change": volume_change(tis),
        "max_displacement_mm": float(np.linalg.norm(tis.displacement, axis=1).max(initial=0.0)),
        "max_F_ext_N": forces.max_force(),
        "interrupted": bool(interrupted),
        "options": asdict(opt),
        "warnings": list(session.warnings),
    }
    if rates:
        out["rates_hz"] = {
            "haptics": counts["haptic_ticks"] / loop_wall,
            "geometry_updates": counts["geometry_updates"] / loop_wall,
            "cut_steps": counts["cut_steps"] / loop_wall,
            "relaxation_list_passes": counts["relax_passes"] / loop_wall,
            "frames": frames / loop_wall,
        }
    return out


def _cut_step_ms(cut) -> dict | None:
    """Median and p90 wall time of the cut steps (volume collision, subdivision and the hand-over
    to the tissue), and of the hand-over alone, ms; None without a cut step."""
    if not cut.step_s:
        return None
    step, handover = np.array(cut.step_s) * 1e3, np.array(cut.handover_s) * 1e3
    return {"n": int(step.size), "median": float(np.median(step)), "p90": float(np.percentile(step, 90)),
            "handover_median": float(np.median(handover)), "handover_p90": float(np.percentile(handover, 90))}


def extents_text(points, tips) -> str:
    """``the model spans X0..X1, ... mm in x, y, z; the trajectory ...``: where a blade that missed went."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    tips = np.asarray(tips, np.float64).reshape(-1, 3)
    lo, hi = points.min(axis=0), points.max(axis=0)
    return (f"the model spans {', '.join(f'{a:g}..{b:g}' for a, b in zip(lo, hi))} mm in x, y, z; the trajectory "
            f"{', '.join(f'{a:g}..{b:g}' for a, b in zip(tips.min(axis=0), tips.max(axis=0)))}")


def closing_warnings(session, tips=None) -> None:
    """The warnings a finished session adds: no touch, or a touch without a cut; crossed edges left uncut.

    ``tips`` (the trajectory's blade tips, mm) adds the model's and the trajectory's extents."""
    if session.counts["entries"] == 0:
        where = f" ({extents_text(session.model.points, tips)})" if tips is not None and len(tips) else ""
        session.warnings.append(f"the trajectory never touches the tissue: no cut{where}")
    elif not session.tets_cut:
        reached = "J_c x depth of cut" if session.opt.scalpel == "fracture" else "F_enter"
        session.warnings.append(f"the blade touched the tissue but never cut it ({reached} not reached)")
    from cutkit.cutting.contact import uncut_edges_line

    line = uncut_edges_line(session.cut_mesh)  # crossed edges left uncut, counted and named
    if line:
        session.warnings.append(line)


def write_cut_model(session, out_dir, summary_: dict) -> None:
    """``model.h5``: the cut model in its rest configuration with its displacement."""
    from cutkit.io.model_h5 import write_model
    from cutkit.simulate.tissues import cut_model

    t1 = time.perf_counter()
    with session.lock:
        m = cut_model(session.cut_mesh, session.tis, session.model, summary_)
    write_model(Path(out_dir) / "model.h5", m)
    session.task_s["output"] += time.perf_counter() - t1


def count_inverted(points, tets) -> int:
    """Tets with non-positive volume in the deformed configuration (a mass-spring model does not forbid them)."""
    from cutkit.mesh.quality import signed_volumes

    return int((signed_volumes(points, tets) <= 0).sum()) if len(tets) else 0


def write_json(path, obj) -> None:
    from cutkit.io.atomic import write_text_atomic

    write_text_atomic(path, json.dumps(obj, indent=2, default=float) + "\n")


__all__ = ["FrameRecorder", "ForceRecorder", "PoseRecorder", "NodeColours", "summary", "write_cut_model",
           "closing_warnings", "count_inverted", "crumbs_report", "write_json"]
