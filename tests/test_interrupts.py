"""Stop requests wait for a loop's safe point (cutkit.interrupts), so a recording never reads a half-made update."""

import csv
import json
import os
import signal

import click
import pytest

from cutkit.interrupts import Terminated, check_stop, request_stop, safe_points


def test_outside_a_loop_the_handler_raises_itself():
    assert request_stop(Terminated) is False
    check_stop()  # nothing waits


def test_a_request_waits_for_the_next_safe_point():
    done = []
    with pytest.raises(Terminated):
        with safe_points():
            for k in range(3):
                check_stop()
                assert request_stop(Terminated) is (k == 0)  # a second request is the caller's to raise
                done.append(k)  # the rest of the update runs to its end
    assert done == [0]
    assert request_stop(Terminated) is False  # the context is gone


def test_a_request_at_the_loops_end_is_raised_on_leaving():
    with pytest.raises(KeyboardInterrupt) as info:
        with safe_points():
            assert request_stop(KeyboardInterrupt)
    assert type(info.value) is KeyboardInterrupt


def test_an_error_in_the_loop_drops_the_request_with_it():
    with pytest.raises(ValueError):
        with safe_points():
            request_stop(Terminated)
            raise ValueError("the loop's own error wins")
    with safe_points():
        check_stop()  # nothing left over from the loop before


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_the_command_line_stops_a_loop_between_two_updates(monkeypatch, sig, code):
    """The signal lands between the two halves of an update: the update ends whole, then the command exits."""
    from cutkit.cli import main as main_module

    halves = []

    @click.command("loop")
    def loop():
        with safe_points():
            for _ in range(1000):
                check_stop()
                halves.append("first")
                os.kill(os.getpid(), sig)
                for _ in range(1000):  # the handler runs at the next bytecode of the main thread
                    pass
                halves.append("second")
        raise AssertionError("the signal did not stop the loop")

    monkeypatch.setattr(main_module._TableGroup, "get_command", lambda self, ctx, name: loop)
    before = signal.getsignal(sig)
    assert main_module.main(["loop"]) == code
    assert halves == ["first", "second"]
    assert signal.getsignal(sig) == before


@pytest.mark.slow
def test_a_stop_during_a_cut_records_the_ticks_before_it(tmp_path, monkeypatch):
    """SIGTERM's request arrives in the middle of a geometry update (a cut): the update ends, the
    replay stops at the next tick, and forces.csv holds exactly the ticks done up to it."""
    from cutkit.cutting.trajectory import straight_incision
    from cutkit.simulate import SimulateOptions, simulate
    from cutkit.scalpel import STATE_NAMES
    from cutkit.simulate.session import Session
    from tests.test_simulate import slab

    traj = straight_incision([6.0, 0.0, 8.3], [26.0, 0.0, 8.3], inward=[0, 1, 0], depth=5.0, approach=3.0,
                             press_time=0.3, cut_time=0.6, rate=100)
    original = Session.geometry_update
    cutting = []  # haptic ticks done at the updates made while the blade cuts

    def geometry_update(self):
        if STATE_NAMES[self.scalpel.code] == "cutting":
            if len(cutting) == 5:  # the handler runs here, in the middle of a cut
                request_stop(Terminated)
            cutting.append(self.counts["haptic_ticks"])
        return original(self)

    monkeypatch.setattr(Session, "geometry_update", geometry_update)
    with pytest.raises(Terminated):
        simulate(slab(0.0), traj, tmp_path, SimulateOptions(frames=False, hold_s=0.0, material_model="springs"))
    assert len(cutting) == 6  # the update that took the request ran to its end, no other began
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["interrupted"] is True
    with open(tmp_path / "forces.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == cutting[-1]
    assert rows[-1]["state"] == "cutting"
