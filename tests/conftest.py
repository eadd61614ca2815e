"""Test-wide settings.

The suite runs on every core (``-n auto --dist loadfile`` in pyproject.toml):
each test file runs whole on one worker, so its module fixtures are built
once.  The session's demo
knee is built once for all workers: the first to need it builds it under a
file lock in the run's shared temporary folder, the others read it there.
Each worker gives numba an equal share of the cores (at least one thread);
the tests that compare thread counts set them explicitly.  The property
tests' examples are the same on every run unless
``CUTKIT_HYPOTHESIS_PROFILE=explore`` (below).
"""

import os
import signal
import threading

import pytest
from hypothesis import settings

#: The property tests draw the same examples on every run ("repeatable": a failure seen once is seen
#: again, and CI does not pass or fail by the luck of a draw); CUTKIT_HYPOTHESIS_PROFILE=explore draws
#: fresh ones (what `benchmarks/cut_fresh_draw.py` does for the thousand paths).  Neither keeps an
#: example database.
settings.register_profile("repeatable", derandomize=True, database=None)
settings.register_profile("explore", database=None)
settings.load_profile(os.environ.get("CUTKIT_HYPOTHESIS_PROFILE", "repeatable"))


def pytest_configure(config):
    if "PYTEST_XDIST_WORKER" in os.environ:
        # a worker's environment says COLUMNS=80; the commands' output is piped in the tests,
        # where tables are printed whole (cutkit.cli._ui), as in a run without workers
        os.environ.pop("COLUMNS", None)
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False  # the order of pytest_collection_modifyitems stands
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers > 1:
        import numba

        numba.set_num_threads(max(1, min(numba.config.NUMBA_NUM_THREADS, (os.cpu_count() or 1) // workers)))


def pytest_collection_modifyitems(config, items):
    """The order the workers take the test files in (``--dist loadfile``: a file runs whole on one
    worker, so a module fixture is built once).

    The files of :data:`FIRST` in their order (the first builds the demo knee, about a minute on
    two cores), then the files with slow tests, heaviest first, then the other files that read the
    knee (built by then), then the rest, which even out the workers' ends.  xdist keeps this order
    (its reordering by the number of tests is switched off in :func:`pytest_configure`) and starts
    each worker on two files: the first and third of the order go to one, the second and fourth to
    the other."""
    files = {}
    for item in items:
        f = files.setdefault(item.path, {"slow": 0, "knee": False, "first": len(files)})
        f["slow"] += item.get_closest_marker("slow") is not None
        f["knee"] |= "demo_knee" in item.fixturenames or item.get_closest_marker("knee") is not None

    def rank(item):
        f = files[item.path]
        if item.path.name in FIRST:
            return (0, FIRST.index(item.path.name), f["first"])
        if f["knee"]:
            return (2, 0, f["first"])
        return (1, -f["slow"], f["first"]) if f["slow"] else (3, 0, f["first"])

    items.sort(key=rank)  # stable: each file keeps its tests' order


#: The test files run first, in this order.  The first's module fixture builds the demo knee, then
#: simulates on it, with the third after it on that worker; the other worker starts on the cut's
#: own files (second and fourth), so that in a fresh clone the two compile different numba kernels
#: first and each later loads what the other compiled, rather than both compiling the simulation's
#: kernels at once.  The fifth to seventh use no relaxation kernel: the cut's worker takes them
#: while the knee's worker still compiles the relaxation's kernels for the knee's settle (about
#: 50 s of compiling done twice otherwise, measured with numba's compile events in a fresh clone).
FIRST = ("test_knee_tissue.py", "test_cut_properties.py", "test_simulate.py", "test_cut_thousand_paths.py",
         "test_isovolume.py", "test_cut_kernels.py", "test_packaging.py")


@pytest.fixture(autouse=True)
def _sigpipe_ignored():
    """Every test starts with SIGPIPE ignored, as Python sets it: a C library that resets it
    (gmsh's initialisation does) would otherwise let a write to a closed socket kill the run."""
    if hasattr(signal, "SIGPIPE") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    yield


@pytest.fixture(scope="session", autouse=True)
def _settle_cache_of_this_run(tmp_path_factory):
    """Settles are cached in a folder of this test run (shared by its tests and the commands
    they start), never in the user's cache."""
    import os

    folder = tmp_path_factory.mktemp("settle-cache")
    old = os.environ.get("CUTKIT_CACHE_DIR")
    os.environ["CUTKIT_CACHE_DIR"] = str(folder)
    yield folder
    if old is None:
        os.environ.pop("CUTKIT_CACHE_DIR", None)
    else:
        os.environ["CUTKIT_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def demo_knee(tmp_path_factory):
    """The demo knee built once for the whole run: ``(folder, knee.h5, the build's report)``.

    The tests that only read it share it (a build takes about a minute on two
    cores); the test of the build's reuse copies the folder.  With several
    workers the first one builds it under a lock in the run's shared folder
    and leaves the build's report beside it for the others.
    """
    import fcntl
    import os
    import pickle

    from cutkit.demo import build_or_reuse

    shared = tmp_path_factory.getbasetemp()
    if "PYTEST_XDIST_WORKER" in os.environ:
        shared = shared.parent  # the folder all workers' temporary folders are in
    folder = shared / "demo-knee"
    with open(shared / "demo-knee.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        path, reused, report = build_or_reuse(folder)
        if reused:
            report = pickle.loads((shared / "demo-knee.report").read_bytes())
        else:
            (shared / "demo-knee.report").write_bytes(pickle.dumps(report))
    return folder, path, report
