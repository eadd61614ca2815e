"""The results table of a sweep: ``results.parquet`` and ``results.csv``, one row per run.

Each finished run's row is first written alone to ``runs/<key>/result.json``
(atomically), then the two tables are rewritten from all rows (atomically,
at most every ``min_interval_s`` and always at the end).  A crash therefore
loses no finished run: :meth:`ResultsTable.load` gathers the rows of the
tables and of every ``result.json``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import time
from pathlib import Path

from cutkit.io.atomic import atomic_output, write_text_atomic
from cutkit.sweep.worker import FIGURES

#: Columns before the parameters and after them.
LEAD_COLUMNS = ("key", "model", "trajectory")
TAIL_COLUMNS = ("status", "error") + FIGURES + ("worker",)


class ResultsTable:
    """Rows by run key, written to ``OUT/results.parquet`` and ``OUT/results.csv``.

    Parameters
    ----------
    out_dir : path-like
    param_names : list of str
        Parameter columns, in order (more are appended as rows bring them).
    min_interval_s : float
        Shortest time between two rewrites of the tables by :meth:`add`.
    """

    def __init__(self, out_dir, param_names=(), min_interval_s: float = 1.0):
        self.out_dir = Path(out_dir)
        self.rows: dict[str, dict] = {}
        self.param_names = list(param_names)
        self.min_interval_s = float(min_interval_s)
        self._last_write = -math.inf
        self._dirty = False

    @property
    def parquet_path(self) -> Path:
        return self.out_dir / "results.parquet"

    @property
    def csv_path(self) -> Path:
        return self.out_dir / "results.csv"

    def load(self) -> int:
        """Read the rows an earlier sweep left in this folder; returns how many."""
        if self.parquet_path.is_file():
            import pyarrow.parquet as pq

            for row in pq.read_table(self.parquet_path).to_pylist():
                self.rows[row["key"]] = row
        for path in sorted((self.out_dir / "runs").glob("*/result.json")):
            try:
                row = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue  # never half written (atomic), but be safe with foreign files
            self.rows[row["key"]] = row
        for row in self.rows.values():
            for k in row:
                if k not in LEAD_COLUMNS and k not in TAIL_COLUMNS and k not in self.param_names:
                    self.param_names.append(k)
        return len(self.rows)

    def add(self, row: dict) -> None:
        """Record a finished run: its files and ``result.json`` now, the tables when due.

        ``row["_files"]`` (name to text), when present, are written to
        ``runs/<key>/`` and left out of the row.
        """
        row = dict(row)
        files = row.pop("_files", None) or {}
        for name, text in files.items():
            write_text_atomic(self.out_dir / "runs" / row["key"] / name, text)
        self.rows[row["key"]] = row
        for k in row:
            if k not in LEAD_COLUMNS and k not in TAIL_COLUMNS and k not in self.param_names:
                self.param_names.append(k)
        write_text_atomic(self.out_dir / "runs" / row["key"] / "result.json",
                          json.dumps(row, default=_json_default) + "\n")
        self._dirty = True
        if time.monotonic() - self._last_write >= self.min_interval_s:
            self.write()

    def flush(self) -> None:
        """Write the tables if a row came since the last write."""
        if self._dirty or not self.parquet_path.exists():
            self.write()

    @property
    def columns(self) -> list[str]:
        return list(LEAD_COLUMNS) + self.param_names + list(TAIL_COLUMNS)

    def write(self) -> None:
        """Rewrite ``results.parquet`` and ``results.csv`` from all rows (atomically)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        cols = self.columns
        rows = list(self.rows.values())
        data = {c: [_cell(r.get(c)) for r in rows] for c in cols}
        arrays = {c: _array(pa, c, v) for c, v in data.items()}
        table = pa.table(arrays)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        with atomic_output(self.parquet_path) as tmp:
            pq.write_table(table, tmp)
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(cols)
        for r in rows:
            w.writerow(["" if r.get(c) is None else _csv_cell(r.get(c)) for c in cols])
        with atomic_output(self.csv_path) as tmp:
            tmp.write_text(buf.getvalue(), encoding="utf-8")
        self._last_write = time.monotonic()
        self._dirty = False


def _cell(v):
    if isinstance(v, float) and math.isnan(v):
        return None
    if isinstance(v, (list, tuple)):
        return json.dumps(list(v))
    return v


def _array(pa, name, values):
    """One column: floats where every value is a number, else strings (or bools)."""
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return pa.array(values, pa.bool_())
    if present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        if name in ("cut_tets", "inverted_tets") and all(isinstance(v, int) for v in present):
            return pa.array(values, pa.int64())
        return pa.array([None if v is None else float(v) for v in values], pa.float64())
    return pa.array([None if v is None else str(v) for v in values], pa.string())


def _csv_cell(v):
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return json.dumps(list(v))
    return v


def _json_default(v):
    import numpy as np

    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON serialisable: {type(v).__name__}")
