"""The scalpel as the simulation drives it: in process, or through the haptics service.

Frames: a trajectory row gives ``a`` along the blade (handle to tip) and
``n`` towards the sharp edge (docs/trajectory-format.md).  The force model
of section 6 calls the forward cutting direction ``a`` and the in-plane
direction along the blade ``n`` (docs/scalpel-model.md).  So the scalpel's
``a`` is the trajectory's ``n`` and the other way round, and the blade
plane normal is ``b = n_traj x a_traj``.
"""

from __future__ import annotations

import numpy as np

from cutkit.scalpel import (
    CUTTING,
    FREE,
    N_OUT,
    O_A,
    O_CUT,
    O_FORCE,
    O_N,
    ScalpelParams,
    ScalpelState,
)
from cutkit.scalpel import Control as ScalpelControl
from cutkit.scalpel import enter as scalpel_enter
from cutkit.scalpel import leave as scalpel_leave
from cutkit.scalpel import step as scalpel_step


#: Blade coupling of the fracture model in ``simulate``: the trajectory is a
#: recorded, position-controlled motion, so the blade edge is held to it by a
#: stiff spring (N/mm); the force the edge feels then follows from the tissue's
#: contact zone and J_c alone (docs/scalpel-model.md, eq. F1), not from the
#: hand-held device's 0.8 N/mm.
FRACTURE_K_SPRING = 100.0


def scalpel_blade(model: str) -> dict:
    """Blade constants of the force model ``model`` ("paper" or "fracture") for :class:`InProcessScalpel`."""
    if model == "fracture":
        return {"model": "fracture", "k_spring": FRACTURE_K_SPRING}
    return {}


class InProcessScalpel:
    """The scalpel force model (section 6, or fracture) stepped in this process at a fixed 1 ms.

    Parameters
    ----------
    blade : dict
        Blade constants passed to :class:`~cutkit.scalpel.ScalpelParams`
        (``blade_breadth`` ...).
    """

    def __init__(self, **blade):
        self.blade = blade
        self.state = ScalpelState()
        self.control = ScalpelControl()
        self.out = np.zeros(N_OUT)
        self.params = ScalpelParams(**blade).array()
        self._f_sim = np.zeros(3)

    @property
    def code(self) -> int:
        return int(self.state.code[0])

    @property
    def proxy(self) -> np.ndarray:
        return self.state.proxy

    def enter(self, entry, normal, tip, material: dict) -> None:
        """The blade touches tissue at ``entry``; coefficients of that tissue from now on."""
        self.params = ScalpelParams.from_material(material, **self.blade).array()
        scalpel_enter(self.state, entry, normal, tip)

    def leave(self) -> None:
        scalpel_leave(self.state)

    def tick(self, tip, a_traj, n_traj) -> np.ndarray:
        """One 1 ms step for the device pose; returns the ``out`` vector (see ``cutkit.scalpel.O_*``)."""
        self.control.set(tip, n_traj, a_traj)
        scalpel_step(self.params, self.state, self.control, self._f_sim, self.out)
        return self.out

    def close(self) -> None:
        pass


class ServiceScalpel:
    """The force model running in ``cutkit haptics serve``, reached over TCP.

    This process plays both of the service's clients: the device (it sends
    the trajectory's poses) and the simulation (it sends the entry point,
    blade plane and material, and reads the proxy back).  The service runs
    against its own 1 kHz clock, so a run with it is paced to the wall clock.

    Parameters
    ----------
    host : str
    port : int
    """

    def __init__(self, host: str, port: int, **blade):
        from cutkit.haptics.client import HapticsClient

        self.blade = blade
        self.device = HapticsClient(host, port, role="device")
        self.sim = HapticsClient(host, port, role="simulation")
        self.out = np.zeros(N_OUT)
        self._proxy = np.zeros(3)
        self._code = FREE
        self._entry = np.zeros(3)
        self._normal = np.zeros(3)
        self._contact = False
        self._last = None

    @property
    def code(self) -> int:
        return self._code

    @property
    def proxy(self) -> np.ndarray:
        return self._proxy

    def enter(self, entry, normal, tip, material: dict) -> None:
        from cutkit.scalpel import CUT_FIELDS

        self._entry[:] = entry
        self._normal[:] = normal
        self.sim.send_sim(entry, normal, material=[material[k] for k in CUT_FIELDS], contact=True)
        self._contact = True

    def leave(self) -> None:
        self.sim.send_sim(self._entry, self._normal, contact=False)
        self._contact = False
        self._code = FREE

    def tick(self, tip, a_traj, n_traj) -> np.ndarray:
        from cutkit.errors import ProtocolError

        self.device.send_pose(tip, n_traj, a_traj)
        # one SIM_UPDATE a tick, in contact or not: the service's watchdog ramps the
        # force to zero 0.1 s after the last one (docs/haptics-protocol.md)
        self.sim.send_sim(self._entry, self._normal, contact=self._contact)
        # newest state wins: take what the service has sent so far without
        # waiting for its next tick (wait only for the very first frame)
        frame = None
        while True:
            try:
                frame = self.device.read_force(0.0)
            except ProtocolError:
                break
        if frame is None:
            frame = self._last if self._last is not None else self.device.latest()
        self._last = frame
        self._code = int(frame.state)
        self._proxy[:] = frame.proxy
        self.out[:] = 0.0
        self.out[O_FORCE:O_FORCE + 3] = frame.force
        # the service sends no cut force: the force on the blade stands in for it, so the
        # tissue feels the blade's reaction as offline
        self.out[O_CUT:O_CUT + 3] = frame.force if self._code == CUTTING else 0.0
        self.out[O_A:O_A + 3] = frame.a
        self.out[O_N:O_N + 3] = frame.n
        return self.out

    def close(self) -> None:
        self.device.close()
        self.sim.close()


def parse_host_port(text: str) -> tuple[str, int]:
    """``HOST:PORT`` -> (host, port); raises InputError naming the problem."""
    from cutkit.errors import InputError

    host, sep, port = str(text).rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"--haptics must be HOST:PORT (e.g. 127.0.0.1:5005), got {text!r}")
    return host, int(port)
