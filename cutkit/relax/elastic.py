"""The element model: stable neo-Hookean tetrahedra relaxed by vertex block descent.

What a step never changes (except by a topology edit) is the
:class:`ElementModel`; what changes every step is the
:class:`ElementState`.  One implicit (backward Euler) step of length ``h``
minimises the incremental potential

    G(x) = sum_i m_i / (2 h^2) |x_i - y_i|^2 + c_i m_i / (2 h) |x_i - x_i^n|^2 + W(x) - f_ext . x

(``y = x^n + h v^n``) by vertex block descent (Chen, Macklin, Kim, Yuksel,
SIGGRAPH 2024): the nodes of one colour class move in parallel, each to the
exact minimiser of G in its own position (a 3x3 solve, exact because the
stable neo-Hookean energy is quadratic in one vertex,
:mod:`cutkit.relax._elastic_kernels`).  ``h = None`` drops the inertia and
damping: the sweeps then relax to static equilibrium.  Iterations stop at a
residual, never after a fixed count (the solves are in :mod:`cutkit.relax.vbd`).

Units as the spring model's (mm, t, s, N, MPa; :mod:`cutkit.relax.model`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cutkit.errors import InputError
from cutkit.relax import _adjacency_kernels as KA
from cutkit.relax import _elastic_kernels as K
from cutkit.relax import _shape_kernels as KS
from cutkit.relax.growable import append_rows
from cutkit.relax.materials import material_of_tets, prestress_of_tets

#: A tet whose normalised rest volume 6 sqrt(2) V / l_rms^3 (1 for a regular
#: tet) is below this carries mass but no energy: its inverse rest shape would
#: amplify rounding errors past any use.  A cut makes such a tet only where
#: the blade passes within about 1e-6 of an edge length from a node.
MIN_ELEMENT_QUALITY = 1e-6
#: Spare slots in a node's adjacency row when it is (re)allocated; a row that fills up moves
#: to the end of the pool with twice the room (the old slots stay unused until a rebuild).
ADJACENCY_SLACK = 8
#: Pool slots kept spare beyond those the elements and the rows' slack take, as a fraction:
#: cuts move rows to the pool's end, and growing the pool copies it (a stall in a live session).
ADJACENCY_POOL_SPARE = 0.25
#: The arrays of the adjacency pool, slot by slot, in the field order of ``Adjacency`` after its start and degree.
ADJACENCY_POOL = ("adj_tets", "adj_corner", "adj_opposite", "adj_terms")
#: Fewer tets than this get their rest shapes on the calling thread (a cut step's new tets):
#: below it, waking the thread pool costs more than the arithmetic it shares out.
PARALLEL_MIN_TETS = 2048

def rest_shape(X, tets, prestrain=None, fibre=None):
    """Inverse rest shapes and volumes of tetrahedra, with an optional prestrain along a fibre.

    The prestrained tissue's natural (stress-free) shape is the rest shape
    shortened by the fraction ``prestrain`` along ``fibre``: ``Dm' = (I - p f
    f^T) Dm`` (paper section 7.3, as a rest shape instead of rest lengths).

    Parameters
    ----------
    X : (n, 3) float64
        Rest positions, mm.
    tets : (m, 4) int64
    prestrain : (m,) float64, optional
    fibre : (m, 3) float64, optional
        Unit fibre directions.

    Returns
    -------
    Dminv : (m, 3, 3) float64
        Inverse natural shapes (zero for inactive tets).
    volume : (m,) float64
        Natural volumes, mm^3 (zero for tets below :data:`MIN_ELEMENT_QUALITY`).
    rest_volume : (m,) float64
        Volumes of the rest shape, mm^3 (what the mass is lumped from).
    """
    X = np.ascontiguousarray(X, np.float64)
    tets = np.ascontiguousarray(tets, np.int64)
    m = tets.shape[0]
    if prestrain is None:
        prestrain, fibre = np.zeros(m), np.zeros((m, 3))
    Dminv, volume, rest_volume = np.empty((m, 3, 3)), np.empty(m), np.empty(m)
    kernel = KS.rest_shapes if m >= PARALLEL_MIN_TETS else KS.rest_shapes_serial
    kernel(X, tets, np.ascontiguousarray(prestrain, np.float64), np.ascontiguousarray(fibre, np.float64),
           MIN_ELEMENT_QUALITY, Dminv, volume, rest_volume)
    return Dminv, volume, rest_volume


@dataclass
class ElementModel:
    """What a step never changes (warp.sim's Model), grown and shrunk by topology edits.

    Element arrays have a capacity; ``n_elements`` of them are in use and an
    element with ``volume == 0`` contributes nothing (removed or inactive).

    Attributes
    ----------
    tets : (cap, 4) int64
    Dminv : (cap, 3, 3) float64
        Inverse natural shape of each element.
    volume : (cap,) float64
        Natural volume (energy weight), mm^3; 0 = no energy.
    mu, lam : (cap,) float64
        Lame parameters, MPa.
    mass_share : (cap,) float64
        Mass each element gives each of its four nodes, t.
    masses : (n,) float64
        Lumped node masses, t.
    damping : (n,) float64
        Mass-proportional damping per node, 1/s.
    fixed : (n, 3) bool
        Components held at their current value.
    adj_start, adj_capacity, adj_degree : each node's row of the adjacency pool
        ``(n,) int64, (n,) int64, (n,) int32``: its slots
        ``adj_start[i] .. + adj_degree[i] - 1``, room for ``adj_capacity[i]``.
    adj_tets, adj_corner : the element and the node's corner in it, per slot
        ``(P,) int32, (P,) int8``.
    adj_opposite, adj_terms : what a node update reads of the element, per slot
        ``(P, 3) int32, (P, INCIDENCE_TERMS) float64``: the other three
        corners and the corner's part of the element's node-term row, derived
        from the arrays above when the element is added
        (``_elastic_kernels.node_term_rows``, ``add_to_adjacency``).
    adj_used : int
        Pool slots handed out to rows.
    colour : (n,) int32
        No two nodes of one element share a colour: the parallel classes.
    element : str
        ``"nh"`` stable neo-Hookean linear tets, ``"anp"`` the average nodal
        pressure tetrahedron (:mod:`cutkit.relax.anp`; projected Newton only).
    deviatoric_smoothing : float
        ``"anp"`` only: the share alpha in [0, 1) of the deviatoric energy carried by
        the nodes' smoothed deformation (:mod:`cutkit.relax.anp`); 0 is plain ANP.
    """

    tets: np.ndarray
    Dminv: np.ndarray
    volume: np.ndarray
    mu: np.ndarray
    lam: np.ndarray
    mass_share: np.ndarray
    n_elements: int
    masses: np.ndarray
    damping: np.ndarray
    fixed: np.ndarray
    adj_start: np.ndarray = field(default=None)
    adj_capacity: np.ndarray = field(default=None)
    adj_degree: np.ndarray = field(default=None)
    adj_tets: np.ndarray = field(default=None)
    adj_corner: np.ndarray = field(default=None)
    adj_opposite: np.ndarray = field(default=None)
    adj_terms: np.ndarray = field(default=None)
    adj_used: int = 0
    colour: np.ndarray = field(default=None)
    element: str = "nh"
    deviatoric_smoothing: float = 0.0
    _classes: tuple | None = None
    _tet_mark: np.ndarray | None = None  # scratch of remove_elements: a flag per element id

    @property
    def n_nodes(self) -> int:
        return int(self.masses.shape[0])

    @property
    def elements(self) -> K.Elements:
        return K.Elements(self.tets, self.Dminv, self.volume, self.mu, self.lam)

    @property
    def adjacency(self) -> K.Adjacency:
        return K.Adjacency(self.adj_start, self.adj_degree, self.adj_tets, self.adj_corner, self.adj_opposite,
                           self.adj_terms)

    def tets_of(self, node: int) -> np.ndarray:
        """(d,) int32 the elements around ``node``."""
        s = self.adj_start[node]
        return self.adj_tets[s:s + self.adj_degree[node]]

    # ------------------------------------------------------------ building
    @classmethod
    def empty(cls, n_nodes: int, capacity: int) -> "ElementModel":
        """No elements yet: room for ``capacity`` elements and their adjacency slots, with a
        quarter to spare for rows that move (:data:`ADJACENCY_POOL_SPARE`)."""
        cap = max(int(capacity), 1)
        pool = int((1.0 + ADJACENCY_POOL_SPARE) * (4 * cap + ADJACENCY_SLACK * int(n_nodes)))
        return cls(
            tets=np.zeros((cap, 4), np.int64), Dminv=np.zeros((cap, 3, 3)), volume=np.zeros(cap),
            mu=np.zeros(cap), lam=np.zeros(cap), mass_share=np.zeros(cap), n_elements=0,
            masses=np.zeros(n_nodes), damping=np.zeros(n_nodes), fixed=np.zeros((n_nodes, 3), bool),
            adj_start=np.zeros(n_nodes, np.int64), adj_capacity=np.zeros(n_nodes, np.int64),
            adj_degree=np.zeros(n_nodes, np.int32),
            adj_tets=np.zeros(pool, np.int32), adj_corner=np.zeros(pool, np.int8),
            adj_opposite=np.zeros((pool, 3), np.int32), adj_terms=np.zeros((pool, K.INCIDENCE_TERMS)),
            colour=np.full(n_nodes, -1, np.int32))

    def add_nodes(self, count: int, damping=0.0, fixed=None) -> np.ndarray:
        """Append ``count`` nodes without elements (mass comes with their elements); returns their ids."""
        n, p = self.n_nodes, int(count)
        # a cut adds a few nodes at a time: the arrays grow into spare room (growable.append_rows)
        self.masses = append_rows(self.masses, np.zeros(p))
        self.damping = append_rows(self.damping, np.broadcast_to(np.asarray(damping, np.float64), (p,)))
        fx = np.zeros((p, 3), bool) if fixed is None else np.broadcast_to(np.asarray(fixed, bool).reshape(p, -1),
                                                                             (p, 3))
        self.fixed = append_rows(self.fixed, fx)
        self.adj_start = append_rows(self.adj_start, np.zeros(p, np.int64))
        self.adj_capacity = append_rows(self.adj_capacity, np.zeros(p, np.int64))
        self.adj_degree = append_rows(self.adj_degree, np.zeros(p, np.int32))
        self.colour = append_rows(self.colour, np.full(p, -1, np.int32))
        self._classes = None
        return np.arange(n, n + p)

    def add_elements(self, X, tets, mu, lam, density, prestrain=None, fibre=None, ids=None) -> np.ndarray:
        """Add tetrahedra with their rest shape, Lame parameters (MPa) and density (t/mm^3).

        Parameters
        ----------
        X : (n, 3) float64
            Rest positions of all nodes, mm.
        tets : (k, 4) int64
        mu, lam, density : (k,) float64
        prestrain : (k,) float64, optional
        fibre : (k, 3) float64, optional
        ids : (k,) int64, optional
            Element ids to use (default: the next ``k``); the arrays grow to fit.

        Returns
        -------
        ids : (k,) int64
        """
        tets = np.asarray(tets, np.int64).reshape(-1, 4)
        k = tets.shape[0]
        if ids is None:
            ids = np.arange(self.n_elements, self.n_elements + k)
        ids = np.asarray(ids, np.int64)
        if k == 0:
            return ids
        self._reserve(int(ids.max()) + 1)
        Dminv, volume, rest_volume = rest_shape(np.asarray(X, np.float64), tets, prestrain, fibre)
        self.tets[ids] = tets
        self.Dminv[ids] = Dminv
        self.volume[ids] = volume
        self.mu[ids] = mu
        self.lam[ids] = lam
        share = np.asarray(density, np.float64) * np.maximum(rest_volume, 0.0) / 4.0
        self.mass_share[ids] = share
        KA.add_mass_shares(self.masses, tets, share)
        self.n_elements = max(self.n_elements, int(ids.max()) + 1)
        self._make_room(tets.ravel())
        KA.add_to_adjacency(self.adjacency, self.tets, K.node_term_rows(Dminv, volume, self.mu[ids], self.lam[ids]),
                           ids)
        self._classes = None
        return ids

    def remove_elements(self, ids) -> None:
        """Take elements out: their energy, their mass and their place in the node lists."""
        ids = np.asarray(ids, np.int64)
        if ids.size == 0:
            return
        if self._tet_mark is None or self._tet_mark.shape[0] < self.tets.shape[0]:
            self._tet_mark = np.zeros(self.tets.shape[0], bool)  # all False between calls
        KA.remove_from_adjacency(self.adjacency, self.tets, ids, self._tet_mark)
        KA.add_mass_shares(self.masses, self.tets[ids], -self.mass_share[ids])
        corners = self.tets[ids].ravel()
        self.masses[corners[self.adj_degree[corners] == 0]] = 0.0  # exactly: what is left is rounding
        self.volume[ids] = 0.0
        self.mass_share[ids] = 0.0
        self._classes = None

    def _reserve(self, cap: int) -> None:
        old = self.tets.shape[0]
        if cap <= old:
            return
        new = max(cap, 2 * old)
        grow = new - old
        self.tets = np.concatenate([self.tets, np.zeros((grow, 4), np.int64)])
        self.Dminv = np.concatenate([self.Dminv, np.zeros((grow, 3, 3))])
        for name in ("volume", "mu", "lam", "mass_share"):
            setattr(self, name, np.concatenate([getattr(self, name), np.zeros(grow)]))

    def _make_room(self, corners: np.ndarray) -> None:
        """Room in the rows of ``corners`` (k,) for one more slot per occurrence: a row too small
        moves to the pool's end (``_adjacency_kernels.make_room``; only the nodes a change touches
        are looked at, never all).  The pool grows by doubling."""
        corners = np.ascontiguousarray(corners, np.int64)
        if corners.size >= self.n_nodes:  # a whole model's elements (a build, a rebase): rows laid out
            # beforehand (reserve_rows) have room, which one count finds faster than the kernel's sort
            need = self.adj_degree + np.bincount(corners, minlength=self.n_nodes)
            if np.all(need <= self.adj_capacity):
                return
        end = KA.make_room(self.adjacency, self.adj_capacity, corners, self.adj_used, ADJACENCY_SLACK,
                           self.adj_tets.shape[0])
        if end < 0:
            self._move_rows(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64),
                            max(-end - 1, 2 * self.adj_tets.shape[0]))
            end = KA.make_room(self.adjacency, self.adj_capacity, corners, self.adj_used, ADJACENCY_SLACK,
                               self.adj_tets.shape[0])
        self.adj_used = end

    def lay_out_rows(self) -> None:
        """Write the adjacency pool again with the node rows in sweep order (colour class by
        colour class, then the nodes no sweep moves), each with :data:`ADJACENCY_SLACK` spare.

        A sweep then reads the pool front to back instead of jumping between
        rows laid out in node order: one sweep of 1M tets 68 -> 49 ms.  Rows
        that move later (a cut's) go to the pool's end; a rebase lays them out
        before its elements are added (:meth:`reserve_rows`).  Nothing a sweep
        computes changes.
        """
        offsets, nodes = self.colour_classes()
        order, start, cap, used = self._rows_in_sweep_order(nodes, self.adj_degree)
        # every row moves, into a fresh pool
        self._fresh_pool(order, start, cap, max(self.adj_tets.shape[0], int((1.0 + ADJACENCY_POOL_SPARE) * used)))
        self.adj_used = used

    def reserve_rows(self, tets) -> None:
        """Empty rows, in sweep order, for the elements ``tets`` (k, 4) int64 about to be added.

        For a model without elements whose colours and fixed flags are set (a
        rebase keeps them): :meth:`add_elements` then writes every row in the
        place where :meth:`lay_out_rows` would have copied it, the same rows
        in the same order, without the copy.

        Raises
        ------
        ValueError
            The model has elements, or a node that a sweep will move has no colour.
        """
        if self.n_elements or self.adj_used:
            raise ValueError("reserve_rows needs a model without elements")
        degree = np.bincount(np.asarray(tets, np.int64).ravel(), minlength=self.n_nodes)
        movable = ~self.fixed.all(axis=1) & (degree > 0)
        if np.any(self.colour[movable] < 0):
            raise ValueError("reserve_rows needs every node a sweep moves coloured")
        n_colours = int(self.colour.max(initial=-1)) + 1
        _, nodes = KA.colour_classes(self.colour, movable, n_colours)
        order, start, cap, used = self._rows_in_sweep_order(nodes, degree)
        size = int((1.0 + ADJACENCY_POOL_SPARE) * used)
        if size > self.adj_tets.shape[0]:
            for name in ADJACENCY_POOL:
                old = getattr(self, name)
                setattr(self, name, np.zeros((size,) + old.shape[1:], old.dtype))
        self.adj_start[order] = start
        self.adj_capacity[order] = cap
        self.adj_used = used

    def _rows_in_sweep_order(self, nodes, degree):
        """The rows' order (the nodes a sweep moves, ``nodes`` in its order, then the others), their
        starts and room (``degree`` + :data:`ADJACENCY_SLACK`) and the slots they take."""
        rest = np.ones(self.n_nodes, bool)
        rest[nodes] = False
        order = np.concatenate([nodes, np.flatnonzero(rest)])
        cap = np.asarray(degree)[order].astype(np.int64) + ADJACENCY_SLACK
        start = np.concatenate([[0], np.cumsum(cap)[:-1]]).astype(np.int64)
        return order, start, cap, int(cap.sum())

    def _move_rows(self, nodes, start, cap, size: int) -> None:
        """Give ``nodes`` the rows at ``start`` with room ``cap``, their slots carried over, in a pool
        of ``size`` slots (grown by copying the slots in use)."""
        deg = self.adj_degree[nodes].astype(np.int64)
        src = np.repeat(self.adj_start[nodes], deg) + _ranges(deg)
        dst = np.repeat(start, deg) + _ranges(deg)
        for name in ADJACENCY_POOL:
            old = getattr(self, name)
            new = old
            if size != old.shape[0]:
                new = np.zeros((size,) + old.shape[1:], old.dtype)
                new[:self.adj_used] = old[:self.adj_used]
            new[dst] = old[src]
            setattr(self, name, new)
        self.adj_start[nodes] = start
        self.adj_capacity[nodes] = cap

    def _fresh_pool(self, nodes, start, cap, size: int) -> None:
        """A pool of ``size`` slots holding only the rows of ``nodes`` (k,) int64, each at ``start`` (k,)
        int64 with room ``cap`` (k,) int64; the old pool is dropped."""
        pool = {name: np.zeros((size,) + getattr(self, name).shape[1:], getattr(self, name).dtype)
                for name in ADJACENCY_POOL}
        KA.copy_rows(self.adjacency, K.Adjacency(self.adj_start, self.adj_degree, *pool.values()),
                     np.ascontiguousarray(nodes, np.int64), np.ascontiguousarray(start, np.int64))
        for name, new in pool.items():
            setattr(self, name, new)
        self.adj_start[nodes] = start
        self.adj_capacity[nodes] = cap

    # ------------------------------------------------------------ colouring
    def recolour(self, nodes=None) -> None:
        """Colour ``nodes`` (default: all) so that no element has two nodes of one colour."""
        if nodes is None:
            self.colour[:] = -1
            nodes = np.arange(self.n_nodes)
        nodes = np.asarray(nodes, np.int64)
        self.colour[nodes] = -1
        KA.colour_nodes_greedy(self.adjacency, self.tets, self.colour, nodes)
        self._classes = None

    def forget_colour_classes(self) -> None:
        """Drop the cached :meth:`colour_classes` (after colours or fixed flags were changed from outside)."""
        self._classes = None

    def colour_classes(self) -> tuple[np.ndarray, np.ndarray]:
        """``offsets`` (c + 1,) int64 and ``nodes`` (k,) int64 of the nodes a sweep moves, by colour."""
        if self._classes is None:
            movable = ~self.fixed.all(axis=1) & (self.adj_degree > 0)
            if np.any(self.colour[movable] < 0):
                self.recolour(np.flatnonzero(movable & (self.colour < 0)))
            n_colours = int(self.colour.max(initial=-1)) + 1
            self._classes = KA.colour_classes(self.colour, movable, n_colours)
        return self._classes


@dataclass
class ElementState:
    """What changes every step (warp.sim's State).

    Attributes
    ----------
    positions : (n, 3) float64
        mm.
    velocities : (n, 3) float64
        mm/s.
    time : float
        s.
    """

    positions: np.ndarray
    velocities: np.ndarray
    time: float = 0.0


def _ranges(counts: np.ndarray) -> np.ndarray:
    """0 .. c-1 for each c of ``counts``, concatenated: (sum(counts),) int64."""
    counts = np.asarray(counts, np.int64)
    return np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)


def build_element_model(model, *, poisson_ratio=None, element: str = "nh",
                        deviatoric_smoothing: float = 0.0) -> ElementModel:
    """The element model of a :class:`~cutkit.model.TetModel` in its rest configuration.

    Materials come from the model's table (``E`` Pa, ``poisson_ratio``,
    ``density`` kg/m^3, ``damping`` 1/s), prestress from its prestress
    table, fixed nodes from its boundary conditions.

    Parameters
    ----------
    model : TetModel
    poisson_ratio : float, optional
        Override the table's Poisson ratio for every label.
    element : str
        ``"nh"`` (stable neo-Hookean linear tets) or ``"anp"`` (average nodal
        pressure tetrahedron, :mod:`cutkit.relax.anp`).
    deviatoric_smoothing : float
        ``"anp"`` only: the share alpha in [0, 1) of the deviatoric energy carried by the
        nodes (:mod:`cutkit.relax.anp`, ``ANP_SMOOTHING`` is the measured choice); 0 plain ANP.
    """
    if element not in ("nh", "anp"):
        raise InputError(f"element must be nh or anp, not {element!r}")
    alpha = float(deviatoric_smoothing)
    if not 0.0 <= alpha < 1.0 or (alpha > 0.0 and element != "anp"):
        raise InputError(f"deviatoric_smoothing must be in [0, 1) and needs element anp, got {deviatoric_smoothing!r}")
    mat = material_of_tets(model, model.labels, poisson_ratio=poisson_ratio)
    n = model.n_points
    em = ElementModel.empty(n, model.n_tets)
    prestrain, fibre = prestress_of_tets(model, model.labels)
    em.add_elements(model.points, model.tets, mat["mu"], mat["lam"], mat["density"], prestrain, fibre)
    em.damping[:] = node_damping(n, model.tets, mat["damping"])
    em.fixed[:] = model.boundary.held_mask(model.n_points)[:, None]
    em.element = element
    em.deviatoric_smoothing = alpha
    em.recolour()
    em.lay_out_rows()
    return em


def node_damping(n: int, tets, damping) -> np.ndarray:
    """Damping per node: the mean over its tets of their material's (1/s), (n,) float64."""
    tets = np.asarray(tets, np.int64)
    s = np.bincount(tets.ravel(), np.repeat(np.asarray(damping, np.float64), 4), minlength=n)
    c = np.bincount(tets.ravel(), minlength=n)
    return np.divide(s, c, out=np.zeros(n), where=c > 0)


def initial_element_state(model) -> ElementState:
    """Rest positions (prescribed displacements applied), zero velocities."""
    x = np.array(model.points, np.float64, copy=True)
    pn = np.asarray(model.boundary.prescribed_nodes, np.int64)
    if pn.size:
        x[pn] += np.asarray(model.boundary.prescribed_displacement, np.float64).reshape(-1, 3)
    return ElementState(positions=x, velocities=np.zeros_like(x))


# ---------------------------------------------------------------- solving
