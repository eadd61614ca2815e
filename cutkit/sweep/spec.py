"""Sweep specs: the TOML file that lists the models, trajectories and parameters of a study.

See ``docs/sweep.md`` for the format.  :func:`load_spec` reads the file and
checks every key; :meth:`SweepSpec.resolve` loads the models and checks
each run's parameters against its model.  A problem is one
:class:`~cutkit.errors.InputError` line naming the file and the key.

Parameters are named by dotted strings:

* ``material.<label>.<field>``: a column of the materials table for one
  label (its number or its name), e.g. ``material.muscle.F_enter``;
* ``option.<field>``: a field of :class:`cutkit.simulate.SimulateOptions`,
  e.g. ``option.hold_s``;
* ``incision.<field>``: a parameter of a generated incision
  (:class:`cutkit.cutting.incision.Incision`), e.g. ``incision.depth``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

import numpy as np

from cutkit.errors import InputError

TOP_KEYS = ("sweep", "options", "models", "trajectories", "product", "runs")
SWEEP_KEYS = {"name": str, "description": str, "retries": int, "threads_per_run": int}
#: Options every sweep run starts from (a sweep writes no frames or model unless asked).
SWEEP_OPTION_DEFAULTS = {"frames": False, "write_model": False, "png": False}
PREFIXES = ("material", "option", "incision")


@dataclass
class Run:
    """One simulation of a sweep.

    Attributes
    ----------
    model, trajectory : str
        Names of the spec's model and trajectory.
    params : dict of str to value
        The run's parameters by dotted name (``material.muscle.E``, ...).
    key : str
        Content key: 16 hex digits of sha256 over the model's content hash,
        the trajectory, the parameters, the options and the cutkit version.
    """

    model: str
    trajectory: str
    params: dict
    key: str = ""


@dataclass
class SweepSpec:
    """A loaded spec.

    Attributes
    ----------
    path : Path
    name : str
    retries : int
        Dask's retries of a task that raised outside the run (a run that
        fails inside is recorded, not retried; a run whose worker died is
        rescheduled by the scheduler up to its ``allowed-failures``).
    threads_per_run : int
        numba threads of each run.
    options : dict
        SimulateOptions fields for every run.
    models : dict of str to dict
        The ``[[models]]`` entries by name.
    trajectories : dict of str to dict
        The ``[[trajectories]]`` entries by name.
    runs : list of Run
        Product runs, then explicit runs (keys filled in by :meth:`resolve`).
    param_names : list of str
        Every parameter name used, in first-seen order (the result columns).
    """

    path: Path
    name: str = ""
    retries: int = 2
    threads_per_run: int = 1
    options: dict = field(default_factory=dict)
    models: dict = field(default_factory=dict)
    trajectories: dict = field(default_factory=dict)
    runs: list = field(default_factory=list)
    param_names: list = field(default_factory=list)

    def resolve(self, models: dict | None = None) -> dict:
        """Load the models, read the trajectory files, check every run and fill in its key.

        Parameters
        ----------
        models : dict of str to TetModel, optional
            Models already loaded (by name); the others are loaded here.

        Returns
        -------
        loaded : dict
            ``{"models": {name: TetModel}, "model_hashes": {name: str},
            "trajectories": {name: Trajectory or None}}`` (None for generated ones).
        """
        import cutkit
        from cutkit.sweep.models import load_model_source, model_hash

        where = self.path.name
        base = self.path.parent
        used_models = sorted({r.model for r in self.runs})
        loaded = dict(models or {})
        for name in used_models:
            if name not in loaded:
                loaded[name] = load_model_source(self.models[name], base, f"{where}: models.{name}")
        hashes = {name: model_hash(loaded[name]) for name in used_models}
        trajs, traj_ids = {}, {}
        for name in sorted({r.trajectory for r in self.runs}):
            entry = self.trajectories[name]
            if "file" in entry:
                from cutkit.cutting.trajectory import read_trajectory

                traj = read_trajectory(_resolve(entry["file"], base), **entry.get("blade", {}))
                trajs[name] = traj
                h = hashlib.sha256()
                for a in (traj.t, traj.tip, traj.a, traj.n):
                    h.update(np.ascontiguousarray(a).tobytes())
                h.update(repr((traj.blade_length, traj.blade_breadth)).encode())
                traj_ids[name] = {"file": h.hexdigest()}
            else:
                trajs[name] = None
                traj_ids[name] = {"incision": entry["incision"]}
        for i, run in enumerate(self.runs):
            _check_run_against_model(run, loaded[run.model], self.trajectories[run.trajectory], where)
            ident = {"cutkit": cutkit.__version__, "model": hashes[run.model], "trajectory": traj_ids[run.trajectory],
                     "params": run.params, "options": self.options}
            blob = json.dumps(ident, sort_keys=True, default=str).encode()
            run.key = hashlib.sha256(blob).hexdigest()[:16]
        return {"models": loaded, "model_hashes": hashes, "trajectories": trajs}


def load_spec(path) -> SweepSpec:
    """Read and check a sweep spec.

    Parameters
    ----------
    path : path-like
        The TOML file.

    Returns
    -------
    SweepSpec
        Runs listed but not yet keyed (:meth:`SweepSpec.resolve` loads the
        models and keys them).

    Raises
    ------
    InputError
        One line naming the file and the bad key.
    """
    path = Path(path)
    where = path.name
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    for key in data:
        if key not in TOP_KEYS:
            raise InputError(f"{where}: {key}: unknown table (known: {', '.join(TOP_KEYS)})")
    spec = SweepSpec(path=path)

    sweep = _table(data, "sweep", where)
    for key, value in sweep.items():
        kind = SWEEP_KEYS.get(key)
        if kind is None:
            raise InputError(f"{where}: sweep.{key}: unknown key (known: {', '.join(SWEEP_KEYS)})")
        if not isinstance(value, kind) or isinstance(value, bool):
            raise InputError(f"{where}: sweep.{key}: must be {_kind_name(kind)}, got {value!r}")
    spec.name = sweep.get("name", path.stem)
    spec.retries = sweep.get("retries", 2)
    spec.threads_per_run = sweep.get("threads_per_run", 1)
    if spec.retries < 0:
        raise InputError(f"{where}: sweep.retries: must be >= 0, got {spec.retries}")
    if spec.threads_per_run < 1:
        raise InputError(f"{where}: sweep.threads_per_run: must be >= 1, got {spec.threads_per_run}")

    options = _table(data, "options", where)
    for key, value in options.items():
        _check_option(key, value, f"{where}: options.{key}")
    spec.options = {**SWEEP_OPTION_DEFAULTS, **options}

    spec.models = _named_entries(data, "models", where, ("path", "recipe", "slab"))
    spec.trajectories = _named_entries(data, "trajectories", where, ("file", "incision"))
    for name, entry in spec.trajectories.items():
        w = f"{where}: trajectories.{name}"
        for key in entry:
            if key not in ("name", "file", "incision", "blade"):
                raise InputError(f"{w}.{key}: unknown key (known: name, file, incision, blade)")
        if "incision" in entry:
            _check_incision(entry["incision"], f"{w}.incision")
        if "blade" in entry:
            if "file" not in entry:
                raise InputError(f"{w}.blade: only for trajectory files (a generated incision has its own)")
            for key, value in _as_table(entry["blade"], f"{w}.blade").items():
                if key not in ("blade_length", "blade_breadth"):
                    raise InputError(f"{w}.blade.{key}: unknown key (known: blade_length, blade_breadth)")
                if not _is_number(value) or not value > 0:
                    raise InputError(f"{w}.blade.{key}: must be a positive number, got {value!r}")

    runs: list[Run] = []
    names: list[str] = []
    if "product" in data:
        product = _as_table(data["product"], f"{where}: product")
        chosen = {}
        for axis, known in (("models", spec.models), ("trajectories", spec.trajectories)):
            value = product.pop(axis, list(known))
            if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
                raise InputError(f"{where}: product.{axis}: must be a non-empty list of names, got {value!r}")
            for v in value:
                if v not in known:
                    raise InputError(f"{where}: product.{axis}: no {axis[:-1]} named {v!r} "
                                     f"(known: {', '.join(known)})")
            chosen[axis] = value
        axes = _flatten(product, "")
        for name, values in axes.items():
            w = f"{where}: product.{name}"
            if not isinstance(values, list) or not values:
                raise InputError(f"{w}: must be a non-empty list of values, got {values!r}")
            for v in values:
                _check_param(name, v, w)
            if name not in names:
                names.append(name)
        keys = list(axes)
        for m, t in itertools.product(chosen["models"], chosen["trajectories"]):
            for combo in itertools.product(*(axes[k] for k in keys)):
                runs.append(Run(model=m, trajectory=t, params=dict(zip(keys, combo))))
    if not isinstance(data.get("runs", []), list):
        raise InputError(f"{where}: runs: must be a list of [[runs]] tables")
    for i, entry in enumerate(data.get("runs", [])):
        w = f"{where}: runs[{i}]"
        entry = dict(_as_table(entry, w))
        model = entry.pop("model", next(iter(spec.models)) if len(spec.models) == 1 else None)
        traj = entry.pop("trajectory", next(iter(spec.trajectories)) if len(spec.trajectories) == 1 else None)
        if model not in spec.models:
            raise InputError(f"{w}.model: must name one of the models ({', '.join(spec.models)}), got {model!r}")
        if traj not in spec.trajectories:
            raise InputError(f"{w}.trajectory: must name one of the trajectories "
                             f"({', '.join(spec.trajectories)}), got {traj!r}")
        params = _flatten(entry, "")
        for name, v in params.items():
            _check_param(name, v, f"{w}.{name}")
            if name not in names:
                names.append(name)
        runs.append(Run(model=model, trajectory=traj, params=params))
    if "product" not in data and "runs" not in data:
        runs = [Run(model=m, trajectory=t, params={}) for m in spec.models for t in spec.trajectories]
    for run in runs:
        if any(k.startswith("incision.") for k in run.params) and "incision" not in spec.trajectories[run.trajectory]:
            bad = next(k for k in run.params if k.startswith("incision."))
            raise InputError(f"{where}: {bad}: trajectory {run.trajectory!r} is a file, not a generated incision")
    for name, entry in spec.trajectories.items():
        if "incision" in entry:
            for key in ("start", "end"):
                if key not in entry["incision"] and not all(f"incision.{key}" in r.params for r in runs
                                                            if r.trajectory == name):
                    raise InputError(f"{where}: trajectories.{name}.incision.{key}: missing")
    spec.runs = runs
    spec.param_names = names
    return spec


def run_incision(spec: SweepSpec, run: Run) -> dict:
    """The incision parameters of a run on a generated trajectory (the entry's, then the run's)."""
    params = dict(spec.trajectories[run.trajectory]["incision"])
    for k, v in run.params.items():
        if k.startswith("incision."):
            params[k.split(".", 1)[1]] = v
    return params


# ---------------------------------------------------------------- checks


def _check_run_against_model(run: Run, model, traj_entry: dict, where: str) -> None:
    labels = {str(int(x)): i for i, x in enumerate(model.materials.label)}
    names = {n: i for i, n in enumerate(model.materials.name)}
    for name in run.params:
        if not name.startswith("material."):
            continue
        parts = name.split(".")
        label, fieldname = parts[1], parts[2]
        if label not in labels and label not in names:
            known = [f"{lab} ({n})" for lab, n in zip(labels, model.materials.name)]
            raise InputError(f"{where}: {name}: model {run.model!r} has no label {label!r} "
                             f"(its labels: {', '.join(known)})")
        if fieldname not in model.materials.values:
            raise InputError(f"{where}: {name}: unknown material field {fieldname!r} "
                             f"(known: {', '.join(model.materials.values)})")


def _check_param(name: str, value, where: str) -> None:
    parts = name.split(".")
    if parts[0] not in PREFIXES:
        raise InputError(f"{where}: unknown parameter (names start with {', '.join(p + '.' for p in PREFIXES)})")
    if parts[0] == "material":
        if len(parts) != 3:
            raise InputError(f"{where}: material parameters are named material.<label>.<field>")
        if not _is_number(value):
            raise InputError(f"{where}: must be a number, got {value!r}")
    elif parts[0] == "option":
        if len(parts) != 2:
            raise InputError(f"{where}: options are named option.<field>")
        _check_option(parts[1], value, where)
    else:
        if len(parts) != 2:
            raise InputError(f"{where}: incision parameters are named incision.<field>")
        from cutkit.cutting.incision import Incision

        known = [f.name for f in dataclasses.fields(Incision)]
        if parts[1] not in known:
            raise InputError(f"{where}: unknown incision parameter (known: {', '.join(known)})")


def _check_option(key: str, value, where: str) -> None:
    from cutkit.simulate import SimulateOptions

    known = [f.name for f in dataclasses.fields(SimulateOptions)]
    if key not in known:
        raise InputError(f"{where}: unknown simulate option (known: {', '.join(known)})")
    if isinstance(value, (dict, list)):
        raise InputError(f"{where}: must be a single value, got {value!r}")


def _check_incision(values, where: str) -> None:
    from cutkit.cutting.incision import Incision

    values = _as_table(values, where)
    known = [f.name for f in dataclasses.fields(Incision)]
    for key in values:
        if key not in known:
            raise InputError(f"{where}.{key}: unknown incision parameter (known: {', '.join(known)})")


def _named_entries(data: dict, key: str, where: str, sources: tuple[str, ...]) -> dict:
    entries = data.get(key)
    if not isinstance(entries, list) or not entries:
        raise InputError(f"{where}: {key}: at least one [[{key}]] entry is needed")
    out: dict[str, dict] = {}
    for i, entry in enumerate(entries):
        w = f"{where}: {key}[{i}]"
        entry = _as_table(entry, w)
        name = entry.get("name")
        if not isinstance(name, str) or not name or "/" in name:
            raise InputError(f"{w}.name: a name is needed (a string without '/'), got {name!r}")
        if name in out:
            raise InputError(f"{w}.name: {name!r} is used twice")
        given = [s for s in sources if s in entry]
        if len(given) != 1:
            raise InputError(f"{where}: {key}.{name}: give exactly one of {', '.join(sources)}")
        if key == "models":
            for k in entry:
                if k not in ("name",) + sources:
                    raise InputError(f"{where}: {key}.{name}.{k}: unknown key (known: name, {', '.join(sources)})")
            src = entry[given[0]]
            if given[0] == "slab":
                _as_table(src, f"{where}: {key}.{name}.slab")
            elif not isinstance(src, str):
                raise InputError(f"{where}: {key}.{name}.{given[0]}: must be a path, got {src!r}")
        out[name] = entry
    return out


def _table(data: dict, key: str, where: str) -> dict:
    return _as_table(data.get(key, {}), f"{where}: {key}")


def _as_table(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise InputError(f"{where}: must be a table, got {value!r}")
    return value


def _flatten(table: dict, prefix: str) -> dict:
    """Nested tables to dotted names: {"material": {"muscle": {"E": v}}} -> {"material.muscle.E": v}."""
    out = {}
    for k, v in table.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, name + "."))
        else:
            out[name] = v
    return out


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _kind_name(kind) -> str:
    return {str: "a string", int: "a whole number"}.get(kind, str(kind))


def _resolve(path, base: Path) -> Path:
    p = Path(path)
    return p if p.is_absolute() else base / p
