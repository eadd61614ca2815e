"""Adaptive step-size control: node lists and their scheduler (paper section 5.2).

Time steps are quantised, ``dt_i = dt_0 2^i``; list i (``node_lists[i]``)
holds the free nodes stepped by dt_i (``state.node_list[k] == i``).  Each
list carries the time of its last relaxation t_i; the scheduler picks the
list with the smallest ``t_i + dt_i`` (eq. 8), advances each of its nodes
from the node's own time stamp to that time (so a node that just changed
list steps by the true elapsed time, section 5.2 last paragraph) and sets
t_i.  After a pass, nodes whose acceleration averaged over the last
:data:`~cutkit.relax.model.ACCEL_WINDOW` updates calls for a longer (or
shorter) step move one list up (or down).

Assignment criterion: the displacement error of a step of length dt with
acceleration a is about a dt^2 / 2; a node belongs to the coarsest list
with ``a dt_i^2 / 2 <= displacement_tolerance``.

The scheduler itself runs in the caller's thread or, with
:meth:`NodeLists.run_async`, on a worker thread; each list pass runs the
``nogil`` parallel kernel over the list's nodes (one colour class at a time
for Gauss-Seidel), so results are bitwise reproducible for a given thread
count and node order.
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from cutkit.errors import InputError
from cutkit.relax._kernels import MODE_EXPLICIT, halo_nodes
from cutkit.relax.integrate import advance_nodes, colour_classes, control_arrays, method_mode, synchronised
from cutkit.relax.momentum import free_momentum_start, keep_free_momentum
from cutkit.relax.model import Control, SpringModel, SpringState

#: Number of quantised step sizes dt_0 2^i by default.
DEFAULT_N_LISTS = 4
#: Scheduler times within this fraction of dt_0 count as equal (eq. 8 ties).
TIME_EPS = 1e-9


class NodeLists:
    """Node lists of quantised time steps and the eq. (8) scheduler.

    Parameters
    ----------
    model : SpringModel
    state : SpringState
        Advanced in place.  Its ``node_list`` entries are clipped to the lists.
    dt0 : float
        Finest step dt_0, s.
    n_lists : int
        Number of lists; list i steps by dt_0 2^i.
    displacement_tolerance : float
        mm; see the module docstring.
    method : str
        As in :func:`cutkit.relax.integrate.step`.
    gauss_seidel : bool
    """

    def __init__(
        self,
        model: SpringModel,
        state: SpringState,
        dt0: float,
        n_lists: int = DEFAULT_N_LISTS,
        *,
        displacement_tolerance: float = 1e-3,
        method: str = "semi-implicit",
        gauss_seidel: bool = True,
    ):
        if not (np.isfinite(dt0) and dt0 > 0):
            raise InputError(f"dt0 must be a positive number of seconds, got {dt0}")
        if not (1 <= int(n_lists) <= 30):
            raise InputError(f"n_lists must lie in 1..30, got {n_lists}")
        if not displacement_tolerance > 0:
            raise InputError(f"displacement_tolerance must be > 0, got {displacement_tolerance}")
        self.model = model
        self.state = state
        self.dt0 = float(dt0)
        self.n_lists = int(n_lists)
        self.dt = self.dt0 * 2.0 ** np.arange(self.n_lists)
        self.tolerance = float(displacement_tolerance)
        self.mode = method_mode(method)
        self.gauss_seidel = bool(gauss_seidel)
        # t_i: time of the last relaxation of list i (section 5.2)
        self.list_time = np.full(self.n_lists, float(state.time))
        nl = np.where(model.fixed, -1, np.clip(state.node_list, 0, self.n_lists - 1))
        state.node_list = nl.astype(np.int32)
        self._since_move = np.zeros(model.n_nodes, np.int64)
        self._passes = np.zeros(self.n_lists, np.int64)
        self._lists: list[np.ndarray | None] = [None] * self.n_lists
        self._classes: list[list[np.ndarray] | None] = [None] * self.n_lists
        self._halo: list[np.ndarray | None] = [None] * self.n_lists
        self._n_nodes = model.n_nodes
        self._adjacency = model.adj_nodes
        self._executor: ThreadPoolExecutor | None = None

    # -- the node lists -------------------------------------------------
    @property
    def node_lists(self) -> list[np.ndarray]:
        """``node_lists[i]``: (n_i,) int64 nodes of list i, ascending."""
        return [self._list(i) for i in range(self.n_lists)]

    def _list(self, i: int) -> np.ndarray:
        self._sync_size()
        if self._lists[i] is None:
            self._lists[i] = np.flatnonzero(self.state.node_list == i)
            self._classes[i] = None
            self._halo[i] = None
        return self._lists[i]

    def _dirty(self, levels) -> None:
        for i in np.unique(np.asarray(levels)):
            if 0 <= i < self.n_lists:
                self._lists[i] = None
                self._classes[i] = None
                self._halo[i] = None

    def _sync_size(self) -> None:
        """Follow topology edits: appended nodes (they enter list 0), new springs."""
        n = self.model.n_nodes
        if self.model.adj_nodes is not self._adjacency:  # the spring graph was rebuilt
            self._adjacency = self.model.adj_nodes
            self._classes = [None] * self.n_lists
            self._halo = [None] * self.n_lists
        if n != self._n_nodes:
            self._since_move = np.concatenate([self._since_move, np.zeros(n - self._n_nodes, np.int64)])
            self._n_nodes = n
            self._lists = [None] * self.n_lists
            self._classes = [None] * self.n_lists
            self._halo = [None] * self.n_lists
            self.state.node_list[self.model.fixed] = -1

    def topology_changed(self) -> None:
        """Forget every cached list (edits are also noticed on their own)."""
        self._sync_size()
        self._lists = [None] * self.n_lists
        self._classes = [None] * self.n_lists
        self._halo = [None] * self.n_lists

    def insert_new_node(self, nodes) -> None:
        """Put (new) free nodes into the finest list; their stamps are kept."""
        self._sync_size()
        nodes = np.atleast_1d(np.asarray(nodes, np.int64))
        nodes = nodes[~self.model.fixed[nodes]]
        old = self.state.node_list[nodes]
        self.state.node_list[nodes] = 0
        self._since_move[nodes] = 0
        self._dirty(np.concatenate([old, [0]]))

    def move_node_up(self, nodes) -> None:
        """Move nodes one list up: to the next larger time step."""
        self._move(nodes, +1)

    def move_node_down(self, nodes) -> None:
        """Move nodes one list down: to the next smaller time step."""
        self._move(nodes, -1)

    def _move(self, nodes, delta: int) -> None:
        self._sync_size()
        nodes = np.atleast_1d(np.asarray(nodes, np.int64))
        nl = self.state.node_list
        nodes = nodes[nl[nodes] >= 0]
        old = nl[nodes].copy()
        new = np.clip(old + delta, 0, self.n_lists - 1)
        moved = new != old
        nl[nodes[moved]] = new[moved]
        self._since_move[nodes[moved]] = 0
        self._dirty(np.concatenate([old[moved], new[moved]]))

    # -- the scheduler ----------------------------------------------------
    def next_list(self) -> int:
        """Index of the list that leads to the smallest time, eq. (8).

        Ties (within :data:`TIME_EPS` dt_0) go to the finest list.  Empty
        lists are skipped (their time follows the others).
        """
        nxt = self.list_time + self.dt
        best, best_t = -1, np.inf
        for i in range(self.n_lists):
            if self._list(i).size == 0:
                continue
            if nxt[i] < best_t - TIME_EPS * self.dt0:
                best, best_t = i, nxt[i]
        return best

    def process(self, i: int, f_ext: np.ndarray, gravity: np.ndarray) -> float:
        """Relax list i to ``t_i + dt_i`` and reassign its nodes; returns that time."""
        nodes = self._list(i)
        target = float(self.list_time[i] + self.dt[i])
        classes = None
        if self.gauss_seidel:
            if self._classes[i] is None:
                self._classes[i] = colour_classes(self.model, nodes)
            classes = self._classes[i]
        if self._halo[i] is None:
            m = self.model
            self._halo[i] = halo_nodes(nodes, m.adj_offsets, m.adj_nodes, m.n_nodes)
        advance_nodes(self.model, self.state, nodes, target, f_ext, gravity, self.mode, classes, self._halo[i])
        self.list_time[i] = target
        # empty lists keep pace (by whole steps) so that a node moved into one starts from now
        for j in range(self.n_lists):
            if self._list(j).size == 0 and target > self.list_time[j]:
                self.list_time[j] += np.floor((target - self.list_time[j]) / self.dt[j] + 1e-9) * self.dt[j]
        self._since_move[nodes] += 1
        # reassign once per accel window of passes: nodes only become ready
        # after a full window in their list anyway (hysteresis), and every
        # move invalidates the cached lists, colour classes and halos
        self._passes[i] += 1
        if self._passes[i] % self.state.accel_window.shape[1] == 0:
            self._reassign(nodes, i)
        self.state.time = target
        return target

    def _reassign(self, nodes: np.ndarray, i: int) -> None:
        w = self.state.accel_window.shape[1]
        ready = nodes[self._since_move[nodes] >= w]
        if ready.size == 0:
            return
        accel = self.state.accel_window[ready].mean(axis=1)
        with np.errstate(divide="ignore"):
            dt_ok = np.sqrt(2.0 * self.tolerance / accel)
        # coarsest level with a dt_level^2 / 2 <= tolerance
        ratio = np.clip(dt_ok / self.dt0, 1.0, 2.0 ** self.n_lists)
        level = np.minimum(np.floor(np.log2(ratio) + 1e-12).astype(np.int64), self.n_lists - 1)
        self.move_node_up(ready[level > i])
        self.move_node_down(ready[level < i])

    def advance(self, control: Control | None, until: float, *, synchronise: bool = True,
                max_passes: int | None = None) -> int:
        """Process lists (eq. 8) up to ``until`` s.

        Nodes with a non-zero external force (tool contact) are moved to the
        finest list first.  With ``synchronise`` every free node is finally
        advanced to exactly ``until`` (a frame).  Returns the number of list
        passes.
        """
        self._sync_size()
        f, g = control_arrays(self.model, control)
        loaded = np.flatnonzero(np.any(f != 0.0, axis=1) & (self.state.node_list > 0))
        if loaded.size:
            old = self.state.node_list[loaded].copy()
            self.state.node_list[loaded] = 0
            self._since_move[loaded] = 0
            self._dirty(np.concatenate([old, [0]]))
        # a free piece's momentum is kept over a synchronised interval (cutkit.relax.momentum)
        start = None
        if self.mode != MODE_EXPLICIT and synchronised(self.model, self.state, TIME_EPS * self.dt0):
            start = free_momentum_start(self.model, self.state)
        passes = 0
        while max_passes is None or passes < max_passes:
            i = self.next_list()
            if i < 0 or self.list_time[i] + self.dt[i] > until + TIME_EPS * self.dt0:
                break
            self.process(i, f, g)
            passes += 1
        if synchronise and (max_passes is None or passes < max_passes):
            self.synchronise(until, f, g)
            keep_free_momentum(self.model, self.state, start, f, g)
        return passes

    def synchronise(self, until: float, f_ext: np.ndarray, gravity: np.ndarray) -> None:
        """Advance every free node whose stamp is behind ``until`` to ``until``.

        The lists' times are left alone: each node's next step is still the
        list time minus its stamp (section 5.2), so the schedule goes on
        as if no frame had been taken.
        """
        # stamps within rounding of ``until`` already are there
        nodes = np.flatnonzero((self.state.time_stamps < until - TIME_EPS * self.dt0) & ~self.model.fixed)
        if nodes.size == 0:
            self.state.time = max(self.state.time, until)
            return
        classes = colour_classes(self.model, nodes) if self.gauss_seidel else None
        m = self.model
        halo = halo_nodes(nodes, m.adj_offsets, m.adj_nodes, m.n_nodes)
        advance_nodes(m, self.state, nodes, float(until), f_ext, gravity, self.mode, classes, halo)
        self.state.time = float(until)

    def run_async(self, control: Control | None, until: float) -> Future:
        """:meth:`advance` on the scheduler's worker thread; returns its future.

        The kernels release the GIL, so the caller (geometry updates,
        rendering) keeps running.  Do not touch the state until the future
        is done.
        """
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="cutkit-relax")
        return self._executor.submit(self.advance, control, until)

    def close(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=True)
            self._executor = None
