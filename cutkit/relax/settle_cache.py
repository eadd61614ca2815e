"""A cache of settled states: a model settles once, not at the start of every run.

The element model's settle (a static solve under prestress and boundary
conditions: :func:`cutkit.relax.newton.newton_static`, or
:func:`cutkit.relax.settle.settle_static` for the ``vbd`` solver) takes
about 2 s (8 s) on the demo knee on one core, and every ``simulate`` run,
sweep job and live session on
the same model and materials makes the same one.  Its result is kept under
a key of everything it reads: the elements (``tets``, ``Dminv``,
``volume``, ``mu``, ``lam``), the fixed nodes, the start and rest
positions, the solve's tolerances and iteration limit, the source of the
modules that compute it and the versions of the libraries it calls.  A hit
gives the very positions the solve would give, bit for bit, so a cached
run simulates exactly what an uncached one does (tested).

The folder is ``$CUTKIT_CACHE_DIR`` (``off`` or empty: no cache), else
``$XDG_CACHE_HOME/cutkit`` or ``~/.cache/cutkit``; its ``settle/`` holds
one ``.npz`` per key.  A file that cannot be read is recomputed and
replaced; a folder that cannot be written leaves the run uncached.  Files
are written to a temporary name and renamed, so a reader never sees half
of one.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

#: Bumped when the file layout or the key's contents change.
CACHE_FORMAT = 1
#: The modules whose source decides a settle's result (relative to the package).
_SOURCES = ("relax", "tissue", "threads.py")


def cache_dir() -> Path | None:
    """The folder of cached settles, or None when caching is off (``CUTKIT_CACHE_DIR=off``)."""
    env = os.environ.get("CUTKIT_CACHE_DIR")
    if env is not None:
        return None if env.strip().lower() in ("", "off", "0", "none") else Path(env) / "settle"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "cutkit" / "settle"


def _code_fingerprint() -> bytes:
    import pyamg
    import scipy

    import cutkit

    h = hashlib.sha256()
    root = Path(cutkit.__file__).parent
    for rel in _SOURCES:
        p = root / rel
        for f in sorted(p.rglob("*.py")) if p.is_dir() else [p]:
            h.update(f.relative_to(root).as_posix().encode())
            h.update(f.read_bytes())
    h.update(f"{cutkit.__version__} {np.__version__} {scipy.__version__} {pyamg.__version__}".encode())
    return h.digest()


def settle_key(em, positions, rest_positions, params: dict) -> str:
    """Hex key of a settle: the element model ``em``'s elements and fixed nodes, positions (n, 3)
    float64 before the settle, rest positions (n, 3) float64, the solve's ``params`` and the code."""
    h = hashlib.sha256()
    h.update(f"cutkit-settle {CACHE_FORMAT}".encode())
    h.update(_code_fingerprint())
    h.update(json.dumps(params, sort_keys=True).encode())
    m = int(em.n_elements)
    for a in (em.tets[:m], em.Dminv[:m], em.volume[:m], em.mu[:m], em.lam[:m], em.fixed, em.adj_degree,
              positions, rest_positions):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def load(key: str) -> tuple[np.ndarray, dict] | None:
    """The settled positions (n, 3) float64 and the settle's report under ``key``, or None."""
    folder = cache_dir()
    if folder is None:
        return None
    path = folder / f"{key}.npz"
    try:
        with np.load(path, allow_pickle=False) as z:
            positions = np.array(z["positions"], np.float64)
            info = json.loads(str(z["info"]))
        return positions, info
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # missing, truncated, foreign: settle again
        return None


def save(key: str, positions: np.ndarray, info: dict) -> bool:
    """Keep a settle's result under ``key`` (write, then rename); False when the folder is not writable."""
    folder = cache_dir()
    if folder is None:
        return False
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{key}.", suffix=".npz", dir=folder)
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez(f, positions=np.asarray(positions, np.float64), info=np.array(json.dumps(info)))
            os.replace(tmp, folder / f"{key}.npz")
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return True
    except OSError:
        return False
