"""``cutkit simulate``: a blade trajectory in, cut and relaxed tissue out.

The tasks of the paper's Fig. 1, on one simulated clock:

* **haptics** (1 kHz, section 6): the trajectory's pose drives the scalpel
  force model; the proxy is where the blade really is.  Before contact the
  proxy follows the hand; at the first boundary face the hand's tip crosses
  inwards the blade enters (``enter``) with the coefficients of that
  tissue; below F_enter the proxy stays put (static friction), then it cuts.
* **collision and geometry update** (``geometry_rate_hz``, sections 3-4):
  while the scalpel cuts, the blade at the proxy cuts the mesh
  (``cut_step``) and the topology change goes over to the springs
  (:class:`~cutkit.simulate.tissue.Tissue`).  The reaction of the cut
  force acts on the nodes around the blade tip.
* **relaxation** (section 5): the node lists advance to the same time, so
  the tissue opens under its prestress.
* **output** at ``fps`` frames per simulated second.

Offline (the default) everything runs on simulated time and the result is
deterministic; ``realtime`` paces the loop to the wall clock and reports
the rate each task reached.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from cutkit.errors import InputError
from cutkit.model.tetmodel import MATERIAL_MODELS

#: The haptic step, s: the force model runs at 1 kHz whatever else happens (section 6).
HAPTIC_DT = 1e-3
#: The blade has left the tissue once the hand's tip is this far outside the
#: entry face's plane, mm (a small margin so surface noise does not flicker).
LEAVE_MARGIN_MM = 0.5
#: Most settle iterations of each material model by default: Newton steps of
#: the element model, which stops earlier at its residual (SimulateOptions.settle_rtol),
#: Gauss-Seidel sweeps of the springs.
SETTLE_MAX_SWEEPS = {"neohookean": 50, "springs": 100}
#: Default volume stiffness (bulk modulus of the volume term over E): see
#: docs/simulate.md for what it does to the demo's inverted tets and opening.
VOLUME_STIFFNESS = 0.0


@dataclass
class SimulateOptions:
    """Options of :func:`simulate` (the command line's, with the same names).

    Attributes
    ----------
    fps : float
        Frames per simulated second (output only: never changes what is simulated).
    geometry_rate_hz : float
        Collision, cut and relaxation updates per simulated second; the
        element model makes one implicit step of ``1 / geometry_rate_hz``
        per update.
    material_model : str or None
        ``"neohookean"`` (stable neo-Hookean elements, vertex block descent)
        or ``"springs"`` (the paper's); None: what the model names.
    settle_iterations : int or None
        The most sweeps the settle before the trajectory may make: the model
        settles under its prestress and boundary conditions.  The element
        model stops at the relative residual ``settle_rtol``; the springs
        make exactly this many sweeps at the step ``settle_step_s``.  None:
        :data:`SETTLE_MAX_SWEEPS` of the material model.
    settle_rtol : float
        Relative residual the element model's settle reaches.
    settle_step_s : float
        s (springs).
    hold_s : float
        Simulated seconds after the trajectory's last row (the cut opens).
    dt0 : float
        Finest relaxation step, s (node list 0).
    n_lists : int
        Node lists, steps dt0 .. dt0 2^(n_lists - 1) (section 5.2).
    tolerance_fraction : float
        Node-list displacement tolerance as a fraction of the mean edge length.
    blade_length : float or None
        mm; default: the trajectory's.
    centre_nodes : bool
        Fig. 2c centre nodes in split faces.
    volume_stiffness : float
        Volume term (:mod:`cutkit.relax.volume`): each tet resists a change of
        its volume with ``bulk = volume_stiffness * E``; 0 is the paper's
        springs only.
    png : bool
        Pictures under ``pictures/`` after the run (:func:`cutkit.render.render_output`).
    realtime : bool
        Pace to the wall clock and report the rates reached.
    haptics : str or None
        ``HOST:PORT`` of a running ``cutkit haptics serve``.
    write_model : bool
        Write the cut model as ``model.h5``.
    frames : bool
        Write the frame series (off for benchmarks).
    """

    fps: float = 30.0
    geometry_rate_hz: float = 50.0
    material_model: str | None = None
    settle_iterations: int | None = None
    settle_rtol: float = 1e-3
    settle_step_s: float = 0.02
    hold_s: float = 0.5
    dt0: float = 2e-3
    n_lists: int = 3
    tolerance_fraction: float = 1e-3
    blade_length: float | None = None
    centre_nodes: bool = False
    volume_stiffness: float = VOLUME_STIFFNESS
    png: bool = False
    realtime: bool = False
    haptics: str | None = None
    write_model: bool = True
    frames: bool = True

    def check(self) -> None:
        for name in ("fps", "geometry_rate_hz", "dt0", "tolerance_fraction"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"{name.replace('_', '-')} must be a positive number, got {v}")
        if self.settle_iterations is not None and not 0 <= int(self.settle_iterations) <= 100000:
            raise InputError(f"settle-iterations must lie in 0..100000, got {self.settle_iterations}")
        if self.material_model is not None and self.material_model not in MATERIAL_MODELS:
            raise InputError(f"material-model must be one of {', '.join(MATERIAL_MODELS)}, "
                             f"not {self.material_model!r}")
        if not (np.isfinite(self.settle_rtol) and 0 < self.settle_rtol < 1):
            raise InputError(f"settle-rtol must lie in (0, 1), got {self.settle_rtol}")
        for name in ("settle_step_s", "hold_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"{name.replace('_', '-')} must be a number >= 0, got {v}")
        if self.geometry_rate_hz > 1.0 / HAPTIC_DT:
            raise InputError(f"geometry-rate-hz must be at most the haptic rate {1.0 / HAPTIC_DT:.0f} Hz")
        if self.blade_length is not None and not (np.isfinite(self.blade_length) and self.blade_length > 0):
            raise InputError(f"blade-length must be a positive number, got {self.blade_length}")
        if not (np.isfinite(self.volume_stiffness) and self.volume_stiffness >= 0):
            raise InputError(f"volume-stiffness must be a number >= 0, got {self.volume_stiffness}")
        if not 1 <= int(self.n_lists) <= 12:
            raise InputError(f"n-lists must lie in 1..12, got {self.n_lists}")
        if self.haptics is not None:
            from cutkit.simulate.blade import parse_host_port

            parse_host_port(self.haptics)


@dataclass
class _Contact:
    entry: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inward: np.ndarray = field(default_factory=lambda: np.zeros(3))
    face_nodes: np.ndarray = field(default_factory=lambda: np.zeros(3, np.int64))
    normal: np.ndarray = field(default_factory=lambda: np.zeros(3))


def _cut_opening(cm, positions) -> np.ndarray:
    """(p,) distances between the two copies of every duplicated cut node, mm."""
    pairs = [cm.edge_node[np.all(cm.edge_node >= 0, axis=1)], cm.face_node[np.all(cm.face_node >= 0, axis=1)]]
    pairs = np.concatenate(pairs)
    if pairs.size == 0:
        return np.zeros(0)
    return np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)


def simulate(model, trajectory, out_dir, options: SimulateOptions | None = None,
             progress: Callable[[float, float], None] | None = None, model_path: str | None = None) -> dict:
    """Cut ``model`` along ``trajectory`` and relax it; write the outputs into ``out_dir``.

    Parameters
    ----------
    model : TetModel
    trajectory : Trajectory
    out_dir : path-like
    options : SimulateOptions
    progress : callable(t, t_end), optional
        Called after every geometry update with the simulated time.
    model_path : str, optional
        Recorded in the summary.

    Returns
    -------
    summary : dict
        What ``summary.json`` holds.
    """
    from cutkit.collision import SurfaceBVH, blade_entry
    from cutkit.cutting import compact_nodes, cut_step, cut_surface_faces
    from cutkit.io.model_h5 import write_model
    from cutkit.io.series import SeriesWriter
    from cutkit.mesh.topology import boundary_faces
    from cutkit.scalpel import CUTTING, FREE, O_A, O_CUT, O_D_A, O_FORCE, O_N, STATE_NAMES
    from cutkit.simulate.blade import InProcessScalpel, ServiceScalpel, parse_host_port
    from cutkit.simulate.outputs import ForceLog, SurfaceSeries

    opt = options or SimulateOptions()
    opt.check()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    blade_length = opt.blade_length or trajectory.blade_length
    blade = {"blade_breadth": float(trajectory.blade_breadth)}
    warnings: list[str] = []

    wall0 = time.perf_counter()
    task_s = {"setup": 0.0, "settle": 0.0, "haptics": 0.0, "collision_and_cut": 0.0, "relaxation": 0.0,
              "output": 0.0}
    material_model = opt.material_model or model.materials.material_model
    tis = make_tissue(model, material_model, opt, blade_length)
    cm = tis.cm
    n0, m0 = cm.n_orig_points, tis.n_orig_tets
    if not tis.fixed.any():
        warnings.append("the model has no fixed node: nothing holds it, it may drift (add [boundary] "
                        "fixed_labels or fixed_regions to its recipe and run `cutkit assign`)")
    faces, face_tet = boundary_faces(cm.orig_tets)
    bvh = SurfaceBVH.build(tis.positions[:n0].copy(), faces)
    rows = model.materials.rows()
    row_of_tet = model.materials.row_of(cm.labels)
    texture = model.texture if (model.texture is not None and model.texcoords is not None) else None
    rgb = np.asarray(texture.sample_rgb(cm.texcoords[:n0])) if texture is not None else None
    task_s["setup"] = time.perf_counter() - wall0

    # the model settles under its prestress and boundary conditions first
    t1 = time.perf_counter()
    settle_sweeps = SETTLE_MAX_SWEEPS[material_model] if opt.settle_iterations is None else opt.settle_iterations
    settle_info = {"iterations": 0}
    if settle_sweeps > 0:
        # the settled state is the start: at rest, at time 0
        if material_model == "springs":
            settle_info = tis.settle(settle_sweeps, opt.settle_step_s)
        else:
            settle_info = tis.settle(settle_sweeps, opt.settle_rtol)
            if not settle_info["converged"]:
                warnings.append(f"the settle stopped after {settle_info['iterations']} sweeps at relative "
                                f"residual {settle_info['relative_residual']:.1e} (asked: {opt.settle_rtol:.0e})")
        bvh.update(tis.positions[:n0])
    task_s["settle"] = time.perf_counter() - t1

    if opt.haptics:
        host, port = parse_host_port(opt.haptics)
        scalpel = ServiceScalpel(host, port, **blade)
        realtime = True  # the service runs on its own clock
    else:
        scalpel = InProcessScalpel(**blade)
        realtime = bool(opt.realtime)

    t_start = float(trajectory.t[0])
    t_traj_end = float(trajectory.t[-1])
    t_end = t_traj_end + opt.hold_s
    n_ticks = int(round((t_end - t_start) / HAPTIC_DT))
    geo_every = max(1, int(round(1.0 / (opt.geometry_rate_hz * HAPTIC_DT))))
    frame_period = 1.0 / opt.fps
    forces = ForceLog(n_ticks + 1)
    contact = _Contact()
    series = SeriesWriter(out_dir, "cut")
    surface = SurfaceSeries(out_dir)
    pictures: list[str] = []
    states_seen: list[str] = []
    counts = {"cut_steps": 0, "geometry_updates": 0, "haptic_ticks": 0, "relax_passes": 0,
              "nodes_added": 0, "entries": 0}
    opening_at_traj_end = None
    cut_plane = {"entry": None, "a": None, "b": None, "n": None}

    def tissue_time(t):
        return t - t_start

    def write_frame(t):
        nonlocal rgb
        t1 = time.perf_counter()
        tets, ids = tis.alive_tets()
        n = tis.n_nodes
        if rgb is not None and rgb.shape[0] < n:
            rgb = np.concatenate([rgb, np.asarray(texture.sample_rgb(cm.texcoords[rgb.shape[0]:n]))])
        pd = {"displacement": tis.displacement, "velocity": tis.velocities,
              "fixed": tis.fixed.astype(np.uint8), **tis.point_data()}
        if rgb is not None:
            pd["texture_rgb"] = rgb
        cd = {"label": cm.labels[cm._tet_orig[ids]].astype(np.int32), "new_tet": (ids >= m0).astype(np.uint8)}
        kept, new_index = compact_nodes(tets, n)  # no orphan node in a frame
        series.write(t, tis.positions[kept], new_index[tets], point_data={k: v[kept] for k, v in pd.items()},
                     cell_data=cd)
        surf_faces = cut_surface_faces(cm)
        spd = {"displacement": pd["displacement"]}
        if rgb is not None:
            spd["texture_rgb"] = rgb
        surface.write(t, tis.positions, surf_faces, spd)
        task_s["output"] += time.perf_counter() - t1

    prev_tip = None
    cutting_pending = False
    next_frame = t_start
    interrupted = False
    out = scalpel.out
    loop0 = time.perf_counter()
    tick_wall = 0.0
    try:
        for k in range(n_ticks + 1):
            t = t_start + k * HAPTIC_DT
            if realtime:
                delay = loop0 + (t - t_start) - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
            th = time.perf_counter()
            tip, a_traj, n_traj = trajectory.pose_at(t)
            if scalpel.code == FREE and prev_tip is not None:
                # contact from the whole blade against the current surface: the tip's path, the
                # blade now (the surface may have moved past it), the quad it swept since the last tick
                prev_a = trajectory.pose_at(t - HAPTIC_DT)[1]
                hit = blade_entry(bvh, tis.positions[:n0], prev_tip, prev_tip - blade_length * prev_a,
                                  tip, tip - blade_length * a_traj)
                if hit is not None:
                    f = hit.face
                    fv = bvh.faces[f]
                    x = tis.positions[fv]
                    normal = np.cross(x[1] - x[0], x[2] - x[0])
                    contact.entry = hit.point.copy()
                    contact.inward = -normal / np.linalg.norm(normal)
                    contact.face_nodes = np.asarray(fv, np.int64).copy()
                    b = np.cross(n_traj, a_traj)
                    contact.normal = b / np.linalg.norm(b)
                    material = rows[int(row_of_tet[face_tet[f]])]
                    scalpel.enter(contact.entry, contact.normal, tip, material)
                    counts["entries"] += 1
                    if cut_plane["entry"] is None:
                        cut_plane.update(entry=contact.entry.copy(), a=a_traj.copy(), b=contact.normal.copy(),
                                         n=n_traj.copy())
            out = scalpel.tick(tip, a_traj, n_traj)
            code = scalpel.code
            if code != FREE and np.dot(tip - contact.entry, contact.inward) < -LEAVE_MARGIN_MM:
                scalpel.leave()
                code = FREE
                cm.prev_pose = None
                cm.tip_tet = -1
                cm.active_tets = np.zeros(0, np.int64)
            if not states_seen or states_seen[-1] != STATE_NAMES[code]:
                states_seen.append(STATE_NAMES[code])
            cutting_pending |= code == CUTTING
            fa, fn = out[O_A:O_A + 3], out[O_N:O_N + 3]
            cut = out[O_CUT:O_CUT + 3]
            forces.add(t, code, -out[O_FORCE:O_FORCE + 3], float(cut @ fa), float(cut @ fn), out[O_D_A],
                       tip, scalpel.proxy)
            counts["haptic_ticks"] += 1
            prev_tip = tip
            tick_wall += time.perf_counter() - th

            if k % geo_every:
                continue
            # ---- collision and geometry update (sections 3-4)
            tg = time.perf_counter()
            axis = out[O_N:O_N + 3].copy()
            near = np.unique(cm.orig_tets[cm.active_tets]) if cm.active_tets.size else contact.face_nodes
            blade_tip = tis.blade_to_rest(scalpel.proxy, near)
            if cutting_pending:
                res = cut_step(cm, blade_tip, axis)
                for key, value in tis.apply_cut(res).items():
                    counts[key] = counts.get(key, 0) + value
                counts["cut_steps"] += 1
                cutting_pending = False
            elif code != FREE:
                # in tissue but not cutting: the blade rests or backs out, the sweep restarts here
                cm.prev_pose = (blade_tip, blade_tip - cm.blade_length * axis)
            f_ext = np.zeros((tis.n_nodes, 3))
            if code == CUTTING and cm.active_tets.size:
                # the tissue along the blade feels the reaction of the cut force (eqs. 16-18);
                # before the blade enters, the surface is not indented (the entry point stays
                # where the surface was met, docs/simulate.md)
                nodes = np.unique(cm.orig_tets[cm.active_tets])  # the cut step moved the blade
                f_ext[nodes] -= out[O_CUT:O_CUT + 3] / len(nodes)
            counts["geometry_updates"] += 1
            task_s["collision_and_cut"] += time.perf_counter() - tg
            # ---- relaxation (section 5)
            tr = time.perf_counter()
            # the whole tissue is brought to the same time at every update, whether a
            # frame is written or not: output never changes what is simulated
            counts["relax_passes"] += tis.advance(f_ext, tissue_time(t))
            frame_due = opt.frames and (t >= next_frame - 1e-9 or k == n_ticks)
            at_traj_end = opening_at_traj_end is None and t >= t_traj_end - 1e-9
            task_s["relaxation"] += time.perf_counter() - tr
            if scalpel.code == FREE:  # the hierarchy serves the entry test: refit to the relaxed surface
                tg = time.perf_counter()
                bvh.update(tis.positions[:n0])
                task_s["collision_and_cut"] += time.perf_counter() - tg
            if at_traj_end:
                o = _cut_opening(cm, tis.positions)
                opening_at_traj_end = float(o.mean()) if o.size else 0.0
            if frame_due:
                write_frame(t)
                next_frame += frame_period * max(1, int(np.floor((t - next_frame) / frame_period + 1e-9)) + 1)
            if progress is not None:
                progress(t - t_start, t_end - t_start)
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:
        loop_wall = time.perf_counter() - loop0
        task_s["haptics"] = tick_wall
        series.close()
        surface.close()
        forces.write(out_dir / "forces.csv")
        scalpel.close()
        summary = _summary(locals_=dict(
            model=model, model_path=model_path, trajectory=trajectory, tis=tis, counts=counts, task_s=task_s,
            loop_wall=loop_wall, t_start=t_start, t_end=t_end, t_traj_end=t_traj_end, warnings=warnings,
            states_seen=states_seen, pictures=pictures, frames=series.n_frames, interrupted=interrupted,
            opening_at_traj_end=opening_at_traj_end, realtime=realtime, opt=opt, m0=m0, forces=forces,
            material_model=material_model, settle_info=settle_info))
        if interrupted:
            _write_json(out_dir / "summary.json", summary)
    if counts["entries"] == 0:
        warnings.append("the trajectory never touches the tissue: no cut")
    elif not tis.cm.subtets:
        warnings.append("the blade touched the tissue but never cut it (F_enter not reached)")
    summary["warnings"] = warnings
    if opt.write_model:
        t1 = time.perf_counter()
        write_model(out_dir / "model.h5", cut_model(tis, model, summary))
        task_s["output"] += time.perf_counter() - t1
        summary["time_per_task_s"] = dict(task_s)
    if hasattr(tis, "counts"):
        summary["counts"].update({f"relax_{k}": v for k, v in tis.counts.items()})
    _write_json(out_dir / "summary.json", summary)
    if opt.png:
        # drawn from the files just written, as `cutkit render` draws any folder again
        from cutkit.render import render_output

        summary["pictures"] = render_output(out_dir)["pictures"]
    return summary


def make_tissue(model, material_model: str, opt: SimulateOptions, blade_length: float):
    """The tissue of a run: :class:`ElasticTissue` or the paper's springs (:class:`Tissue`)."""
    if material_model == "springs":
        from cutkit.simulate.tissue import Tissue

        return Tissue(model, blade_length=blade_length, dt0=opt.dt0, n_lists=opt.n_lists,
                      tolerance_fraction=opt.tolerance_fraction, centre_nodes=opt.centre_nodes,
                      volume_stiffness=opt.volume_stiffness)
    from cutkit.simulate.elastic_tissue import ElasticTissue

    return ElasticTissue(model, blade_length=blade_length, step_s=1.0 / opt.geometry_rate_hz,
                         centre_nodes=opt.centre_nodes)


def cut_model(tis, model, summary: dict | None = None):
    """The cut tissue as a model: rest configuration, cut topology, displacement as point data.

    A model is defined in its rest configuration (the springs' rest lengths
    follow from it), so ``points`` are the rest positions of the cut mesh,
    where every tetrahedron is positively oriented; ``point_data
    ["displacement"]`` (mm) holds the relaxed deformation (ParaView: Warp By
    Vector).  Nodes no tetrahedron uses are dropped (``to_model`` compacts
    the numbering and carries the boundary conditions over to it).
    """
    import dataclasses

    from cutkit.cutting import to_model

    cm = tis.cm
    m = to_model(cm, model, points=cm.points, point_data={"displacement": tis.displacement})
    provenance = dict(m.provenance)
    stages = dict(provenance.get("stages", {}))
    if summary is not None:
        stages["simulate"] = {"options": summary.get("options"), "cut_tets": summary.get("cut_tets"),
                              "simulated_s": summary.get("simulated_s")}
    provenance["stages"] = stages
    return dataclasses.replace(m, provenance=provenance)


def _summary(locals_: dict) -> dict:
    L = locals_
    tis, counts, task_s = L["tis"], L["counts"], L["task_s"]
    cm = tis.cm
    simulated = tis.time
    n_cut = len(cm.subtets)
    new_tets = int(sum(len(v) for v in cm.subtets.values()))
    opening = _cut_opening(cm, tis.positions)
    loop_wall = max(L["loop_wall"], 1e-12)
    work = task_s["haptics"] + task_s["collision_and_cut"] + task_s["relaxation"]
    summary = {
        "model": L["model_path"],
        "tets_initial": int(L["m0"]),
        "nodes_initial": int(cm.n_orig_points),
        "tets_final": int(cm._alive[:cm.n_tets_total].sum()),
        "nodes_final": tis.n_nodes,
        "material_model": L["material_model"],
        "settle": L["settle_info"],
        "cut_tets": n_cut,
        "new_tets": new_tets,
        "new_tets_per_cut_tet": (new_tets / n_cut) if n_cut else 0.0,
        "states": L["states_seen"],
        "frames": int(L["frames"]),
        "pictures": L["pictures"],
        "simulated_s": simulated,
        "wall_s": loop_wall,
        "simulated_per_wall": simulated / loop_wall,
        "simulated_per_wall_without_output": simulated / max(work, 1e-12),
        "time_per_task_s": dict(task_s),
        "counts": dict(counts),
        "cut_opening_mm": {
            "at_trajectory_end": L["opening_at_traj_end"],
            "final_mean": float(opening.mean()) if opening.size else 0.0,
            "final_max": float(opening.max()) if opening.size else 0.0,
        },
        "inverted_tets_deformed": _count_inverted(tis.positions, cm.tets),
        "max_displacement_mm": float(np.linalg.norm(tis.displacement, axis=1).max(initial=0.0)),
        "max_F_ext_N": float(np.linalg.norm(L["forces"].rows[:, 2:5], axis=1).max(initial=0.0)),
        "interrupted": bool(L["interrupted"]),
        "options": asdict(L["opt"]),
        "warnings": list(L["warnings"]),
    }
    if L["realtime"]:
        summary["rates_hz"] = {
            "haptics": counts["haptic_ticks"] / loop_wall,
            "geometry_updates": counts["geometry_updates"] / loop_wall,
            "cut_steps": counts["cut_steps"] / loop_wall,
            "relaxation_list_passes": counts["relax_passes"] / loop_wall,
            "frames": L["frames"] / loop_wall,
        }
    return summary


def _count_inverted(points, tets) -> int:
    """Tets with non-positive volume in the deformed configuration (a mass-spring model does not forbid them)."""
    from cutkit.mesh.quality import signed_volumes

    return int((signed_volumes(points, tets) <= 0).sum()) if len(tets) else 0


def _write_json(path, obj) -> None:
    from cutkit.io.atomic import write_text_atomic

    write_text_atomic(path, json.dumps(obj, indent=2, default=float) + "\n")
