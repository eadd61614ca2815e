"""Both tissue models provide what the session asks of a physics (cutkit.tissue.TissuePhysics)."""

import inspect

import pytest

from _tissues import with_cut_mesh
from cutkit.tissue import TissuePhysics


def _members():
    return [n for n in dir(TissuePhysics) if not n.startswith("_") and n not in dir(object)]


@pytest.mark.parametrize("module, name", [("cutkit.relax.spring_tissue", "Tissue"),
                                          ("cutkit.relax.elastic_tissue", "ElasticTissue")])
def test_tissue_models_implement_the_protocol(module, name):
    import importlib

    cls = getattr(importlib.import_module(module), name)
    members = _members()
    assert {"settle", "advance", "apply_delta", "rebase", "load_shares", "masses", "positions"} <= set(members)
    for m in members:
        assert hasattr(cls, m), f"{name} has no {m}"
        want = getattr(TissuePhysics, m)
        if inspect.isfunction(want):  # same number of positional parameters
            got = getattr(cls, m)
            n_want = len(inspect.signature(want).parameters)
            params = inspect.signature(got).parameters.values()
            required = sum(p.default is inspect.Parameter.empty for p in params)
            assert required <= n_want <= len(params), f"{name}.{m}"


def _two_touching_boxes():
    """Two 4 x 2 x 2 mm boxes of 1 mm cells side by side at x = 4, sharing no node (as the two
    walls of a cut do), each held at its far end."""
    import numpy as np

    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.mesh.generate import box_mesh
    from cutkit.model.tetmodel import BoundaryConditions, Materials, TetModel

    p, t = box_mesh((4, 2, 2), spacing=(1.0, 1.0, 1.0))
    points = np.concatenate([p, p + [4.0, 0.0, 0.0]])
    tets = np.concatenate([t, t + len(p)])
    held = np.flatnonzero((points[:, 0] == 0.0) | (points[:, 0] == 8.0))
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    return TetModel.from_arrays(points, tets, materials=Materials.from_rows([row]),
                                boundary=BoundaryConditions(fixed_nodes=held)), len(p)


def _rings(tets, seeds, k):
    """Nodes within k rings of tets of ``seeds``, by a plain breadth-first search over the tets."""
    import numpy as np

    nodes = set(int(v) for v in seeds)
    for _ in range(k):
        nodes |= {int(v) for row in tets if nodes & set(row.tolist()) for v in row}
    return np.array(sorted(nodes))


@pytest.mark.parametrize("material", ["neohookean", "springs"])
def test_the_blade_load_goes_by_mass_over_two_rings_and_never_across_a_cut(material):
    """load_shares: the nodes within BLADE_LOAD_RINGS rings of tets of the given ones (a breadth-first
    search over the tets here), none of the other box however close, each share its lumped mass over
    the sum (one material: V / 4 per node and tet, computed here), the shares summing to 1."""
    import numpy as np

    from cutkit.tissue import BLADE_LOAD_RINGS

    model, n_first = _two_touching_boxes()
    if material == "springs":
        from cutkit.relax.spring_tissue import Tissue

        tis = with_cut_mesh(Tissue(model, dt0=1e-3, n_lists=1, tolerance_fraction=1e-3), 10.0)
    else:
        from cutkit.relax.elastic_tissue import ElasticTissue

        tis = with_cut_mesh(ElasticTissue(model, step_s=0.004), 10.0)
    x = model.points
    seeds = np.flatnonzero((x[:, 0] == 3.0) & (x[:, 1] == 1.0) & (x[:, 2] == 1.0))  # 1 mm from the other box
    nodes, shares = tis.load_shares(seeds)
    assert BLADE_LOAD_RINGS == 2
    np.testing.assert_array_equal(nodes, _rings(model.tets, seeds, BLADE_LOAD_RINGS))
    assert nodes.max() < n_first  # x = 5 is 2 mm away, in the other box: not reached
    assert shares.sum() == pytest.approx(1.0, abs=1e-12)
    V = np.abs(np.linalg.det(x[model.tets[:, 1:]] - x[model.tets[:, :1]])) / 6.0
    lumped = np.bincount(model.tets.ravel(), weights=np.repeat(V / 4.0, 4), minlength=len(x))
    np.testing.assert_allclose(shares, lumped[nodes] / lumped[nodes].sum(), rtol=1e-9)


def test_node_rings_kernel_equals_a_breadth_first_search():
    """cutkit.relax.kernels.node_rings against _rings (a plain search over the tets), 0 to 3 rings."""
    import numpy as np

    from cutkit.relax.kernels import node_rings
    from cutkit.relax.elastic_tissue import ElasticTissue

    model, _ = _two_touching_boxes()
    tis = with_cut_mesh(ElasticTissue(model, step_s=0.004), 10.0)
    seeds = np.array([3, 40, 3], np.int64)
    for rings in range(4):
        got = node_rings(tis.em.adjacency, seeds, rings, tis.em.n_nodes)
        np.testing.assert_array_equal(got, _rings(model.tets, seeds, rings))
