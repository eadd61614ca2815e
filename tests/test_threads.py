"""numba threads: --threads, CUTKIT_THREADS, the default, and identical results with 1 and 2 threads."""

import os
import sys

import numba
import numpy as np
import pytest

from cutkit.cli.main import main
from cutkit.threads import available_cores, configure_threads, default_threads, free_cores


@pytest.fixture(autouse=True)
def _restore_threads():
    before = numba.get_num_threads()
    yield
    numba.set_num_threads(before)


def test_default_is_free_cores_never_more_than_cores(monkeypatch):
    cores = available_cores()
    monkeypatch.setattr("os.getloadavg", lambda: (cores + 3.0, 0.0, 0.0))
    monkeypatch.setattr("cutkit.threads.busy_cores_now", lambda: float(cores + 3))
    assert free_cores(cores) == 1
    monkeypatch.setattr("os.getloadavg", lambda: (0.0, 0.0, 0.0))
    assert free_cores(cores) == cores
    assert 1 <= default_threads() <= cores


def test_a_load_that_has_ended_does_not_count(monkeypatch):
    """The load average remembers a run that just ended; the cores busy now decide."""
    calls = []

    def idle_now():
        calls.append(1)
        return 0.1

    monkeypatch.setattr("os.getloadavg", lambda: (4.0, 0.0, 0.0))
    monkeypatch.setattr("cutkit.threads.busy_cores_now", idle_now)
    assert free_cores(2) == 2 and calls
    monkeypatch.setattr("cutkit.threads.busy_cores_now", lambda: 1.2)
    assert free_cores(2) == 1
    monkeypatch.setattr("cutkit.threads.busy_cores_now", lambda: None)  # no counters: the load average
    assert free_cores(2) == 1
    calls.clear()
    monkeypatch.setattr("os.getloadavg", lambda: (0.2, 0.0, 0.0))
    monkeypatch.setattr("cutkit.threads.busy_cores_now", idle_now)
    assert free_cores(2) == 2 and not calls  # an idle load average is believed without a sample


def test_busy_cores_now_reads_the_processor_counters(tmp_path):
    import threading

    from cutkit.threads import _cpu_times, busy_cores_now

    stat = tmp_path / "stat"
    stat.write_text("cpu  100 5 50 800 45 0 0 0 0 0\ncpu0 1 2 3 4 5\n")
    assert _cpu_times(stat) == (155, 1000)  # busy: user + nice + system; idle: idle + iowait
    assert busy_cores_now(0.01, tmp_path / "missing") is None
    stat.write_text("intr 1 2 3\n")
    assert busy_cores_now(0.01, stat) is None
    # a thread spinning through the sample keeps at least half a core busy, whatever else runs (it
    # spins until the sample is taken, not for a time that a stall before the sample could use up)
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            pass

    th = threading.Thread(target=spin)
    th.start()
    try:
        busy = busy_cores_now(0.3)
    finally:
        stop.set()
        th.join()
    assert busy is not None and busy >= 0.5, busy


def test_explicit_and_environment(monkeypatch):
    pool = numba.config.NUMBA_NUM_THREADS
    assert configure_threads(1) == 1 and numba.get_num_threads() == 1
    monkeypatch.setenv("CUTKIT_THREADS", str(pool + 5))
    assert configure_threads() == pool  # never more than numba's pool
    assert configure_threads(1) == 1  # the argument wins over the environment


@pytest.mark.parametrize("bad", ["0", "-2", "two"])
def test_bad_thread_count_is_one_line(tmp_path, capsys, bad):
    code = main(["info", str(tmp_path / "missing.h5"), "--threads", bad])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [f"cutkit: error: threads must be a whole number >= 1, got {bad!r}"]


def test_every_command_takes_threads():
    import click

    from cutkit.cli.commands import COMMANDS
    from cutkit.cli.main import cli

    ctx = click.Context(cli)
    for name in COMMANDS:
        cmd = cli.get_command(ctx, name)
        if cmd is None:
            continue
        assert any(p.name == "threads" for p in cmd.params), name


def test_cli_threads_sets_numba(tmp_path, monkeypatch):
    from test_relax import block

    from cutkit.io.model_h5 import write_model

    write_model(tmp_path / "m.h5", block(2, 2, 2))
    monkeypatch.setenv("CUTKIT_THREADS", "1")
    assert main(["info", str(tmp_path / "m.h5")]) == 0
    assert numba.get_num_threads() == 1


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="numba's pool has one thread")
@pytest.mark.parametrize("material_model", ["springs", None])  # None: the model's own (the default)
def test_simulate_is_identical_with_one_and_two_threads(tmp_path, monkeypatch, material_model):
    from cutkit.cutting.trajectory import straight_incision
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.sweep import slab_model

    traj = straight_incision([3.0, 0.0, 6.3], [13.0, 0.0, 6.3], inward=[0, 1, 0], depth=4.0, approach=2.0,
                             press_time=0.2, cut_time=0.3, rate=100)
    monkeypatch.setenv("CUTKIT_CACHE_DIR", "off")  # each run settles: the settle is compared too
    out = {}
    for n in (1, 2):
        configure_threads(n)
        opt = SimulateOptions(frames=False, write_model=False, hold_s=0.1, material_model=material_model)
        s = simulate(slab_model((8, 5, 6)), traj, tmp_path / str(n), opt)
        forces = np.loadtxt(tmp_path / str(n) / "forces.csv", delimiter=",", skiprows=1, usecols=(0, 2, 3, 4))
        out[n] = (s["cut_tets"], s["new_tets"], s["cut_opening_mm"], s["inverted_tets_deformed"], forces)
    assert out[1][0] > 0  # it cut
    assert out[1][:4] == out[2][:4]
    np.testing.assert_array_equal(out[1][4], out[2][4])


def test_a_first_run_is_told_that_kernels_compile(tmp_path, monkeypatch):
    """`cutkit demo` says "compiling the numba kernels (first run only ...)" when numba's cache
    next to the kernel sources is missing (kernels_compiled is False), not when it is there."""
    from cutkit.demo.warmup import CACHE_WITNESSES, kernels_compiled

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    for rel in CACHE_WITNESSES:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("")
    assert kernels_compiled(tmp_path) is False
    for rel in CACHE_WITNESSES[:-1]:
        cache = tmp_path / rel.rsplit("/", 1)[0] / "__pycache__"
        cache.mkdir(exist_ok=True)
        (cache / (rel.rsplit("/", 1)[1][:-3] + ".kernel-12.py311.nbi")).write_text("")
    assert kernels_compiled(tmp_path) is False  # one kernel module still to compile
    rel = CACHE_WITNESSES[-1]
    cache = tmp_path / rel.rsplit("/", 1)[0] / "__pycache__"
    cache.mkdir(exist_ok=True)
    (cache / (rel.rsplit("/", 1)[1][:-3] + ".k-1.py311.nbi")).write_text("")
    assert kernels_compiled(tmp_path) is True
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert kernels_compiled(tmp_path) is None  # the cache lives elsewhere: unknown


def test_the_demos_two_processes_compile_different_kernels(monkeypatch):
    """`cutkit demo`'s second process cuts the warm-up slab and nothing else: not the decimation (the
    build, in the first process, needs it first and compiled it too) nor the kernels the short cut
    misses (the first process's share once its build is done).  The live session's warm-up in one
    process still takes them all."""
    import cutkit.simulate as simulate_module
    import cutkit.simulate.warmup as run_warmup
    from cutkit.demo.warmup import warm_up as demo_warm_up

    calls = []
    monkeypatch.setattr(simulate_module, "simulate", lambda *a, **k: calls.append("cut"))
    monkeypatch.setattr(run_warmup, "warm_up_conjugate_gradients", lambda: calls.append("cg"))
    monkeypatch.setattr(run_warmup, "warm_up_missed_kernels", lambda: calls.append("missed"))
    import cutkit.decimate as decimate_module

    monkeypatch.setattr(decimate_module, "decimate", lambda *a, **k: calls.append("decimate"))
    demo_warm_up()
    assert calls == ["cut"]
    calls.clear()
    run_warmup.warm_up(outputs=False)
    assert calls == ["cut", "cg", "missed"]
    calls.clear()
    run_warmup.warm_up_extras()
    assert calls == ["cg", "missed"]


def test_a_worker_thread_takes_the_configured_count_less_one(monkeypatch):
    """numba's thread count is per thread: a thread started after configure_threads runs on all of
    numba's threads unless it sets its own; the live workers set worker_threads(), one fewer than
    the configured count (at least one)."""
    import threading

    import cutkit.threads as T

    monkeypatch.setattr(T, "_configured", None)
    pool = numba.config.NUMBA_NUM_THREADS
    configure_threads(pool)
    assert T.configured_threads() == pool and T.worker_threads() == max(1, pool - 1)
    seen = {}

    def worker():
        seen["before"] = numba.get_num_threads()
        T.use_threads_in_this_thread(T.worker_threads())
        seen["after"] = numba.get_num_threads()

    configure_threads(1)
    assert T.worker_threads() == 1
    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen["before"] == pool  # what a thread starts with, whatever the main thread chose
    assert seen["after"] == 1
    configure_threads(pool)
    with T.threads_in_this_thread(1):
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == pool  # restored after the block


def test_one_blas_thread_limits_every_blas_and_restores_it_each_time():
    """The BLAS libraries are looked up once; every later block still runs on one BLAS thread and
    gives the threads back after."""
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info, threadpool_limits

    from cutkit.threads import one_blas_thread

    with threadpool_limits(limits=2, user_api="blas"):
        outside = [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]
        for _ in range(2):
            with one_blas_thread():
                inside = [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]
            assert inside and set(inside) == {1}
            assert [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"] == outside


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread priorities are set on Linux only")
def test_a_live_worker_yields_the_cpu_in_its_own_thread_only():
    """The relaxation and rebase threads run at WORKER_NICE; the thread that called it alone."""
    import threading

    from cutkit.threads import WORKER_NICE, yield_cpu_in_this_thread

    main_before = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    seen = {}

    def worker():
        seen["set"] = yield_cpu_in_this_thread()
        seen["nice"] = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen["nice"] == max(WORKER_NICE, main_before) and seen["set"] == (main_before < WORKER_NICE)
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == main_before


def test_a_live_worker_leaves_its_priority_alone_off_linux(monkeypatch):
    """Off Linux a native thread id is not a process id: nothing is set (another process could be named)."""
    from cutkit.threads import yield_cpu_in_this_thread

    calls = []
    monkeypatch.setattr("sys.platform", "darwin")
    monkeypatch.setattr("os.setpriority", lambda *a: calls.append(a), raising=False)
    assert yield_cpu_in_this_thread() is False and calls == []
