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
