"""Mass-spring model of a tetrahedral mesh (paper section 5).

Springs sit on the mesh edges and masses on the nodes.  What never changes
except by an explicit topology edit is the :class:`SpringModel`; what
changes every step is the :class:`SpringState`; the inputs of a step are
the :class:`Control`.

Units (one consistent system, that of many FE codes): length mm, mass
tonne (1 t = 1000 kg), time s, force N, stress MPa = N/mm^2, stiffness
N/mm, density t/mm^3, acceleration mm/s^2.  The model file stores E in Pa
and density in kg/m^3; :func:`build_spring_model` converts them
(:data:`~cutkit.relax.materials.PA_TO_MPA`, :data:`~cutkit.relax.materials.KG_M3_TO_T_MM3`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cutkit.errors import InputError, MeshError
from cutkit.mesh.geometry import tet_volumes
from cutkit.relax._kernels import greedy_colouring, spring_csr
from cutkit.relax.materials import material_of_tets, prestress_of_tets

#: Standard gravity as a vector in mm/s^2 (pass ``Control(gravity=...)``).
STANDARD_GRAVITY_MM_S2 = 9806.65
#: Calibration constant c of k_e = sum_t E V_t / (c l_e^2).  c = 1 makes an
#: isotropic spring network have Young's modulus E (Poisson ratio 1/4),
#: see docs/relaxation.md.
STIFFNESS_CALIBRATION = 1.0
#: Number of past updates averaged for the node-list assignment (section 5.2).
ACCEL_WINDOW = 4


@dataclass
class SpringModel:
    """What a step never changes (warp.sim's Model).

    Attributes
    ----------
    rest_positions : (n, 3) float64
        Node rest positions, mm.
    masses : (n,) float64
        Lumped node masses, t.
    springs : (s, 2) int64
        Node pair of each spring (a mesh edge), ``springs[:, 0] < springs[:, 1]``
        for mesh-built springs.
    rest_length : (s,) float64
        Spring rest length, mm (shortened along fibres by the prestress).
    stiffness : (s,) float64
        Spring stiffness k_jk, N/mm.
    damping : (n,) float64
        Mass-proportional damping per node, 1/s (D_k = damping_k m_k in eq. 1).
    fixed : (n,) bool
        Nodes held where they are (at rest, or at their prescribed position).
    prescribed_displacement : (n, 3) float64
        Displacement imposed on fixed nodes, mm (zero for plainly fixed nodes).
    adj_offsets, adj_nodes, adj_springs : CSR of the spring graph
        ``(n + 1,) int64``, ``(2 s,) int32``, ``(2 s,) int32``: the springs of
        node k are ``adj_springs[adj_offsets[k]:adj_offsets[k + 1]]``, their
        other ends ``adj_nodes[...]`` (ascending).
    adj_rest, adj_stiffness : (2 s,) float64
        ``rest_length`` and ``stiffness`` in CSR order (contiguous for the kernel).
    colour : (n,) int32
        Greedy colouring of the spring graph (no spring joins two nodes of
        one colour): the parallel Gauss-Seidel classes.
    spring_a, spring_b : (s,) int32
        ``springs[:, 0]`` and ``springs[:, 1]``, contiguous for the kernels.
    node_stiffness : (n,) float64
        Sum of the stiffness of each node's springs, N/mm (the integrator adds
        the volume term's at the current shape).
    volume : VolumeTerm or None
        Per-tet volume springs (:mod:`cutkit.relax.volume`); None: springs only,
        as in the paper.
    topology_version : int
        Counts the rebuilds of the spring graph (caches of it key on it).
    """

    rest_positions: np.ndarray
    masses: np.ndarray
    springs: np.ndarray
    rest_length: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    fixed: np.ndarray
    prescribed_displacement: np.ndarray
    adj_offsets: np.ndarray = field(default=None)
    adj_nodes: np.ndarray = field(default=None)
    adj_springs: np.ndarray = field(default=None)
    adj_rest: np.ndarray = field(default=None)
    adj_stiffness: np.ndarray = field(default=None)
    colour: np.ndarray = field(default=None)
    spring_a: np.ndarray = field(default=None)
    spring_b: np.ndarray = field(default=None)
    node_stiffness: np.ndarray = field(default=None)
    volume: "VolumeTerm | None" = None
    topology_version: int = 0

    def __post_init__(self):
        if self.adj_offsets is None:
            self.rebuild_adjacency()

    @property
    def n_nodes(self) -> int:
        return int(self.rest_positions.shape[0])

    @property
    def n_springs(self) -> int:
        return int(self.springs.shape[0])

    @property
    def free_nodes(self) -> np.ndarray:
        """(f,) int64 nodes the integrator moves."""
        return np.flatnonzero(~self.fixed)

    def rebuild_adjacency(self, recolour: bool = True) -> None:
        """Recompute the CSR spring graph (and the colouring) from ``springs``."""
        n = self.n_nodes
        s = self.springs
        self.topology_version += 1  # caches of the graph (momentum.spring_pieces) key on it
        # counting sort, O(n + s): a cut rebuilds this every geometry update
        self.adj_offsets, self.adj_nodes, self.adj_springs = spring_csr(
            np.ascontiguousarray(s[:, 0], np.int64), np.ascontiguousarray(s[:, 1], np.int64), n)
        self.spring_a = np.ascontiguousarray(s[:, 0], np.int32)
        self.spring_b = np.ascontiguousarray(s[:, 1], np.int32)
        self.refresh_spring_arrays()
        if recolour:
            self.colour = greedy_colouring(self.adj_offsets, self.adj_nodes, n)

    def refresh_spring_arrays(self) -> None:
        """Copy ``rest_length``/``stiffness`` into CSR order after editing them."""
        from cutkit.relax._kernels import gather_spring_arrays

        self.adj_rest = np.empty(self.adj_springs.shape[0])
        self.adj_stiffness = np.empty(self.adj_springs.shape[0])
        self.node_stiffness = np.empty(self.n_nodes)
        gather_spring_arrays(self.adj_offsets, self.adj_springs, np.ascontiguousarray(self.rest_length, np.float64),
                             np.ascontiguousarray(self.stiffness, np.float64), self.adj_rest, self.adj_stiffness,
                             self.node_stiffness)


@dataclass
class SpringState:
    """What a step changes (warp.sim's State).

    Attributes
    ----------
    positions : (n, 3) float64, mm
    velocities : (n, 3) float64, mm/s
    time_stamps : (n,) float64
        Simulated time each node has been advanced to, s (section 5.2).
    accel_window : (n, w) float64
        Magnitude of the node's acceleration over its last w updates, mm/s^2.
    n_updates : (n,) int64
        Number of updates of each node so far.
    node_list : (n,) int32
        Index i of the node list (time step dt_0 2^i) holding each node;
        -1 for fixed nodes.
    time : float
        Simulated time of the whole state, s.
    """

    positions: np.ndarray
    velocities: np.ndarray
    time_stamps: np.ndarray
    accel_window: np.ndarray
    n_updates: np.ndarray
    node_list: np.ndarray
    time: float = 0.0

    def copy(self) -> "SpringState":
        return SpringState(
            self.positions.copy(), self.velocities.copy(), self.time_stamps.copy(),
            self.accel_window.copy(), self.n_updates.copy(), self.node_list.copy(), self.time,
        )


@dataclass
class Control:
    """Inputs of a step (warp.sim's Control).

    Attributes
    ----------
    external_forces : (n, 3) float64 or None
        Forces on nodes, N (e.g. tool contact).
    gravity : (3,) float64
        Acceleration of gravity, mm/s^2 (zero by default).
    """

    external_forces: np.ndarray | None = None
    gravity: np.ndarray = field(default_factory=lambda: np.zeros(3))


def tet_edges(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique edges of a tet mesh and the edge index of each tet's six edges.

    Returns
    -------
    edges : (e, 2) int64, ``edges[:, 0] < edges[:, 1]``, lexicographically sorted
    tet_edge : (m, 6) int64
    """
    from cutkit.mesh.topology import unique_edges

    return unique_edges(tets)


def _checked_mesh(model) -> tuple[np.ndarray, np.ndarray]:
    """The model's points (n, 3) float64 and tets (m, 4) int64, contiguous; MeshError on bad shapes
    or indices."""
    points = np.ascontiguousarray(model.points, np.float64)
    tets = np.ascontiguousarray(model.tets, np.int64)
    n = points.shape[0]
    if points.ndim != 2 or points.shape[1] != 3:
        raise MeshError(f"points must have shape (n, 3), got {points.shape}")
    if tets.ndim != 2 or tets.shape[1] != 4 or tets.shape[0] == 0:
        raise MeshError(f"tets must have shape (m, 4) with m > 0, got {tets.shape}")
    if tets.min() < 0 or tets.max() >= n:
        raise MeshError(f"tets index nodes outside 0..{n - 1}")
    return points, tets


def _prestressed_rest_lengths(model, d, length, vol, tet_edge) -> np.ndarray:
    """Rest lengths (e,) shortened along each prestressed label's fibre (paper section 7.3):
    ``l_e (1 - strain_e)``, strain_e the volume-weighted mean over all the edge's tets of
    ``prestrain cos^2(angle(e, fibre))`` (0 for plain tets).  ``d`` (e, 3) are the edge vectors."""
    n_edges = len(length)
    strain = np.zeros(n_edges)
    prestrain, fibre = prestress_of_tets(model, model.labels)
    for lab in model.prestress.label:
        in_lab = model.labels == lab
        if not in_lab.any():
            continue
        e_ids = tet_edge[in_lab].ravel()
        f, eps = fibre[in_lab][0], prestrain[in_lab][0]  # one fibre and prestrain per label
        cos2 = (d[e_ids] @ f / length[e_ids]) ** 2
        np.add.at(strain, e_ids, np.repeat(vol[in_lab], 6) * eps * cos2)
    # an edge shared by prestressed and plain tets: volume-weighted mean over all its tets
    all_w = np.bincount(tet_edge.ravel(), np.repeat(vol, 6), minlength=n_edges)
    return length * (1.0 - strain / all_w)


def _boundary_conditions(bc, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Fixed flags (n,) bool (fixed and prescribed nodes) and prescribed displacements (n, 3)
    float64 of a model's boundary conditions; InputError on a node index outside 0..n-1."""
    presc = np.zeros((n, 3))
    fn = np.asarray(bc.fixed_nodes, np.int64)
    pn = np.asarray(bc.prescribed_nodes, np.int64)
    for name, idx in (("fixed", fn), ("prescribed", pn)):
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise InputError(f"{name} node index outside 0..{n - 1}")
    fixed = bc.held_mask(n)
    presc[pn] = np.asarray(bc.prescribed_displacement, np.float64).reshape(-1, 3)
    return fixed, presc


def build_spring_model(model, *, calibration: float = STIFFNESS_CALIBRATION, prestress: bool = True,
                       volume_stiffness: float = 0.0, edges: tuple[np.ndarray, np.ndarray] | None = None
                       ) -> SpringModel:
    """Mass-spring model of a :class:`~cutkit.model.tetmodel.TetModel`.

    Masses are lumped (a quarter of each tet's mass to each of its nodes);
    a spring on every edge with stiffness
    ``k_e = sum_{t containing e} E_t V_t / (calibration * l_e^2)`` (Van Gelder
    1998's area-weighted rule carried to volumes, see docs/relaxation.md);
    the rest length along a prestressed label's fibre is shortened to
    ``l_e (1 - prestrain cos^2(angle(e, fibre)))`` (paper section 7.3).

    Parameters
    ----------
    model : TetModel
        Needs a materials row (E, density, damping) for every tet label.
    calibration : float
        The constant c above.
    prestress : bool
        Apply the model's prestress to the rest lengths.
    volume_stiffness : float
        > 0 adds the volume term (:mod:`cutkit.relax.volume`) with
        ``bulk_t = volume_stiffness * E_t``; 0 (default) keeps the paper's
        springs only.
    edges : ((e, 2) int64, (m, 6) int64), optional
        :func:`cutkit.mesh.topology.unique_edges` of the tets where the caller has them (spring k: edge k).

    Returns
    -------
    SpringModel
    """
    points, tets = _checked_mesh(model)
    n = points.shape[0]
    if not calibration > 0:
        raise InputError(f"stiffness calibration must be > 0, got {calibration}")
    if not (np.isfinite(volume_stiffness) and volume_stiffness >= 0):
        raise InputError(f"volume_stiffness must be a finite number >= 0, got {volume_stiffness}")
    vol = tet_volumes(points, tets)
    if np.any(vol <= 0):
        bad = int(np.flatnonzero(vol <= 0)[0])
        raise MeshError(f"tet {bad} has non-positive volume {vol[bad]:.3g} mm^3 (inverted or degenerate)")
    mat = material_of_tets(model, model.labels, poisson_ratio=0.0)  # the springs have no Poisson ratio
    E, rho, damp_t = mat["E"], mat["density"], mat["damping"]

    tet_mass = rho * vol
    masses = np.bincount(tets.ravel(), np.repeat(tet_mass / 4.0, 4), minlength=n)
    # node damping: mass-weighted mean of the damping of its tets
    damping = np.bincount(tets.ravel(), np.repeat(tet_mass * damp_t / 4.0, 4), minlength=n)
    damping = np.divide(damping, masses, out=np.zeros(n), where=masses > 0)

    edges, tet_edge = tet_edges(tets) if edges is None else edges
    d = points[edges[:, 1]] - points[edges[:, 0]]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))
    ev = np.bincount(tet_edge.ravel(), np.repeat(E * vol, 6), minlength=len(edges))
    stiffness = ev / (calibration * length**2)

    rest = length.copy()
    if prestress and len(model.prestress.label):
        rest = _prestressed_rest_lengths(model, d, length, vol, tet_edge)
    fixed, presc = _boundary_conditions(model.boundary, n)
    volume = None
    if volume_stiffness > 0:
        from cutkit.relax.volume import VolumeTerm

        volume = VolumeTerm.build(points, tets, vol, volume_stiffness * E)
    return SpringModel(
        rest_positions=points.copy(),
        masses=masses,
        springs=edges,
        rest_length=rest,
        stiffness=stiffness,
        damping=damping,
        fixed=fixed,
        prescribed_displacement=presc,
        volume=volume,
    )


def initial_state(spring_model: SpringModel, n_lists: int = 1) -> SpringState:
    """State at rest, with prescribed nodes at their displaced position.

    Every free node starts in node list 0 (the finest step); fixed nodes
    are in no list (-1).
    """
    n = spring_model.n_nodes
    x = spring_model.rest_positions + spring_model.prescribed_displacement
    node_list = np.where(spring_model.fixed, -1, 0).astype(np.int32)
    return SpringState(
        positions=np.ascontiguousarray(x),
        velocities=np.zeros((n, 3)),
        time_stamps=np.zeros(n),
        accel_window=np.zeros((n, ACCEL_WINDOW)),
        n_updates=np.zeros(n, np.int64),
        node_list=node_list,
        time=0.0,
    )
