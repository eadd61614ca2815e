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
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers > 1:
        import numba

        numba.set_num_threads(max(1, min(numba.config.NUMBA_NUM_THREADS, (os.cpu_count() or 1) // workers)))


def pytest_collection_modifyitems(config, items):
    """xdist groups (one per test file with module fixtures); the demo knee's single tests last.

    xdist hands out the groups first, largest first, then the single tests in
    this order.  The first group that reads the demo knee builds it (about a
    minute on two cores, longer while numba compiles); a single test that
    read it early would hold the other worker waiting for that build, so the
    single tests that read it come after all the others."""
    module_fixtures = {}
    for item in items:
        if item.path not in module_fixtures:
            module_fixtures[item.path] = 'scope="module"' in item.path.read_text()
        if module_fixtures[item.path]:
            item.add_marker(pytest.mark.xdist_group(item.path.name))

    def knee_single(item):
        knee = "demo_knee" in item.fixturenames or item.get_closest_marker("knee") is not None
        return knee and not module_fixtures[item.path]

    items.sort(key=knee_single)  # stable: the rest keeps the files' order


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
