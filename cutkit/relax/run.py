"""Settle a model over simulated seconds and record frames (``cutkit relax``)."""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np

from cutkit.errors import InputError
from cutkit.relax.adaptive import NodeLists
from cutkit.relax.model import Control, SpringModel, build_spring_model, initial_state

#: Default finest step as a fraction of the explicit (symplectic Euler) limit 2 / omega_max.
DT0_FRACTION = 1.0
#: Default number of node lists (steps dt_0 .. 32 dt_0).
RUN_N_LISTS = 6
#: Default displacement tolerance of the list assignment, as a fraction of the mean edge length.
RUN_TOLERANCE_FRACTION = 1e-4


def explicit_time_limit(model: SpringModel) -> float:
    """2 / omega_max with omega_k^2 = sum_j k_jk / m_k (a bound for symplectic Euler), s."""
    ksum = np.bincount(model.springs.ravel(), np.repeat(model.stiffness, 2), minlength=model.n_nodes)
    free = ~model.fixed & (model.masses > 0)
    if not free.any() or ksum[free].max() <= 0:
        return 1e-3
    return float(2.0 / np.sqrt((ksum[free] / model.masses[free]).max()))


def settle(
    tet_model,
    seconds: float,
    out_dir: str | os.PathLike,
    *,
    fps: float = 30.0,
    gravity_mm_s2=(0.0, 0.0, 0.0),
    dt0: float | None = None,
    n_lists: int = RUN_N_LISTS,
    progress: Callable[[float, float], None] | None = None,
) -> dict:
    """Relax a model under its prestress, boundary conditions and gravity.

    Writes ``out_dir/frames/NNNN.vtu`` (point data ``displacement`` mm,
    ``velocity`` mm/s, ``node_list``) and ``out_dir/relax.pvd``.

    Parameters
    ----------
    tet_model : TetModel
    seconds : float
        Simulated time, s.
    out_dir : path-like
    fps : float
        Frames per simulated second (a frame at t = 0 and one at the end).
    gravity_mm_s2 : (3,) float
    dt0 : float, optional
        Finest step, s (default: :data:`DT0_FRACTION` of :func:`explicit_time_limit`).
    n_lists : int
    progress : callable(t, seconds), optional

    Returns
    -------
    summary : dict
        ``frames``, ``dt0``, ``node_updates``, ``max_displacement`` (mm), ``time``.
    """
    from cutkit.io.series import SeriesWriter

    if not (np.isfinite(seconds) and seconds > 0):
        raise InputError(f"seconds must be a positive number, got {seconds}")
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(f"fps must be a positive number, got {fps}")
    sm = build_spring_model(tet_model)
    state = initial_state(sm)
    if dt0 is None:
        dt0 = DT0_FRACTION * explicit_time_limit(sm)
    edge = float(np.mean(sm.rest_length)) if sm.n_springs else 1.0
    lists = NodeLists(sm, state, dt0, n_lists, displacement_tolerance=RUN_TOLERANCE_FRACTION * edge)
    control = Control(gravity=np.asarray(gravity_mm_s2, np.float64))
    n_frames = max(1, int(np.ceil(seconds * fps - 1e-9)))
    times = np.linspace(0.0, seconds, n_frames + 1)
    tets = np.ascontiguousarray(tet_model.tets, np.int64)

    with SeriesWriter(out_dir, "relax") as series:
        for i, t in enumerate(times):
            if i:
                lists.advance(control, float(t))
            series.write(
                float(t),
                state.positions,
                tets,
                point_data={
                    "displacement": state.positions - sm.rest_positions,
                    "velocity": state.velocities,
                    "node_list": state.node_list.astype(np.int32),
                },
            )
            if progress is not None:
                progress(float(t), float(seconds))
    disp = np.linalg.norm(state.positions - sm.rest_positions, axis=1)
    return {
        "frames": len(times),
        "dt0": float(dt0),
        "node_updates": int(state.n_updates.sum()),
        "max_displacement": float(disp.max(initial=0.0)),
        "time": float(state.time),
    }
