"""Test-wide settings.

The suite runs on every core (``-n auto --dist loadgroup`` in pyproject.toml):
a test file with module-scoped fixtures is one group, so they are built once,
and every other test goes to whichever worker is free.  The session's demo
knee is built once for all workers: the first to need it builds it under a
file lock in the run's shared temporary folder, the others read it there.
Each worker gives numba an equal share of the cores (at least one thread);
the tests that compare thread counts set them explicitly.
"""

import os
import signal
import threading

import pytest

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
    """xdist groups (one per test file with module fixtures), and an order that keeps both workers busy.

    The demo knee takes a worker about a minute to build (more while numba compiles), and every
    test that reads it waits for it: the file that builds it runs first, then the heavy tests that
    do not need it, then the other knee tests, then the quick ones, which even out the workers'
    ends.  xdist keeps this order (its reordering by group size is switched off in
    :func:`pytest_configure`)."""
    module_fixtures = {}
    for item in items:
        if item.path not in module_fixtures:
            module_fixtures[item.path] = 'scope="module"' in item.path.read_text()
        if module_fixtures[item.path]:
            item.add_marker(pytest.mark.xdist_group(item.path.name))

    # a group runs as one unit on one worker, placed where its first test is: it ranks as a whole
    knee_groups = {item.path for item in items if module_fixtures[item.path] and "demo_knee" in item.fixturenames}

    def rank(item):
        knee = "demo_knee" in item.fixturenames or item.path in knee_groups or item.get_closest_marker("knee")
        if knee and item.path.name == KNEE_FIRST:
            return 0
        if knee:
            return 2
        return 1 if module_fixtures[item.path] or item.get_closest_marker("slow") else 3

    items.sort(key=rank)  # stable: each rank keeps the files' order


#: The knee test file run first: its module fixture builds the demo knee, then simulates on it.
KNEE_FIRST = "test_knee_tissue.py"


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
