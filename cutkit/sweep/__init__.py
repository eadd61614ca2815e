"""Parameter studies: many ``simulate`` runs over models x trajectories x parameters, on Dask.

``load_spec`` reads a sweep spec (TOML, ``docs/sweep.md``), ``run_sweep``
runs it on an embedded local cluster or an existing one and writes one row
per run to ``results.parquet`` and ``results.csv``.
"""

from cutkit.sweep.models import model_hash, slab_model
from cutkit.sweep.runner import SweepReport, local_cluster, run_sweep
from cutkit.sweep.spec import Run, SweepSpec, load_spec

__all__ = ["load_spec", "run_sweep", "local_cluster", "SweepSpec", "SweepReport", "Run", "slab_model",
           "model_hash"]
