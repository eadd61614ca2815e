"""Preloaded by the workers of the embedded cluster (``dask worker --preload``).

Ctrl-C in a terminal reaches every process of the foreground group; the
workers leave it to the main process, which cancels the sweep, writes the
results table and closes the cluster.
"""

import signal
import threading


def dask_setup(worker) -> None:
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
