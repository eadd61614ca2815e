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
  (:class:`~cutkit.relax.spring_tissue.Tissue`).  The reaction of the cut
  force acts on the nodes around the blade tip.
* **relaxation** (section 5): the node lists advance to the same time, so
  the tissue opens under its prestress.
* **output** at ``fps`` frames per simulated second.

Offline (the default) everything runs on simulated time and the result is
deterministic; ``realtime`` paces the loop to the wall clock and reports
the rate each task reached.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cutkit.errors import InputError
from cutkit.interrupts import check_stop, safe_points
from cutkit.model.tetmodel import MATERIAL_MODELS
from cutkit.simulate.tissues import SETTLE_MAX_SWEEPS, cut_model, make_tissue  # noqa: F401 (public here too)
from cutkit.scalpel.model import HAPTIC_DT  # the force model's 1 kHz step, defined there once
from cutkit.threads import one_blas_thread

#: ``simulate --haptics`` and live sessions warn when the haptic loop reaches
#: less than this fraction of 1 kHz.
RATE_WARN_FRACTION = 0.9
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
        :data:`cutkit.simulate.tissues.SETTLE_MAX_SWEEPS` of the material model.
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
    solver : str or None
        How the element model's relaxation steps are solved: ``"newton"``
        (projected Newton), ``"vbd"`` (vertex block descent) or ``"hybrid"``
        (vertex block descent, a step left unconverged at its sweep cap
        finished by a local Newton polish, :mod:`cutkit.relax.hybrid`); None:
        :data:`cutkit.relax.elastic_tissue.DEFAULT_SOLVER`.  Ignored by the springs.
    rest_rtol : float or None
        The tolerance over the force scale (in (0, 1)) the hybrid's resting
        steps bring a tissue at rest to once the blade has left it; under the
        blade's load they end at ``max(rest_rtol, REST_FIRST_RTOL)`` (3e-4),
        the first one after the blade left at ``max(rest_rtol,
        REST_UNLOADED_FIRST_RTOL)`` (1e-3).  None:
        :data:`cutkit.relax.elastic_tissue.REST_RTOL` (1e-4).  Tighter brings
        a soft model's wound nearer its equilibrium (docs/relaxation.md,
        "Resting steps", "Measured on an MRI head").
    scalpel : str
        Scalpel force model: ``"paper"`` (section 6, F_enter and cut
        friction) or ``"fracture"`` (the crack advances when the blade pays
        J_c per crack area; docs/scalpel-model.md).  With ``haptics`` the
        service's own ``--scalpel`` decides.
    element : str
        The element model's tetrahedron: ``"nh"`` (stable neo-Hookean linear
        tets) or ``"anp"`` (average nodal pressure, :mod:`cutkit.relax.anp`;
        solved by ``"newton"``, which it selects where no solver is named).
    deviatoric_smoothing : float or None
        With ``element="anp"``: the share alpha of the deviatoric energy
        smoothed over the nodes (:mod:`cutkit.relax.anp`); None takes
        :data:`cutkit.relax.anp.ANP_SMOOTHING` (0.7, the share that meets the
        5 % bound against quadratic tets, docs/relaxation.md), 0 is plain ANP.
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
    solver: str | None = None
    rest_rtol: float | None = None
    scalpel: str = "paper"
    element: str = "nh"
    deviatoric_smoothing: float | None = None

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
        from cutkit.relax.elastic_tissue import SOLVERS

        if self.solver is not None and self.solver not in SOLVERS:
            raise InputError(f"solver must be {', '.join(SOLVERS[:-1])} or {SOLVERS[-1]}, not {self.solver!r}")
        if self.rest_rtol is not None and not (np.isfinite(self.rest_rtol) and 0.0 < self.rest_rtol < 1.0):
            raise InputError(f"rest-rtol must lie in (0, 1), got {self.rest_rtol}")
        from cutkit.scalpel import SCALPEL_MODELS

        if self.scalpel not in SCALPEL_MODELS:
            raise InputError(f"scalpel must be one of {', '.join(SCALPEL_MODELS)}, not {self.scalpel!r}")
        if self.element not in ("nh", "anp"):
            raise InputError(f"element must be nh or anp, not {self.element!r}")
        if self.element == "anp" and self.solver in ("vbd", "hybrid"):
            raise InputError(f"element anp is solved by the newton solver only, not {self.solver}")
        if self.deviatoric_smoothing is not None:
            a = float(self.deviatoric_smoothing)
            if self.element != "anp":
                raise InputError("deviatoric smoothing needs element anp")
            if not (np.isfinite(a) and 0.0 <= a < 1.0):
                raise InputError(f"deviatoric smoothing must lie in [0, 1), got {self.deviatoric_smoothing}")
        if not 1 <= int(self.n_lists) <= 12:
            raise InputError(f"n-lists must lie in 1..12, got {self.n_lists}")
        if self.haptics is not None:
            from cutkit.simulate.blade import parse_host_port

            parse_host_port(self.haptics)


def simulate(model, trajectory, out_dir, options: SimulateOptions | None = None,
             progress: Callable[[float, float], None] | None = None, model_path: str | None = None) -> dict:
    """Cut ``model`` along ``trajectory`` and relax it; write the outputs into ``out_dir``.

    The trajectory is replayed through a :class:`~cutkit.simulate.session.Session`
    on the simulated clock: per 1 ms tick the pose, the entry test, the force
    model and the leave test; every ``1 / geometry_rate_hz`` the cut and the
    relaxation; frames at ``fps``.  One thread, a fixed order: deterministic.

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
    with one_blas_thread():  # the same sums on every machine: docs/relaxation.md
        return _simulate(model, trajectory, out_dir, options, progress, model_path)


def _simulate(model, trajectory, out_dir, options, progress, model_path) -> dict:
    """:func:`simulate` with BLAS on one thread."""
    from cutkit.simulate.session import Session

    opt = options or SimulateOptions()
    opt.check()
    blade_length = opt.blade_length or trajectory.blade_length
    _refuse_a_blade_put_inside(model, trajectory, blade_length)
    out_dir = Path(out_dir)
    session = Session(model, opt, blade_length, float(trajectory.blade_breadth))
    out_dir.mkdir(parents=True, exist_ok=True)  # once the model is known to run: no empty folder on a refusal
    realtime = bool(opt.realtime)
    if opt.haptics:
        from cutkit.simulate.blade import ServiceScalpel, parse_host_port

        session.scalpel = ServiceScalpel(*parse_host_port(opt.haptics), blade_breadth=session.blade_breadth)
        if opt.scalpel != "paper":
            session.warnings.append(f"--scalpel {opt.scalpel} is ignored with --haptics: the service's own "
                                    "--scalpel decides the force model")
        session.out = session.scalpel.out
        realtime = True  # the service runs on its own clock
    replay = _Replay(session, trajectory, out_dir, opt, realtime)
    # Ctrl-C and SIGTERM stop the replay between two ticks; one that comes while the
    # recording is written waits until it is whole (cutkit.interrupts)
    with safe_points():
        try:
            replay.run(progress)
        except KeyboardInterrupt:
            replay.interrupted = True
            raise
        finally:
            summary = replay.finish(model_path)
        return _complete(session, replay, summary, out_dir, opt)


def _refuse_a_blade_put_inside(model, trajectory, blade_length: float) -> None:
    """A blade whose whole edge lies inside the tissue at the first pose never meets its surface,
    so the scalpel model (section 6) has no entry: it would never cut.  Refused in one line."""
    from cutkit.cutting import tet_containing

    tip, a, _ = trajectory.pose_at(float(trajectory.t[0]))
    handle_end = tip - blade_length * a
    if tet_containing(model.points, model.tets, tip) >= 0 and \
            tet_containing(model.points, model.tets, handle_end) >= 0:
        raise InputError(f"the blade lies inside the tissue at the trajectory's first pose (tip at "
                         f"{', '.join(f'{v:g}' for v in tip)} mm): start the trajectory outside the tissue, "
                         f"so that the blade enters through its surface")


class _Replay:
    """A trajectory replayed through a session on the simulated clock, with its recorders."""

    def __init__(self, session, trajectory, out_dir, opt: SimulateOptions, realtime: bool):
        from cutkit.simulate.record import ForceRecorder, FrameRecorder

        self.session, self.trajectory, self.out_dir, self.opt = session, trajectory, out_dir, opt
        self.realtime = realtime
        self.t_start = float(trajectory.t[0])
        self.t_traj_end = float(trajectory.t[-1])
        self.t_end = self.t_traj_end + opt.hold_s
        self.n_ticks = int(round((self.t_end - self.t_start) / HAPTIC_DT))
        self.geo_every = max(1, int(round(1.0 / (opt.geometry_rate_hz * HAPTIC_DT))))
        self.forces = ForceRecorder(self.n_ticks + 1)
        self.frames = FrameRecorder(session, out_dir)
        self.opening_at_traj_end = None
        self.interrupted = False
        self.loop_wall = 0.0

    def run(self, progress) -> None:
        loop0 = time.perf_counter()
        try:
            self._ticks(progress, loop0)
        finally:
            self.loop_wall = time.perf_counter() - loop0

    def _ticks(self, progress, loop0: float) -> None:
        """Per 1 ms tick: pose, force, record; every geometry period the cut and relaxation; frames."""
        s, traj, opt = self.session, self.trajectory, self.opt
        t_start, frame_period = self.t_start, 1.0 / opt.fps
        next_frame = t_start
        for k in range(self.n_ticks + 1):
            check_stop()  # the safe point: every array of the session and the recorders is whole here
            t = t_start + k * HAPTIC_DT
            if self.realtime:
                delay = loop0 + (t - t_start) - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
            tip, a, n = traj.pose_at(t)
            out = s.haptic_tick(tip, a, n)
            self.forces.add(t, s.code, out, tip, s.scalpel.proxy)
            if k % self.geo_every:
                continue
            s.relax_to(s.geometry_update(), t - t_start)
            if self.opening_at_traj_end is None and t >= self.t_traj_end - 1e-9:
                o = s.opening()
                self.opening_at_traj_end = float(o.mean()) if o.size else 0.0
            if opt.frames and (t >= next_frame - 1e-9 or k == self.n_ticks):
                self.frames.show(t)
                next_frame += frame_period * max(1, int(np.floor((t - next_frame) / frame_period + 1e-9)) + 1)
            if progress is not None:
                progress(t - t_start, self.t_end - t_start)

    def finish(self, model_path) -> dict:
        """Close the recorders, write forces.csv; the summary (written here when interrupted)."""
        from cutkit.simulate.record import summary, write_json

        self.frames.close()
        self.forces.write(self.out_dir / "forces.csv")
        self.session.scalpel.close()
        out = summary(self.session, model_path=model_path, loop_wall=self.loop_wall, t_traj_end=self.t_traj_end,
                      opening_at_traj_end=self.opening_at_traj_end, frames=self.frames.n_frames,
                      forces=self.forces, interrupted=self.interrupted, rates=self.realtime)
        if self.interrupted:
            write_json(self.out_dir / "summary.json", out)
        return out


def _complete(session, replay, summary: dict, out_dir: Path, opt: SimulateOptions) -> dict:
    """Warnings, the cut model, summary.json and the pictures of a finished replay."""
    from cutkit.simulate.record import closing_warnings, write_cut_model, write_json

    closing_warnings(session, replay.trajectory.tip)
    if hasattr(session.tis, "relax_report"):
        summary["relax_steps"] = session.tis.relax_report()
        line = relax_steps_warning(summary["relax_steps"])
        if line:
            session.warnings.append(line)
    if replay.realtime and "rates_hz" in summary:
        rate = summary["rates_hz"]["haptics"]
        if rate < RATE_WARN_FRACTION / HAPTIC_DT:
            session.warnings.append(f"the haptic loop reached {rate:.0f} Hz, below "
                                    f"{RATE_WARN_FRACTION:.0%} of {1.0 / HAPTIC_DT:.0f} Hz")
    summary["warnings"] = list(session.warnings)
    if opt.write_model:
        write_cut_model(session, out_dir, summary)
        summary["time_per_task_s"] = dict(session.task_s)
    if hasattr(session.tis, "counts"):
        summary["counts"].update({f"relax_{k}": v for k, v in session.tis.counts.items()})
    write_json(out_dir / "summary.json", summary)
    if opt.png:
        # drawn from the files just written, as `cutkit render` draws any folder again
        from cutkit.render import render_output

        summary["pictures"] = render_output(out_dir)["pictures"]
    return summary


#: Peak memory of a run, bytes per tet and per node of the model (``preflight``): fitted to the
#: peak resident size of ``cutkit simulate`` (neo-Hookean elements, one thread, a 0.4 s cut and
#: 0.2 s hold) on Kuhn-split boxes: 0.98 GB at 96,000 tets (18,491 nodes), 1.77 GB at 192,000
#: (36,531 nodes); the estimate is 12 % and 1 % above those.  The springs need less (+65 MB
#: from 24,000 to 48,000 tets, against +160 MB), so one estimate serves both.
SIMULATE_BYTES_PER_TET = 6500
SIMULATE_BYTES_PER_NODE = 3000
#: Peak resident size of the same run on 6,000 tets: the interpreter and cutkit's libraries (bytes).
SIMULATE_BASE_BYTES = 400 << 20
#: Wall seconds of relaxation per tet and simulated second, one thread (the same runs: 31 s for
#: 48,000 tets and 1 s simulated with the neo-Hookean elements on a loaded 2-core machine; the
#: springs take a tenth), for the build's size warning.
SIMULATE_S_PER_TET_SECOND = 6.5e-4


def simulate_memory_bytes(n_tets: int, n_points: int) -> int:
    """Estimated peak memory of :func:`simulate` on a model of this size (see the constants above)."""
    return int(SIMULATE_BASE_BYTES + SIMULATE_BYTES_PER_TET * n_tets + SIMULATE_BYTES_PER_NODE * n_points)


def available_memory_bytes() -> int | None:
    """Memory available to a new allocation: ``MemAvailable`` of /proc/meminfo, else free pages; None if unknown."""
    import os

    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def preflight(model, model_path: str = "MODEL", available: int | None = None, memory: bool = True) -> None:
    """The cheap checks of a model before a run: mesh, materials, memory.

    Raises
    ------
    MeshError
        The mesh fails one of the quick checks of ``cutkit check`` (finite
        coordinates, indices, positive orientation, faces shared by <= 2 tets).
    InputError
        A tet label has no material, or (``memory``) the run would not fit in the memory available.
    """
    from cutkit.errors import MeshError
    from cutkit.mesh.check import check_mesh

    rep = check_mesh(model.points, model.tets, quick=True)
    for row in rep.rows:
        if not row.passed:
            raise MeshError(f"{model_path}: fails the mesh check \"{row.name}\" ({row.detail}); "
                            f"run `cutkit check {model_path}`")
    labels = np.unique(np.asarray(model.labels))
    missing = labels[model.materials.row_of(labels) < 0]
    if missing.size:
        what = "has no materials yet" if model.materials.n_materials == 0 else \
            f"has no material for tet label{'s' * (missing.size > 1)} {', '.join(str(int(v)) for v in missing)}"
        raise InputError(f"{model_path}: the model {what}; give them with `cutkit assign {model_path} "
                         "--recipe R.toml -o MODEL.h5` (docs/recipes.md)")
    if not memory:
        return
    need = simulate_memory_bytes(model.n_tets, model.n_points)
    available = available_memory_bytes() if available is None else available
    if available is not None and need > available:
        raise InputError(f"{model_path}: {model.n_tets:,} tets need about {need / 2**30:.1f} GiB to simulate, "
                         f"{available / 2**30:.1f} GiB is available; decimate it first (`cutkit decimate "
                         f"{model_path} --ratio R -o SMALLER.h5`)")


def relax_steps_line(report: dict) -> str | None:
    """The closing line on a run's relaxation: steps, how many ended within tolerance, resting steps,
    and the last step's residual (what the final state is out of balance by, the blade's load
    included); None without steps."""
    if not report.get("count"):
        return None
    ok = report["count"] - report["not_converged"]
    resting = f", {report['resting_steps']} resting" if report.get("resting_steps") else ""
    last = report["relative_residual"][-1]
    ended = ("a waiting cut ended it early, its residual not evaluated" if last is None
             else f"the last ended at {last:.1e} of the force scale ({report['force_scale_N']:.3g} N)")
    return f"relaxation ({report['solver']}): {ok} of {report['count']} steps within tolerance{resting}; {ended}"


def relax_steps_warning(report: dict) -> str | None:
    """The one line a run's warnings get when a relaxation step ended unconverged, else None."""
    if not report["not_converged"]:
        return None
    # the sweeps stall on crushed tets near a cut (docs/relaxation.md): say what finishes such steps
    hint = "; --solver hybrid finishes such steps" if report["solver"] == "vbd" else ""
    resting = f", resting steps {report['rest_rtol']:.0e}" if report.get("rest_rtol") else ""
    return (f"{report['not_converged']} of {report['count']} relaxation steps ended unconverged "
            f"(worst residual {report['worst_relative_residual']:.1e} of the force scale, asked "
            f"{report['rtol']:.0e}{resting}; solver {report['solver']}{hint})")
