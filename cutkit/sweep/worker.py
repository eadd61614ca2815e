"""One run of a sweep, as a worker runs it: parameters in, one result row out.

:func:`run_one` never raises for a problem of the run itself: the row says
``status = "failed"`` and holds the one-line error.  Only the death of the
worker process (or a bug in this module) reaches Dask, which then retries
the run on another worker.
"""

from __future__ import annotations

import contextlib
import copy
import math
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from cutkit.errors import CutkitError, InputError

#: The measured figures of a result row, in column order (units in the names).
FIGURES = ("peak_force_N", "mean_cut_force_N", "cut_tets", "opening_mm", "inverted_tets", "volume_change",
           "simulated_per_wall", "wall_s", "cpu_s")

#: Options whose outputs a run writes straight into the sweep's folder.
LARGE_OUTPUTS = ("frames", "png", "write_model", "movie")

# Runs in one worker process take turns: numba's default thread pool is not
# safe for parallel calls from several threads at once.  (Sweeps run one
# thread per worker, where this costs nothing.)
_RUN_LOCK = threading.Lock()


def one_line(exc: BaseException) -> str:
    """An exception as one line: the message of a :class:`CutkitError`, else ``Type: message``."""
    text = str(exc) if isinstance(exc, CutkitError) else f"{type(exc).__name__}: {exc}"
    return " ".join(text.split()) or type(exc).__name__


def with_materials(model, params: dict):
    """A copy of ``model`` whose materials table has the ``material.<label>.<field>`` values of ``params``.

    The model itself is not changed (workers share it between runs).

    Parameters
    ----------
    model : TetModel
    params : dict
        Run parameters; those not starting with ``material.`` are ignored.

    Raises
    ------
    InputError
        Unknown label or field, or a value that no material can have
        (not finite, a non-positive E or density, a negative coefficient,
        a Poisson ratio outside (-1, 0.5)).
    """
    overrides = [(k, v) for k, v in params.items() if k.startswith("material.")]
    if not overrides:
        return model
    mats = model.materials
    values = {k: np.array(v, dtype=np.float64, copy=True) for k, v in mats.values.items()}
    for name, value in overrides:
        _, label, fieldname = name.split(".")
        rows = [i for i, (lab, n) in enumerate(zip(mats.label, mats.name)) if str(int(lab)) == label or n == label]
        if not rows:
            raise InputError(f"{name}: the model has no label {label!r}")
        if fieldname not in values:
            raise InputError(f"{name}: unknown material field {fieldname!r}")
        v = float(value)
        if not math.isfinite(v):
            raise InputError(f"{name}: must be finite, got {value!r}")
        if fieldname in ("E", "density") and v <= 0:
            raise InputError(f"{name}: must be > 0, got {value!r}")
        if fieldname == "poisson_ratio" and not -1.0 < v < 0.5:
            raise InputError(f"{name}: must lie in (-1, 0.5), got {value!r}")
        if fieldname not in ("E", "density", "poisson_ratio") and v < 0:
            raise InputError(f"{name}: must be >= 0, got {value!r}")
        values[fieldname][rows[0]] = v
    new = copy.copy(model)
    new.materials = copy.copy(mats)
    new.materials.values = values
    return new


def simulate_options(options: dict, params: dict):
    """:class:`SimulateOptions` from the spec's options and a run's ``option.<field>`` parameters."""
    import dataclasses

    from cutkit.simulate import SimulateOptions

    merged = dict(options)
    merged.update({k.split(".", 1)[1]: v for k, v in params.items() if k.startswith("option.")})
    known = {f.name for f in dataclasses.fields(SimulateOptions)}
    for key in merged:
        if key not in known:
            raise InputError(f"option.{key}: unknown simulate option")
    opt = SimulateOptions(**merged)
    opt.check()
    return opt


def run_one(model, run: dict, out_root: str, before_run=None) -> dict:
    """Run one simulation of a sweep and return its result row.

    Parameters
    ----------
    model : TetModel
        The run's model, unchanged (material parameters are applied to a copy).
    run : dict
        ``key``, ``model``, ``trajectory`` (names), ``params`` (dotted names),
        ``options`` (the spec's), ``threads`` (numba threads), and either
        ``trajectory_data`` (a :class:`Trajectory`) or ``incision`` (the
        parameters of a generated one).
    out_root : str
        The sweep's output folder.  A run whose options ask for frames,
        pictures or the model file writes them to ``runs/<key>/`` there
        (a path the worker must see); any other run works in a temporary
        folder of the worker and returns its small outputs in the row.
    before_run : callable(run), optional
        Called first (a test hook).

    Returns
    -------
    row : dict
        ``key``, ``model``, ``trajectory``, the parameters, ``status``
        (``"ok"`` or ``"failed"``), ``error`` and the :data:`FIGURES`;
        ``_files`` maps ``forces.csv`` and ``summary.json`` to their text
        when the run worked in a temporary folder.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    row = {"key": run["key"], "model": run["model"], "trajectory": run["trajectory"], **run["params"],
           "status": "failed", "error": ""}
    row.update({k: None for k in FIGURES})
    merged = {**run["options"], **{k.split(".", 1)[1]: v for k, v in run["params"].items()
                                   if k.startswith("option.")}}
    in_place = any(bool(merged.get(k)) for k in LARGE_OUTPUTS)
    with _RUN_LOCK, contextlib.ExitStack() as stack:
        if in_place:
            out_dir = Path(out_root) / "runs" / run["key"]
        else:  # no shared file system needed: the small outputs travel back in the row
            out_dir = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="cutkit-run-")))
        try:
            if before_run is not None:
                before_run(run)
            row.update(_simulate(model, run, out_dir))
            row["status"] = "ok"
        except Exception as exc:  # the run failed: recorded, the sweep goes on
            row["error"] = one_line(exc)
        if not in_place:
            row["_files"] = {name: (out_dir / name).read_text(encoding="utf-8")
                             for name in ("forces.csv", "summary.json") if (out_dir / name).is_file()}
    row["wall_s"] = time.perf_counter() - t0
    row["cpu_s"] = time.process_time() - c0
    try:
        from dask.distributed import get_worker

        row["worker"] = get_worker().address
    except (ImportError, ValueError):
        row["worker"] = "local"
    return row


def _simulate(model, run: dict, out_dir: Path) -> dict:
    from cutkit.simulate import simulate
    from cutkit.threads import configure_threads

    configure_threads(run.get("threads", 1))
    opt = simulate_options(run["options"], run["params"])
    tet_model = with_materials(model, run["params"])
    if run.get("trajectory_data") is not None:
        traj = run["trajectory_data"]
    else:
        from cutkit.cutting.incision import Incision, incision

        traj = incision(Incision.from_dict(run["incision"], "incision"), tet_model)
    summary = simulate(tet_model, traj, out_dir, opt, model_path=run["model"])
    return figures(summary, out_dir / "forces.csv")


def figures(summary: dict, forces_csv) -> dict:
    """The measured figures of a finished run.

    Parameters
    ----------
    summary : dict
        What :func:`cutkit.simulate.simulate` returned.
    forces_csv : path-like
        Its forces.csv.

    Returns
    -------
    dict
        ``peak_force_N``: largest |F_ext| of any tick; ``mean_cut_force_N``:
        mean |F_ext| over the ticks in the cutting state (0 when it never
        cut); ``cut_tets``; ``opening_mm``: final mean distance between the
        two copies of the cut nodes; ``inverted_tets`` in the deformed
        tissue; ``volume_change``: deformed total volume of the live tets
        over their rest volume, minus 1 (the summary's); ``simulated_per_wall``.
    """
    f = np.loadtxt(forces_csv, delimiter=",", skiprows=1, usecols=(2, 3, 4), ndmin=2)
    states = np.loadtxt(forces_csv, delimiter=",", skiprows=1, usecols=(1,), dtype=str, ndmin=1)
    mag = np.linalg.norm(f, axis=1) if f.size else np.zeros(0)
    cutting = mag[states == "cutting"] if mag.size else mag
    volume_change = float(summary.get("volume_change", float("nan")))
    return {
        "peak_force_N": float(mag.max()) if mag.size else 0.0,
        "mean_cut_force_N": float(cutting.mean()) if cutting.size else 0.0,
        "cut_tets": int(summary["cut_tets"]),
        "opening_mm": float(summary["cut_opening_mm"]["final_mean"]),
        "inverted_tets": int(summary["inverted_tets_deformed"]),
        "volume_change": volume_change,
        "simulated_per_wall": float(summary["simulated_per_wall"]),
    }


