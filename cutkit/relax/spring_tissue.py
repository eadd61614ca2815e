"""The tissue being cut as the paper's springs: a tissue store and its mass-spring model on one node numbering.

The paper's Fig. 1 runs collision and geometry update beside the
relaxation.  Both work on the same nodes: node ``k`` of the
:class:`~cutkit.tissue.store.TissueStore` is node ``k`` of the
:class:`~cutkit.relax.SpringModel`.  After every cut step
:meth:`Tissue.apply_cut` carries the topology change over to the springs
in one batch:

* new nodes (split edges, duplicated cut-surface nodes, section 3) are
  appended with the position, rest position and velocity interpolated from
  their defining nodes and enter the finest node list (section 5.2);
* every tetrahedron keeps a record of what it contributed (rest volume,
  and per edge the prestress term), so a removed tetrahedron takes back
  exactly what it gave: lumped masses (rho V / 4 per node), the spring sums
  ``sum E V`` (stiffness ``k = sum E V / (c l^2)``, docs/relaxation.md),
  ``sum V`` and ``sum V p cos^2`` (prestressed rest length
  ``l (1 - sum V p cos^2 / sum V)``, section 7.3);
* a spring lives while at least one tetrahedron has its edge;
* cut nodes the blade moves (tip and crack-front nodes) get their rest
  position re-interpolated and their tetrahedra re-recorded.

Total mass is the sum of rho V over the tetrahedra, and a subdivision
keeps the rest volume, so a cut keeps the total mass exactly.
"""

from __future__ import annotations

import numpy as np

from cutkit.mesh.geometry import TET_EDGES, tet_volumes
from cutkit.relax import Control, NodeLists, build_spring_model, initial_state
from cutkit.relax import _adjacency_kernels as KA
from cutkit.relax.materials import material_of_tets, prestress_of_tets
from cutkit.relax.model import STIFFNESS_CALIBRATION
from cutkit.relax.topology import recolour
from cutkit.relax._handover_kernels import lookup_springs
from cutkit.relax.rest_map import rest_map_radius
from cutkit.relax.tissue_base import TissueBase, uncut_store
from cutkit.tissue.store import TissueStore


#: Tets whose normalised volume 6 sqrt(2) V / l_rms^3 (1 for a regular tet)
#: is below this get no volume term (see Tissue._rebuild_volume_term).
VOLUME_TERM_MIN_QUALITY = 0.1
#: Sub-tets smaller than this fraction of their original tet get no volume
#: term either: their nodes carry almost no mass.
VOLUME_TERM_MIN_FRACTION = 0.05


def _shape_quality(X: np.ndarray, tets: np.ndarray, V: np.ndarray) -> np.ndarray:
    """6 sqrt(2) V / l_rms^3 of each tet (1 for a regular tet, 0 for a flat one): (m,) float64."""
    p = X[tets]
    l2 = np.zeros(tets.shape[0])
    for a, b in TET_EDGES:
        d = p[:, b] - p[:, a]
        l2 += np.einsum("ij,ij->i", d, d)
    l_rms = np.sqrt(l2 / 6.0)
    return 6.0 * np.sqrt(2.0) * V / np.maximum(l_rms, 1e-300) ** 3


class Tissue(TissueBase):
    """Cut mesh + mass-spring model + node lists of one tissue model (the paper's springs).

    Parameters
    ----------
    model : TetModel
        Needs a materials row for every label.
    store : TissueStore, optional
        The nodes and tets it reads (default: the model's own, nothing cut).
    dt0 : float
        Finest relaxation step, s.
    n_lists : int
        Number of node lists (steps dt0 .. dt0 2^(n_lists - 1)).
    tolerance_fraction : float
        Displacement tolerance of the node-list assignment as a fraction of
        the mean spring rest length.

    Attributes
    ----------
    store : TissueStore
    springs : SpringModel
    state : SpringState
    lists : NodeLists
    n_orig_tets : int
    """

    def __init__(self, model, store: TissueStore | None = None, *, dt0: float, n_lists: int,
                 tolerance_fraction: float, calibration: float = STIFFNESS_CALIBRATION, volume_stiffness: float = 0.0):
        self.model = model
        self.calibration = float(calibration)
        self.volume_stiffness = float(volume_stiffness)
        self.store = store = uncut_store(model, store)
        self.rest_map_radius = rest_map_radius(model.points, model.tets)
        self.springs = sm = build_spring_model(model, calibration=calibration, volume_stiffness=volume_stiffness,
                                               edges=(store.edges, store.tet_edges))
        self.state = initial_state(sm)
        tolerance = tolerance_fraction * float(np.mean(sm.rest_length))
        self.lists = NodeLists(sm, self.state, dt0, n_lists, displacement_tolerance=tolerance)
        self.n_orig_tets = int(store.orig_tets.shape[0])

        self._read_materials()

        # per-tet records (indexed by tet id), per-spring sums
        tets = store.orig_tets
        cap = store.tet_capacity
        self.rec_V = np.zeros(cap)
        self.rec_sv = np.zeros((cap, 6))
        V, sv = self._contributions(np.arange(self.n_orig_tets))
        self.rec_V[:self.n_orig_tets] = V
        self.rec_sv[:self.n_orig_tets] = sv
        # rest volume of each model tet (the store is not cut yet: its original tets are the model's);
        # model_V: of the model tet each original tet comes from (flat sub-tets: _rebuild_volume_term)
        self.model_tet_V = V.copy()
        self.model_V = self.model_tet_V[store.model_tet]
        # the store's edges of the original tets (one computation): spring k is edge k
        edges, tet_edge = store.edges, store.tet_edges
        s = len(edges)
        flat = tet_edge.ravel()
        self.spring_count = np.bincount(flat, minlength=s).astype(np.int64)
        self.spring_ev = np.bincount(flat, np.repeat(self.E * V, 6), minlength=s)
        self.spring_v = np.bincount(flat, np.repeat(V, 6), minlength=s)
        self.spring_sv = np.bincount(flat, sv.ravel(), minlength=s)
        # tets of each cut node (nodes >= n_orig_points), to re-record moved nodes
        self._node_tets: dict[int, set] = {}
        # number of live tets at each node: a node with none is an orphan and is held
        self.node_tet_count = np.bincount(tets.ravel(), minlength=store.n_nodes).astype(np.int64)

    # ------------------------------------------------------------------ records
    def _contributions(self, tet_ids: np.ndarray):
        """Rest volume (t,) and prestress terms V p cos^2 per edge (t, 6) of the store's tets."""
        store = self.store
        q = store.tet_corners[tet_ids]
        X = store.rest_points
        V = tet_volumes(X, q)
        orig = store.tet_origins[tet_ids]
        d = X[q[:, TET_EDGES[:, 1]]] - X[q[:, TET_EDGES[:, 0]]]  # (t, 6, 3)
        length = np.linalg.norm(d, axis=2)
        cos = np.einsum("tkc,tc->tk", d, self.fibre[orig]) / np.where(length > 0, length, 1.0)
        sv = V[:, None] * self.prestrain[orig][:, None] * cos**2
        return V, sv

    # ------------------------------------------------------------------ cut
    def apply_delta(self, delta) -> dict:
        """Carry a cut step's :class:`~cutkit.tissue.TopologyDelta` over to the springs.

        Returns
        -------
        counts : dict
            ``nodes_added``, ``springs_added``, ``springs_removed``.
        """
        store, sm = self.store, self.springs
        n_old = sm.n_nodes
        n_new = delta.n_nodes_after
        added = [int(t) for t in delta.added_tets]
        removed = [int(t) for t in delta.removed_tets]
        moved = [int(k) for k in delta.moved_nodes]
        if not added and not removed and not moved and n_new == n_old:
            return {"nodes_added": 0, "springs_added": 0, "springs_removed": 0}
        if self.rec_V.shape[0] < store.tet_capacity:
            grow = store.tet_capacity - self.rec_V.shape[0]
            self.rec_V = np.concatenate([self.rec_V, np.zeros(grow)])
            self.rec_sv = np.concatenate([self.rec_sv, np.zeros((grow, 6))])

        new = self._cut_nodes(n_old, n_new, delta)
        keys, sums = self._cut_tet_sums(added, removed, moved)
        new_pairs, n_dead = self._cut_springs(keys, sums)
        self._cut_refresh(new_pairs)
        return {"nodes_added": int(new.size), "springs_added": len(new_pairs), "springs_removed": n_dead}

    def _cut_nodes(self, n_old: int, n_new: int, delta) -> np.ndarray:
        """Append the cut's new nodes and re-interpolate the moved ones; returns the new node ids."""
        sm, st = self.springs, self.state
        # ---- nodes: append, and re-interpolate moved ones
        new = np.arange(n_old, n_new)
        if new.size:
            self._append_nodes(new, delta)
        if delta.moved_nodes.size:
            mv = delta.moved_nodes
            sm.rest_positions[mv] = delta.moved_rest_to
            st.positions[mv] = self.interpolate_positions(mv)
        return new

    def _cut_tet_sums(self, added: list, removed: list, moved: list):
        """Take back what removed (and reweighed) tets gave, record what added ones give: edge keys and sums."""
        store, sm = self.store, self.springs
        # ---- tets to take back and to (re)record
        added_set = set(added)
        removed_set = set(removed)
        reweigh = set()
        for k in moved:
            for t in self._node_tets.get(k, ()):
                if t not in added_set and t not in removed_set:
                    reweigh.add(t)
        take_back = np.array(sorted(removed_set | reweigh), np.int64)
        record = np.array(sorted(added_set | reweigh), np.int64)
        masses = sm.masses
        keys, sums = [], []
        key_base = np.int64(store.n_nodes + 1)
        for sign, ids in ((-1.0, take_back), (1.0, record)):
            if ids.size == 0:
                continue
            if sign > 0:
                V, sv = self._contributions(ids)
                self.rec_V[ids] = V
                self.rec_sv[ids] = sv
            else:
                V, sv = self.rec_V[ids], self.rec_sv[ids]
            orig = store.tet_origins[ids]
            q = store.tet_corners[ids]
            KA.add_mass_shares(masses, np.ascontiguousarray(q, np.int64), sign * self.rho[orig] * V / 4.0)
            np.add.at(self.node_tet_count, q.ravel(), int(sign))
            ea, eb = q[:, TET_EDGES[:, 0]], q[:, TET_EDGES[:, 1]]  # (t, 6)
            keys.append((np.minimum(ea, eb) * key_base + np.maximum(ea, eb)).ravel())
            w = np.full(ea.shape, sign)
            sums.append(np.stack([w, w * (self.E[orig] * V)[:, None], w * V[:, None], sign * sv],
                                 axis=-1).reshape(-1, 4))
            for r in range(ids.size):
                for node in q[r]:
                    if node >= store.n_orig_nodes:
                        owners = self._node_tets.setdefault(int(node), set())
                        if sign > 0:
                            owners.add(int(ids[r]))
                        else:
                            owners.discard(int(ids[r]))
        return keys, sums

    def _cut_springs(self, keys: list, sums: list):
        """Apply the per-edge sums to the springs: update, create, drop; returns (new pairs, dropped count)."""
        store, sm = self.store, self.springs
        key_base = np.int64(store.n_nodes + 1)
        if keys:
            uk, inv = np.unique(np.concatenate(keys), return_inverse=True)
            allsums = np.concatenate(sums)
            acc = np.stack([np.bincount(inv, allsums[:, c], minlength=uk.size) for c in range(4)], axis=1)
            ua, ub = uk // key_base, uk % key_base
            sid = lookup_springs(sm.adj_offsets, sm.adj_nodes, sm.adj_springs, ua, ub)
        else:
            acc, ua, ub, sid = np.zeros((0, 4)), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
        old = sid >= 0
        so = sid[old]
        self.spring_count[so] += np.rint(acc[old, 0]).astype(np.int64)
        self.spring_ev[so] += acc[old, 1]
        self.spring_v[so] += acc[old, 2]
        self.spring_sv[so] += acc[old, 3]
        touched = [so]
        born = ~old & (acc[:, 0] > 0.5)
        new_pairs = np.stack([ua[born], ub[born]], axis=1)
        new_sums = acc[born]
        n_spr = sm.n_springs
        if len(new_pairs):
            pairs = new_pairs
            sums = new_sums
            self.spring_count = np.concatenate([self.spring_count, np.rint(sums[:, 0]).astype(np.int64)])
            self.spring_ev = np.concatenate([self.spring_ev, sums[:, 1]])
            self.spring_v = np.concatenate([self.spring_v, sums[:, 2]])
            self.spring_sv = np.concatenate([self.spring_sv, sums[:, 3]])
            sm.springs = np.concatenate([sm.springs, pairs])
            sm.rest_length = np.concatenate([sm.rest_length, np.zeros(len(pairs))])
            sm.stiffness = np.concatenate([sm.stiffness, np.zeros(len(pairs))])
            touched.append(np.arange(n_spr, n_spr + len(pairs)))
        ts = np.concatenate(touched)
        if ts.size:
            X = sm.rest_positions
            d = X[sm.springs[ts, 1]] - X[sm.springs[ts, 0]]
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            v = self.spring_v[ts]
            strain = np.divide(self.spring_sv[ts], v, out=np.zeros_like(v), where=v > 0)
            sm.rest_length[ts] = length * (1.0 - strain)
            sm.stiffness[ts] = np.divide(self.spring_ev[ts], self.calibration * length**2,
                                         out=np.zeros_like(v), where=length > 0)
        dead = self.spring_count <= 0
        n_dead = int(dead.sum())
        if n_dead:
            keep = ~dead
            sm.springs = sm.springs[keep]
            sm.rest_length = sm.rest_length[keep]
            sm.stiffness = sm.stiffness[keep]
            self.spring_count = self.spring_count[keep]
            self.spring_ev = self.spring_ev[keep]
            self.spring_v = self.spring_v[keep]
            self.spring_sv = self.spring_sv[keep]
        return new_pairs, n_dead

    def _cut_refresh(self, new_pairs) -> None:
        """Hold orphan nodes, refresh the volume term, adjacency, colours and node lists."""
        sm, st = self.springs, self.state
        masses = sm.masses
        # ---- nodes left without tets (orphans) are held; nodes with tets are free unless BC-fixed
        orphan = self.node_tet_count <= 0
        masses[orphan] = 0.0  # exactly: what is left is rounding
        fixed = self.store.held | orphan
        changed = np.flatnonzero(fixed != sm.fixed)
        sm.fixed = fixed
        if changed.size:
            st.node_list[changed] = np.where(fixed[changed], -1, 0)
            st.velocities[changed[fixed[changed]]] = 0.0
            # a node freed again (an unused T node a later cut uses) was held since its stamp:
            # its first step starts now, not there (a step that long threw it)
            st.time_stamps[changed[~fixed[changed]]] = st.time
            sm.prescribed_displacement[changed] = np.where(
                fixed[changed, None], st.positions[changed] - sm.rest_positions[changed], 0.0)

        if sm.volume is not None:
            self._rebuild_volume_term()
        sm.rebuild_adjacency(recolour=False)
        if sm.colour.shape[0] < sm.n_nodes:
            sm.colour = np.concatenate([sm.colour, np.full(sm.n_nodes - sm.colour.shape[0], -1, np.int32)])
        if len(new_pairs):
            recolour(sm, np.unique(new_pairs))
        self.lists.topology_changed()
    def _rebuild_volume_term(self) -> None:
        """The volume term over the live tets: rest volumes from the per-tet records (the cut is made at rest)."""
        from cutkit.relax.volume import VolumeTerm

        store = self.store
        ids = np.flatnonzero(store.tet_alive)
        # Flat sub-tets of a cut are left out: their volume stiffness
        # (bulk |dV/dx|^2 / V0) dwarfs their springs' and the semi-implicit
        # step, which treats it per node, overshoots on them.
        sub = ids[store.made_by_cut(ids)]  # in any stroke
        small = self.rec_V[sub] < VOLUME_TERM_MIN_FRACTION * self.model_V[store.tet_origins[sub]]
        flat = sub[small | (self.rec_V[sub] <= 0.0)
                   | (_shape_quality(store.rest_points, store.tet_corners[sub], self.rec_V[sub]) < VOLUME_TERM_MIN_QUALITY)]
        ids = np.setdiff1d(ids, flat, assume_unique=True)
        V0 = self.rec_V[ids]
        self.springs.volume = VolumeTerm.build(self.springs.rest_positions, store.tet_corners[ids], V0,
                                               self.volume_stiffness * self.E[store.tet_origins[ids]])

    def _append_nodes(self, new: np.ndarray, delta) -> None:
        """Append the delta's new nodes ``new`` (p,) int64: rest from the delta, the rest interpolated."""
        sm, st = self.springs, self.state
        p = new.size
        par = delta.added_node_parents
        w = delta.added_node_weights
        valid = par >= 0
        pz = np.where(valid, par, 0)
        wz = np.where(valid, w, 0.0)
        wsum = wz.sum(axis=1, keepdims=True)
        wz = wz / np.where(wsum > 0, wsum, 1.0)
        vel = np.einsum("pq,pqc->pc", wz, st.velocities[pz])
        damp = (wz * sm.damping[pz]).sum(axis=1)
        held = self.store.held[new]  # a node between held nodes only (a cut into bone) is held too
        X = delta.added_node_rest
        x = self.interpolate_positions(new)
        self.node_tet_count = np.concatenate([self.node_tet_count, np.zeros(p, np.int64)])
        sm.rest_positions = np.concatenate([sm.rest_positions, X])
        sm.masses = np.concatenate([sm.masses, np.zeros(p)])
        sm.damping = np.concatenate([sm.damping, damp])
        sm.fixed = np.concatenate([sm.fixed, held])
        sm.prescribed_displacement = np.concatenate(
            [sm.prescribed_displacement, np.where(held[:, None], x - X, 0.0)])
        st.positions = np.concatenate([st.positions, x])
        st.velocities = np.concatenate([st.velocities, np.where(held[:, None], 0.0, vel)])
        st.time_stamps = np.concatenate([st.time_stamps, np.full(p, st.time)])
        st.accel_window = np.concatenate([st.accel_window, np.zeros((p, st.accel_window.shape[1]))])
        st.n_updates = np.concatenate([st.n_updates, np.zeros(p, np.int64)])
        # section 5.2: nodes made by a cut enter the finest list
        st.node_list = np.concatenate([st.node_list, np.where(held, -1, 0).astype(np.int32)])

    # ------------------------------------------------------------------ the shared interface
    @property
    def n_nodes(self) -> int:
        return int(self.springs.n_nodes)

    @property
    def positions(self) -> np.ndarray:
        return self.state.positions

    @property
    def rest_positions(self) -> np.ndarray:
        return self.springs.rest_positions

    @property
    def velocities(self) -> np.ndarray:
        return self.state.velocities

    @property
    def fixed(self) -> np.ndarray:
        return self.springs.fixed

    @property
    def time(self) -> float:
        return float(self.state.time)

    def point_data(self) -> dict:
        return {"node_list": self.state.node_list.astype(np.int32)}

    def settle(self, iterations: int, step_s: float) -> dict:
        """Gauss-Seidel sweeps of the whole model at a large step, then at rest at time 0.

        Returns
        -------
        info : dict
            ``iterations`` and the relative residual (out-of-balance spring
            forces against their first value) they reached.
        """
        from cutkit.relax import spring_forces
        from cutkit.relax import step as relax_step

        sm, st = self.springs, self.state
        free = ~sm.fixed
        r0 = float(np.linalg.norm(spring_forces(sm, st.positions)[free]))
        for _ in range(int(iterations)):
            relax_step(sm, st, Control(), step_s, gauss_seidel=True)
        r = float(np.linalg.norm(spring_forces(sm, st.positions)[free]))
        st.velocities[:] = 0.0
        st.time = 0.0
        st.time_stamps[:] = 0.0
        self.lists.list_time[:] = 0.0
        return {"iterations": int(iterations), "relative_residual": r / r0 if r0 > 0 else 0.0}

    @property
    def masses(self) -> np.ndarray:
        """(n,) float64 lumped masses (rho V / 4 per node and tet)."""
        return self.springs.masses

    def node_rings(self, nodes: np.ndarray, rings: int) -> np.ndarray:
        """``nodes`` grown by ``rings`` rings of neighbours along springs (every pair of a tet's corners
        is a spring)."""
        sm = self.springs
        nodes = np.unique(np.asarray(nodes, np.int64))
        for _ in range(rings):
            start, stop = sm.adj_offsets[nodes], sm.adj_offsets[nodes + 1]
            counts = stop - start
            slots = np.repeat(start - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))
            nodes = np.union1d(nodes, sm.adj_nodes[slots])
        return nodes

    def bearing_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """The nodes of ``nodes`` (k,) int64 in a piece of tissue that is held (has a fixed node).

        A piece the cut has set loose cannot resist the blade: the reaction of
        the cut force (eqs. 16-18), spread over a few milligrams, would throw
        it away at metres per second.  It gets no share; the rest of the
        blade's tissue takes it (:mod:`cutkit.relax.momentum` keeps the loose
        piece's own momentum).
        """
        from cutkit.relax.momentum import held_pieces

        labels, held = held_pieces(self.springs)
        return nodes if held.all() else nodes[held[labels[nodes]]]

    def advance(self, f_ext: np.ndarray, until: float, stop=None) -> int:
        """Process the node lists up to ``until`` s and bring every node there; returns list passes.

        Every node is brought to the same time at every call, whether a frame
        is written or not, so what is written never changes what is simulated.
        ``stop`` is not read: a pass of the springs is short.
        """
        return self.lists.advance(Control(external_forces=f_ext), until, synchronise=True)

    def _read_materials(self) -> None:
        """Young's modulus, density, prestrain and fibre of each original tet, from the store's labels
        (a sub-tet has its original's; the springs have no Poisson ratio: the table's is not read)."""
        mat = material_of_tets(self.model, self.store.labels, poisson_ratio=0.0)
        self.E, self.rho = mat["E"], mat["density"]
        self.prestrain, self.fibre = prestress_of_tets(self.model, self.store.labels)

    # ------------------------------------------------------------------ strokes
    def rebase(self, old_of_new: np.ndarray) -> None:
        """Follow :meth:`TissueStore.rebase <cutkit.tissue.store.TissueStore.rebase>` (called after it, between strokes).

        The live tets became the original tets ``0 .. m-1`` of a fresh cut
        state: the per-tet records (rest volume, prestress terms) move to
        the new ids, the per-original-tet materials are read again from the
        store's labels and model tets.  Springs, their sums, masses and node lists are
        per node pair or node and stay; no node is a cut node any more, so
        the cut nodes' tet lists restart.

        Parameters as :meth:`TissueBase.rebase`.
        """
        old_of_new = np.asarray(old_of_new, np.int64)
        m, cap = old_of_new.shape[0], max(self.store.tet_capacity, old_of_new.shape[0])
        rec_V, rec_sv = np.zeros(cap), np.zeros((cap, 6))
        rec_V[:m], rec_sv[:m] = self.rec_V[old_of_new], self.rec_sv[old_of_new]
        self.rec_V, self.rec_sv = rec_V, rec_sv
        self._read_materials()  # the store's labels and model tets follow its rebase
        self.model_V = self.model_tet_V[self.store.model_tet]
        self.n_orig_tets = int(m)
        self._node_tets = {}
