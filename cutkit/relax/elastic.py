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
residual, never after a fixed count (:data:`DEFAULT_RTOL`).

Units as the spring model's (mm, t, s, N, MPa; :mod:`cutkit.relax.model`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cutkit.errors import InputError
from cutkit.relax import _adjacency_kernels as KA
from cutkit.relax import _elastic_kernels as K
from cutkit.relax.model import KG_M3_TO_T_MM3, MAX_PRESTRAIN, PA_TO_MPA

#: The iterations of a solve stop once the residual (the 2-norm of the
#: out-of-balance node forces, N) has fallen to this fraction of its first value...
DEFAULT_RTOL = 1e-4
#: ... or below this absolute value, N (a strain of about 1e-7 on a soft-tissue tet of 3 mm).
DEFAULT_ATOL_N = 1e-7
#: The most sweeps one solve makes before it reports that it did not converge.
DEFAULT_MAX_ITERATIONS = 10000
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

#: The stop flag of solves nothing interrupts (see :func:`local_step`); never written.
NEVER_STOP = np.zeros(1, np.int64)


def lame(E, nu):
    """Lame parameters (mu, lam) of Young's modulus E and Poisson ratio nu (same units as E)."""
    E = np.asarray(E, np.float64)
    nu = np.asarray(nu, np.float64)
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


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
    p = X[tets]
    Dm = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)  # columns
    rest_volume = np.linalg.det(Dm) / 6.0
    if prestrain is not None:
        ff = np.einsum("mi,mj->mij", fibre, fibre)
        Dm = Dm - prestrain[:, None, None] * np.einsum("mij,mjk->mik", ff, Dm)
    volume = np.linalg.det(Dm) / 6.0
    edges = np.concatenate([Dm, Dm[:, :, [1, 2, 0]] - Dm], axis=2)
    l_rms = np.sqrt(np.einsum("mij,mij->m", edges, edges) / 6.0)
    quality = 6.0 * np.sqrt(2.0) * volume / np.maximum(l_rms, 1e-300) ** 3
    active = quality >= MIN_ELEMENT_QUALITY
    Dminv = np.zeros_like(Dm)
    if active.any():
        Dminv[active] = np.linalg.inv(Dm[active])
    return Dminv, np.where(active, volume, 0.0), rest_volume


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
        ``(rows,) int64, (rows,) int64, (n,) int32`` (``rows >= n``): its slots
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
    _classes: tuple | None = None

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
        rows = int(n_nodes)
        pool = int((1.0 + ADJACENCY_POOL_SPARE) * (4 * cap + ADJACENCY_SLACK * rows))
        return cls(
            tets=np.zeros((cap, 4), np.int64), Dminv=np.zeros((cap, 3, 3)), volume=np.zeros(cap),
            mu=np.zeros(cap), lam=np.zeros(cap), mass_share=np.zeros(cap), n_elements=0,
            masses=np.zeros(n_nodes), damping=np.zeros(n_nodes), fixed=np.zeros((n_nodes, 3), bool),
            adj_start=np.zeros(rows, np.int64), adj_capacity=np.zeros(rows, np.int64),
            adj_degree=np.zeros(n_nodes, np.int32),
            adj_tets=np.zeros(pool, np.int32), adj_corner=np.zeros(pool, np.int8),
            adj_opposite=np.zeros((pool, 3), np.int32), adj_terms=np.zeros((pool, K.INCIDENCE_TERMS)),
            colour=np.full(n_nodes, -1, np.int32))

    def add_nodes(self, count: int, damping=0.0, fixed=None) -> np.ndarray:
        """Append ``count`` nodes without elements (mass comes with their elements); returns their ids."""
        n, p = self.n_nodes, int(count)
        self.masses = np.concatenate([self.masses, np.zeros(p)])
        self.damping = np.concatenate([self.damping, np.broadcast_to(np.asarray(damping, np.float64), (p,))])
        fx = np.zeros((p, 3), bool) if fixed is None else np.broadcast_to(np.asarray(fixed, bool).reshape(p, -1),
                                                                             (p, 3))
        self.fixed = np.concatenate([self.fixed, fx])
        if n + p > self.adj_start.shape[0]:
            # rows grow by doubling (a cut adds a few nodes at a time); rows past n_nodes are unused
            rows = max(n + p, 2 * self.adj_start.shape[0]) - self.adj_start.shape[0]
            self.adj_start = np.concatenate([self.adj_start, np.zeros(rows, np.int64)])
            self.adj_capacity = np.concatenate([self.adj_capacity, np.zeros(rows, np.int64)])
        self.adj_degree = np.concatenate([self.adj_degree, np.zeros(p, np.int32)])
        self.colour = np.concatenate([self.colour, np.full(p, -1, np.int32)])
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
        np.add.at(self.masses, tets.ravel(), np.repeat(share, 4))
        self.n_elements = max(self.n_elements, int(ids.max()) + 1)
        self._make_room(np.bincount(tets.ravel(), minlength=self.n_nodes))
        KA.add_to_adjacency(self.adjacency, self.tets, K.node_term_rows(Dminv, volume, self.mu[ids], self.lam[ids]),
                           ids)
        self._classes = None
        return ids

    def remove_elements(self, ids) -> None:
        """Take elements out: their energy, their mass and their place in the node lists."""
        ids = np.asarray(ids, np.int64)
        if ids.size == 0:
            return
        KA.remove_from_adjacency(self.adjacency, self.tets, ids)
        np.add.at(self.masses, self.tets[ids].ravel(), np.repeat(-self.mass_share[ids], 4))
        self.masses[self.adj_degree == 0] = 0.0  # exactly: what is left is rounding
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

    def _make_room(self, more: np.ndarray) -> None:
        """Rows with room for ``more`` (n,) slots each: a row too small moves to the pool's end."""
        n = self.n_nodes
        need = self.adj_degree + more[:n]
        short = np.flatnonzero(need > self.adj_capacity[:n])
        if short.size == 0:
            return
        cap = np.maximum(2 * self.adj_capacity[short], need[short] + ADJACENCY_SLACK)
        start = self.adj_used + np.concatenate([[0], np.cumsum(cap)[:-1]])
        end = self.adj_used + int(cap.sum())
        size = self.adj_tets.shape[0]
        if end > size:  # the pool grows by doubling
            size = max(end, 2 * size)
        self._move_rows(short, start, cap, size)
        self.adj_used = end

    def lay_out_rows(self) -> None:
        """Write the adjacency pool again with the node rows in sweep order (colour class by
        colour class, then the nodes no sweep moves), each with :data:`ADJACENCY_SLACK` spare.

        A sweep then reads the pool front to back instead of jumping between
        rows laid out in node order: one sweep of 1M tets 68 -> 49 ms.  Rows
        that move later (a cut's) go to the pool's end; a rebase lays it out
        again.  Nothing a sweep computes changes.
        """
        offsets, nodes = self.colour_classes()
        rest = np.ones(self.n_nodes, bool)
        rest[nodes] = False
        order = np.concatenate([nodes, np.flatnonzero(rest)])
        cap = self.adj_degree[order].astype(np.int64) + ADJACENCY_SLACK
        start = np.concatenate([[0], np.cumsum(cap)[:-1]]).astype(np.int64)
        used = int(cap.sum())
        # every row moves, into a fresh pool
        self._move_rows(order, start, cap, max(self.adj_tets.shape[0], int((1.0 + ADJACENCY_POOL_SPARE) * used)),
                        fresh=True)
        self.adj_used = used

    def _move_rows(self, nodes, start, cap, size: int, fresh: bool = False) -> None:
        """Give ``nodes`` the rows at ``start`` with room ``cap``, their slots carried over, in a pool
        of ``size`` slots (grown by copying the slots in use, or ``fresh``: nothing else kept)."""
        deg = self.adj_degree[nodes].astype(np.int64)
        src = np.repeat(self.adj_start[nodes], deg) + _ranges(deg)
        dst = np.repeat(start, deg) + _ranges(deg)
        for name in ("adj_tets", "adj_corner", "adj_opposite", "adj_terms"):
            old = getattr(self, name)
            new = old
            if fresh or size != old.shape[0]:
                new = np.zeros((size,) + old.shape[1:], old.dtype)
                if not fresh:
                    new[:self.adj_used] = old[:self.adj_used]
            new[dst] = old[src]
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


@dataclass
class SolveInfo:
    """How a solve ended: sweeps made, residual before the first and after the last (N), node updates.

    ``taken`` is False for a :func:`local_step` stopped within its first sweep (nothing changed).
    """

    iterations: int
    initial_residual: float
    residual: float
    converged: bool
    node_updates: int = 0
    taken: bool = True


def _ranges(counts: np.ndarray) -> np.ndarray:
    """0 .. c-1 for each c of ``counts``, concatenated: (sum(counts),) int64."""
    counts = np.asarray(counts, np.int64)
    return np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)


def build_element_model(model, *, poisson_ratio=None) -> ElementModel:
    """The element model of a :class:`~cutkit.model.TetModel` in its rest configuration.

    Materials come from the model's table (``E`` Pa, ``poisson_ratio``,
    ``density`` kg/m^3, ``damping`` 1/s), prestress from its prestress
    table, fixed nodes from its boundary conditions.

    Parameters
    ----------
    model : TetModel
    poisson_ratio : float, optional
        Override the table's Poisson ratio for every label.
    """
    mat = material_of_tets(model, model.labels, poisson_ratio=poisson_ratio)
    n = model.n_points
    em = ElementModel.empty(n, model.n_tets)
    prestrain, fibre = prestress_of_tets(model, model.labels)
    em.add_elements(model.points, model.tets, mat["mu"], mat["lam"], mat["density"], prestrain, fibre)
    em.damping[:] = node_damping(n, model.tets, mat["damping"])
    em.fixed[:] = fixed_nodes_mask(model)[:, None]
    em.recolour()
    em.lay_out_rows()
    return em


def material_of_tets(model, labels, poisson_ratio=None) -> dict:
    """Per-tet material in solver units: ``mu``, ``lam`` (MPa), ``density`` (t/mm^3), ``damping`` (1/s), ``E`` (MPa).

    Raises
    ------
    InputError
        A label has no row in the materials table, or a Poisson ratio lies outside [0, 0.5).
    """
    rows = model.materials.row_of(labels)
    if np.any(rows < 0):
        bad = int(np.asarray(labels)[np.argmax(rows < 0)])
        raise InputError(f"label {bad} has no row in the materials table")
    nu = model.materials["poisson_ratio"][rows] if poisson_ratio is None else np.full(rows.shape, poisson_ratio)
    if np.any(~np.isfinite(nu) | (nu < 0.0) | (nu >= 0.5)):
        raise InputError(f"Poisson ratio must lie in [0, 0.5), got {float(nu[np.argmax((nu < 0) | (nu >= 0.5))])}")
    E = model.materials["E"][rows] * PA_TO_MPA
    mu, lam = lame(E, nu)
    return {"E": E, "mu": mu, "lam": lam, "density": model.materials["density"][rows] * KG_M3_TO_T_MM3,
            "damping": model.materials["damping"][rows]}


def prestress_of_tets(model, labels):
    """Prestrain (m,) and unit fibre direction (m, 3) of each tet from the model's prestress table."""
    labels = np.asarray(labels)
    prestrain = np.zeros(labels.shape[0])
    fibre = np.zeros((labels.shape[0], 3))
    ps = model.prestress
    for lab, f, eps in zip(ps.label, np.asarray(ps.fibre_direction, np.float64).reshape(-1, 3),
                           np.asarray(ps.prestrain, np.float64)):
        if not abs(eps) < MAX_PRESTRAIN:
            raise InputError(f"prestrain of label {int(lab)} must lie in (-{MAX_PRESTRAIN}, {MAX_PRESTRAIN}), got {eps}")
        sel = labels == lab
        prestrain[sel] = eps
        fibre[sel] = f / np.linalg.norm(f)
    return prestrain, fibre


def node_damping(n: int, tets, damping) -> np.ndarray:
    """Damping per node: the mean over its tets of their material's (1/s), (n,) float64."""
    tets = np.asarray(tets, np.int64)
    s = np.bincount(tets.ravel(), np.repeat(np.asarray(damping, np.float64), 4), minlength=n)
    c = np.bincount(tets.ravel(), minlength=n)
    return np.divide(s, c, out=np.zeros(n), where=c > 0)


def fixed_nodes_mask(model) -> np.ndarray:
    """(n,) bool: nodes the boundary conditions hold (fixed or prescribed)."""
    mask = np.zeros(model.n_points, bool)
    mask[np.asarray(model.boundary.fixed_nodes, np.int64)] = True
    mask[np.asarray(model.boundary.prescribed_nodes, np.int64)] = True
    return mask


def initial_element_state(model) -> ElementState:
    """Rest positions (prescribed displacements applied), zero velocities."""
    x = np.array(model.points, np.float64, copy=True)
    pn = np.asarray(model.boundary.prescribed_nodes, np.int64)
    if pn.size:
        x[pn] += np.asarray(model.boundary.prescribed_displacement, np.float64).reshape(-1, 3)
    return ElementState(positions=x, velocities=np.zeros_like(x))


# ---------------------------------------------------------------- solving
def _node_terms(em: ElementModel, x, h, f_ext, gravity, y=None):
    n = em.n_nodes
    force = np.zeros((n, 3)) if f_ext is None else np.array(f_ext, np.float64, copy=True)
    if gravity is not None and np.any(gravity):
        force += em.masses[:, None] * np.asarray(gravity, np.float64)[None, :]
    if h is None:
        zero = np.zeros(n)
        return K.NodeTerms(zero, zero, em.fixed, x, x, force)
    inertia = em.masses / (h * h)
    damping = em.damping * em.masses / h
    return K.NodeTerms(inertia, damping, em.fixed, y, x.copy(), force)


def iterate(em: ElementModel, x, terms, *, rtol=DEFAULT_RTOL, atol=DEFAULT_ATOL_N,
            max_iterations=DEFAULT_MAX_ITERATIONS, min_iterations=1, chebyshev=None) -> SolveInfo:
    """Vertex block descent sweeps on ``x`` (in place) until the residual criterion holds.

    ``chebyshev`` (a spectral radius estimate in (0, 1)) turns on the
    Chebyshev semi-iterative acceleration that vertex block descent uses
    (Wang 2015): ``x = w (x_sweep - x_prev2) + x_prev2``.
    """
    offsets, nodes = em.colour_classes()
    r2 = np.zeros(em.n_nodes)
    adj = em.adjacency
    r0 = res = 0.0
    it = 0
    prev2 = prev = None
    omega = 1.0
    while it < max_iterations:
        if chebyshev is not None:
            prev2, prev = prev, x.copy()
        K.vbd_sweep(x, adj, terms, offsets, nodes, r2, NEVER_STOP)
        it += 1
        res = float(np.sqrt(r2.sum()))
        if it == 1:
            r0 = res
        if it >= min_iterations and (res <= rtol * r0 or res <= atol):
            return SolveInfo(it, r0, res, True)
        if chebyshev is not None and prev2 is not None:
            rho2 = chebyshev * chebyshev
            omega = 2.0 / (2.0 - rho2) if omega == 1.0 else 4.0 / (4.0 - rho2 * omega)
            x[:] = omega * (x - prev2) + prev2
    return SolveInfo(it, r0, res, False)


def implicit_step(em: ElementModel, state: ElementState, h: float, f_ext=None, gravity=None,
                  **tolerances) -> SolveInfo:
    """Advance ``state`` by one backward Euler step of ``h`` seconds.

    Parameters
    ----------
    em : ElementModel
    state : ElementState
        Changed in place.
    h : float
        s.
    f_ext : (n, 3) float64, optional
        External node forces, N.
    gravity : (3,) float64, optional
        mm/s^2.
    **tolerances
        ``rtol``, ``atol``, ``max_iterations`` of :func:`iterate`.
    """
    chebyshev = tolerances.pop("chebyshev", None)
    x0 = state.positions.copy()
    free = ~em.fixed
    y = np.where(free, x0 + h * state.velocities, x0)
    state.positions[:] = y  # the inertial prediction is the first guess
    terms = _node_terms(em, x0, h, f_ext, gravity, y)
    info = iterate(em, state.positions, terms, chebyshev=chebyshev, **tolerances)
    state.velocities[:] = np.where(free, (state.positions - x0) / h, 0.0)
    state.time += h
    return info


def local_step(em: ElementModel, state: ElementState, h: float, f_ext, r2, seeds, *,
               atol: float, max_iterations: int = DEFAULT_MAX_ITERATIONS, chebyshev=None,
               stop=None) -> SolveInfo:
    """One backward Euler step that moves only the nodes out of balance (and their neighbours).

    A node whose out-of-balance force stays below ``tau = atol / (2 sqrt(n))``
    and that does not move (its inertial force ``m |v| / h`` below tau)
    sleeps: it keeps its position and its last residual ``r2``.  The nodes of
    ``seeds`` (touched by a cut, loaded) are awake, and so is every neighbour
    of a node still out of balance after a sweep, so a disturbance spreads
    exactly as far as it is felt.  The step ends when the residual of all
    nodes, sleeping ones with their last value, is at most ``atol``; with
    every node awake this is :func:`implicit_step`.

    Parameters
    ----------
    r2 : (n,) float64
        Squared residual of every node at its last sweep, N^2; updated in place.
    seeds : (k,) int64
        Nodes to wake.
    stop : (1,) int64, optional
        Read before every colour class of a sweep (in the kernel) and after
        every sweep: non-zero ends the step there, unconverged, with the
        positions reached (a live session's cut waiting for the tissue,
        :class:`~cutkit.simulate.tasks.HandoverLock`).  Stopped within its
        first sweep, the step is not taken: positions and time stay as they
        were and the result has 0 iterations.
    """
    x, v = state.positions, state.velocities
    n = em.n_nodes
    tau2 = (0.5 * atol) ** 2 / max(n, 1)
    movable = ~em.fixed.all(axis=1) & (em.adj_degree > 0)
    # a node held or left without tets (a cut's orphan) has no residual: its last one would
    # otherwise stay in the sum and keep every later step from converging
    r2[~movable] = 0.0
    moving = movable & (em.masses * np.linalg.norm(v, axis=1) / h > np.sqrt(tau2))
    seeds = np.unique(np.concatenate([np.asarray(seeds, np.int64), np.flatnonzero(moving),
                                      np.flatnonzero(movable & (r2 > tau2))]))
    mark = np.zeros(n, bool)
    awake = KA.awake_after_sweep(em.adjacency, movable, r2, -1.0, seeds, mark)
    x0 = x.copy()
    y = x0.copy()
    y[awake] += h * np.where(em.fixed[awake], 0.0, v[awake])
    # the sweeps start from x^n, not from the inertial prediction y: from a state
    # without inverted tets no sweep makes one (_elastic_kernels.KEEP_J_FRACTION),
    # while y itself could fold a tet over
    terms = _node_terms(em, x0, h, f_ext, None, y)
    n_colours = int(em.colour.max(initial=-1)) + 1
    r0 = res = 0.0
    it = 0
    prev2 = prev = None
    omega = 1.0
    updates = 0
    stop = NEVER_STOP if stop is None else stop
    while it < max_iterations and awake.size:
        offsets, nodes = KA.colour_classes_of(em.colour, awake, n_colours)
        updates += nodes.size
        if chebyshev is not None:
            prev2, prev = prev, x.copy()
        swept = K.vbd_sweep(x, em.adjacency, terms, offsets, nodes, r2, stop)
        if it == 0 and swept < offsets.size - 1:  # stopped within the first sweep: the step is not taken
            x[:] = x0
            return SolveInfo(0, 0.0, 0.0, False, 0, taken=False)
        it += 1
        if chebyshev is not None and prev2 is not None:  # as in iterate(); nodes that slept are unchanged
            rho2 = chebyshev * chebyshev
            omega = 2.0 / (2.0 - rho2) if omega == 1.0 else 4.0 / (4.0 - rho2 * omega)
            x[:] = omega * (x - prev2) + prev2
        res = float(np.sqrt(r2.sum()))
        if it == 1:
            r0 = res
        if res <= atol or stop[0]:
            break
        awake = KA.awake_after_sweep(em.adjacency, movable, r2, tau2, awake, mark)
    v[:] = np.where(em.fixed, 0.0, (x - x0) / h)
    state.time += h
    return SolveInfo(it, r0, res, res <= atol, updates)


def static_solve(em: ElementModel, positions, f_ext=None, gravity=None, **tolerances) -> SolveInfo:
    """Relax ``positions`` (in place) to static equilibrium under the external forces."""
    return iterate(em, positions, _node_terms(em, positions, None, f_ext, gravity), **tolerances)


def elastic_forces(em: ElementModel, positions) -> np.ndarray:
    """Elastic node forces -dW/dx, N: (n, 3) float64 (reaction forces at held nodes)."""
    out = np.zeros((em.n_nodes, 3))
    K.node_forces(np.ascontiguousarray(positions, np.float64), em.adjacency, out)
    return out


def elastic_energy(em: ElementModel, positions) -> float:
    """Total stored energy, N mm."""
    return float(K.element_energy(np.ascontiguousarray(positions, np.float64), em.elements))
