"""Test-wide settings."""

import signal
import threading

import pytest


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
    cores); the test of the build's reuse copies the folder.
    """
    from cutkit.simulate.demo import build_or_reuse

    folder = tmp_path_factory.mktemp("demo-knee")
    path, _, report = build_or_reuse(folder)
    return folder, path, report
