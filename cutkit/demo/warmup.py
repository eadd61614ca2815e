"""Compile (and cache) the numba kernels of the simulation on a tiny model, beside the demo's build.

``cutkit demo`` runs this in a second process while the first one builds
the model: on a fresh installation numba compiles each kernel once (then
loads it from its cache), and this way the two cores compile side by side.
The shares do not overlap: the build compiles its own kernels (isovolume,
decimation: needed within its first minute, before a second process could
have them ready), this process the cut of the run side's warm-up slab, and
the first process, once its build is done, the kernels that short cut
misses (:func:`cutkit.simulate.warmup.warm_up_extras`).  A kernel two
processes both compile costs its time twice: numba has no lock between
processes.

    python -m cutkit.demo.warmup
"""

from __future__ import annotations

import subprocess
import sys


def warm_up() -> None:
    """This process's share: cut the run side's warm-up slab with its outputs, nothing else."""
    from cutkit.simulate.warmup import warm_up as warm_up_run

    warm_up_run(extras=False)


#: Kernel modules whose numba cache tells whether this installation has compiled the demo's
#: kernels: decimation, cutting and the default element model (caches are written on first use;
#: the springs' kernels compile only when a run asks for the springs).
CACHE_WITNESSES = ("decimate/_kernels.py", "cutting/_kernels_step.py", "relax/_elastic_kernels.py")


def kernels_compiled(root=None) -> bool | None:
    """Whether the numba kernels of this installation are in numba's cache (next to the sources).

    ``root`` is the package folder (default: this installation's ``cutkit``).

    False on a first run: the kernels compile then (minutes on two cores) and
    later runs load them.  None where the cache lives elsewhere
    (``NUMBA_CACHE_DIR``) or the package folder is not writable: unknown.
    """
    import os
    from pathlib import Path

    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    root = Path(__file__).resolve().parent.parent if root is None else Path(root)
    if not os.access(root, os.W_OK):
        return None
    for rel in CACHE_WITNESSES:
        src = root / rel
        if not any((src.parent / "__pycache__").glob(src.stem + ".*.nbi")):
            return False
    return True


def start_background() -> subprocess.Popen | None:
    """Run :func:`warm_up` in a quiet child process; None if it cannot start."""
    try:
        return subprocess.Popen([sys.executable, "-m", "cutkit.demo.warmup"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except OSError:
        return None


if __name__ == "__main__":
    warm_up()
