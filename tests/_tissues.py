"""A physics with the cut state that writes its store, as a session pairs them (tests only)."""

from cutkit.cutting import CutMesh


def with_cut_mesh(tis, blade_length: float, centre_nodes: bool = False):
    """``tis`` with ``tis.cm``: a :class:`CutMesh` over its store (cuts made on it reach ``tis`` by
    ``tis.apply_cut``, as in a session)."""
    tis.cm = CutMesh.over(tis.store, blade_length=blade_length, centre_nodes=centre_nodes)
    return tis
