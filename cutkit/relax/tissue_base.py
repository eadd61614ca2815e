"""What both tissue models of a session share (:class:`TissueBase`): the store they read and its nodes.

The springs (:class:`cutkit.relax.spring_tissue.Tissue`, the paper's) and the
elements (:class:`cutkit.relax.elastic_tissue.ElasticTissue`) keep their
nodes on the tissue store's numbering (:class:`cutkit.tissue.store.TissueStore`);
this base class interpolates cut nodes over their defining nodes, carries
the blade into the rest configuration and lists the live tetrahedra.
"""

from __future__ import annotations

import numpy as np

from cutkit.tissue.store import TissueStore


def uncut_store(model, store: TissueStore | None) -> TissueStore:
    """The store a physics of ``model`` is made over: ``store``, which must hold the model as loaded
    (nothing cut, never rebased), or a new one of the model (None)."""
    if store is None:
        return TissueStore.from_model(model)
    if store.n_rebases or store.n_tets_total != store.n_orig_tets or store.n_orig_tets != len(model.tets):
        from cutkit.errors import InputError

        raise InputError("a tissue physics is made over the store of its model before anything is cut")
    return store


class TissueBase:
    """What both tissue kinds share: the store, node interpolation, the live tets.

    Subclasses set ``store`` (:class:`~cutkit.tissue.store.TissueStore`, which they only read) and provide
    ``positions``, ``rest_positions``, ``velocities``, ``fixed``, ``time``,
    :meth:`settle`, :meth:`advance` and :meth:`apply_delta`.
    """

    store: TissueStore
    #: Radius of the neighbourhood whose displacement carries the blade (:mod:`cutkit.relax.rest_map`), mm.
    rest_map_radius: float
    #: Its flood fill's buffers (:class:`cutkit.relax.rest_map.BladeNeighbourhood`), made on first use.
    _blade_hood = None

    def rebase(self, old_of_new: np.ndarray) -> None:
        """Follow :meth:`TissueStore.rebase <cutkit.tissue.store.TissueStore.rebase>` (called after it, between strokes).

        Parameters
        ----------
        old_of_new : (m,) int64
            Old tet id of each new original tet.
        """
        raise NotImplementedError

    def apply_delta(self, delta) -> dict:
        """Grow the physics by one cut step's :class:`~cutkit.tissue.TopologyDelta`; counts of what changed."""
        raise NotImplementedError

    def apply_cut(self, res) -> dict:
        """Carry a cut step's result (its ``delta``) over: :meth:`apply_delta` of its ``delta``."""
        return self.apply_delta(res.delta)

    def interpolate_positions(self, nodes: np.ndarray) -> np.ndarray:
        """Current positions of cut nodes from their defining nodes, (p, 3) float64.

        The cut works in the rest configuration; a cut node's weights
        over its defining original nodes carry over to the deformed ones.
        """
        store = self.store
        par = store.defining_nodes[nodes]
        w = np.where(par >= 0, store.defining_weights[nodes], 0.0)
        return np.einsum("pq,pqc->pc", w, self.positions[np.where(par >= 0, par, 0)])

    def _interpolation_weights(self, nodes: np.ndarray):
        """Defining nodes (p, q) and their normalised weights (p, q) of cut nodes (invalid slots weigh 0)."""
        store = self.store
        par = store.defining_nodes[nodes]
        valid = par >= 0
        wz = np.where(valid, store.defining_weights[nodes], 0.0)
        wsum = wz.sum(axis=1, keepdims=True)
        return np.where(valid, par, 0), wz / np.where(wsum > 0, wsum, 1.0), valid

    def blade_to_rest(self, point, axis, blade_length: float, active_tets: np.ndarray,
                      entry_nodes: np.ndarray) -> np.ndarray:
        """Carry the blade's tip from the deformed tissue into the rest configuration, (3,) float64.

        The cut is made in the rest configuration, where no original
        tetrahedron is ever inverted, so the cut's topology does not depend
        on how far the tissue has moved.  The blade is moved back by the
        displacement of the tissue around it (:mod:`cutkit.relax.rest_map`:
        the smooth weighted mean over the nodes near the blade; first order,
        the local rotation and stretch are neglected), or before the blade
        has met a tetrahedron, by the mean displacement of the entry face's
        nodes.

        Parameters
        ----------
        point : (3,) float64  the tip (the proxy), deformed configuration, mm
        axis : (3,) float64  unit vector along the blade, handle to tip
        blade_length : float  mm
        active_tets : (k,) int64  the last cut step's active (original) tets
        entry_nodes : (q,) int64  the nodes of the face the blade entered through
        """
        from cutkit.relax.rest_map import rest_displacement

        point = np.asarray(point, np.float64)
        if len(active_tets):
            nodes, w = self.blade_neighbourhood(point, axis, blade_length, active_tets)
            u = rest_displacement(self.positions, self.rest_positions, nodes, w)
            if u is not None:
                return point - u
        if len(entry_nodes) == 0:
            return point.copy()
        return point - (self.positions[entry_nodes] - self.rest_positions[entry_nodes]).mean(axis=0)

    def blade_neighbourhood(self, point, axis, blade_length: float, active_tets: np.ndarray):
        """The original nodes (k,) int64 within :attr:`rest_map_radius` of the blade (deformed positions) and
        their weights (k,) float64 (:func:`cutkit.relax.rest_map.blade_weights`), found by a flood fill
        from ``active_tets`` (original tets).

        Parameters
        ----------
        point : (3,) float64  the blade's tip, deformed configuration, mm
        axis : (3,) float64  unit vector along the blade, handle to tip
        blade_length : float  mm
        active_tets : (k,) int64
        """
        from cutkit.relax.rest_map import BladeNeighbourhood, blade_weights

        point, axis = np.asarray(point, np.float64), np.asarray(axis, np.float64)
        hood = self._blade_hood
        if hood is None or hood.n_rebases != self.store.n_rebases:  # the first, or the mesh was rebased
            hood = self._blade_hood = BladeNeighbourhood(self.store, self.rest_map_radius)
        nodes, d2 = hood.nodes(self.store, self.positions, active_tets, point - blade_length * axis, point)
        return nodes, blade_weights(d2, self.rest_map_radius)

    def load_shares(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`cutkit.tissue.TissuePhysics.load_shares`: ``nodes`` grown by
        :data:`~cutkit.tissue.BLADE_LOAD_RINGS` rings (:meth:`node_rings`), those
        :meth:`bearing_nodes` keeps, each in proportion to its mass."""
        from cutkit.tissue import BLADE_LOAD_RINGS

        nodes = self.bearing_nodes(self.node_rings(np.unique(np.asarray(nodes, np.int64)), BLADE_LOAD_RINGS))
        m = self.masses[nodes]
        total = float(m.sum())
        if not total > 0.0:
            return nodes[:0], np.empty(0)
        return nodes, m / total

    def at_rest(self) -> bool:
        """Whether the tissue has come to rest after the blade left (a model that cannot tell: False)."""
        return False

    def prepare_resting(self) -> None:
        """Nothing to build ahead (a model without resting steps)."""

    def node_rings(self, nodes: np.ndarray, rings: int) -> np.ndarray:
        """(j,) int64 ascending: ``nodes`` (k,) int64 grown by ``rings`` rings of live tets (each ring adds
        every node sharing a tet with one found so far)."""
        raise NotImplementedError

    def bearing_nodes(self, nodes: np.ndarray) -> np.ndarray:
        """The nodes of ``nodes`` (k,) int64 that bear the blade's reaction (all, unless a model says otherwise)."""
        return nodes

    def alive_tets(self) -> tuple[np.ndarray, np.ndarray]:
        """(k, 4) int64 current tets and (k,) int64 their ids."""
        store = self.store
        ids = np.flatnonzero(store.tet_alive)
        return store.tet_corners[ids], ids

    @property
    def displacement(self) -> np.ndarray:
        """(n, 3) float64 positions minus rest positions, mm."""
        return self.positions - self.rest_positions

    def point_data(self) -> dict:
        """Further per-node arrays for the frames."""
        return {}
