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


def _boxes(shapes, held_boxes):
    """Boxes of 1 mm cells of ``shapes`` side by side along x, 1 mm apart (no node shared); the boxes
    whose index is in ``held_boxes`` held at their x = min face.  (model, first node of each box)."""
    import numpy as np

    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.mesh.generate import box_mesh
    from cutkit.model.tetmodel import BoundaryConditions, Materials, TetModel

    points, tets, first, held, x0 = [], [], [], [], 0.0
    n = 0
    for b, shape in enumerate(shapes):
        p, t = box_mesh(shape, spacing=(1.0, 1.0, 1.0))
        p = p + [x0, 0.0, 0.0]
        points.append(p)
        tets.append(t + n)
        first.append(n)
        if b in held_boxes:
            held.append(n + np.flatnonzero(p[:, 0] == x0))
        n += len(p)
        x0 += shape[0] + 1.0
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    model = TetModel.from_arrays(np.concatenate(points), np.concatenate(tets), materials=Materials.from_rows([row]),
                                 boundary=BoundaryConditions(fixed_nodes=np.concatenate(held)))
    return model, first


@pytest.mark.parametrize("material", ["neohookean", "springs"])
def test_a_loose_piece_takes_no_share_of_the_blade_load(material):
    """A piece with no held node (what a cut sets loose) gets no share of the blade's reaction, in
    either material model: the held piece's nodes take it all, by mass; where the blade touches only
    loose tissue nobody does (the element model once threw such a slice 500 mm away)."""
    import numpy as np

    model, first = _boxes([(4, 2, 2), (2, 2, 2)], held_boxes={0})
    if material == "springs":
        from cutkit.relax.spring_tissue import Tissue

        tis = with_cut_mesh(Tissue(model, dt0=1e-3, n_lists=1, tolerance_fraction=1e-3), 10.0)
    else:
        from cutkit.relax.elastic_tissue import ElasticTissue

        tis = with_cut_mesh(ElasticTissue(model, step_s=0.004), 10.0)
    x = model.points
    near_gap = np.flatnonzero((x[:, 0] == 4.0) | (x[:, 0] == 5.0))  # the two facing faces
    nodes, shares = tis.load_shares(near_gap)
    assert nodes.size and nodes.max() < first[1]
    np.testing.assert_array_equal(nodes, _rings(model.tets, near_gap[near_gap < first[1]], 2))
    assert shares.sum() == pytest.approx(1.0, abs=1e-12)
    nodes, shares = tis.load_shares(np.flatnonzero(x[:, 0] >= 5.0))
    assert nodes.size == 0 and shares.size == 0


def _loose_twin(tets, n, held, nodes, budget):
    """(k,) bool: ``nodes`` in a component of the tets' node graph with no held node and at most
    ``budget`` nodes (scipy's connected components)."""
    import numpy as np
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    r = np.repeat(tets, 4, axis=1).ravel()
    c = np.tile(tets, (1, 4)).ravel()
    _, label = connected_components(coo_matrix((np.ones(r.size), (r, c)), shape=(n, n)), directed=False)
    size = np.bincount(label)
    anchored = np.bincount(label, weights=held.astype(float), minlength=size.size) > 0
    return ~anchored[label[nodes]] & (size[label[nodes]] <= budget)


def test_loose_nodes_kernel_equals_connected_components():
    """cutkit.relax.kernels.loose_nodes against _loose_twin: boxes of 8 to 48 nodes, random held
    nodes and queries (repeats and several per box), budgets below, at and above the boxes' sizes."""
    import numpy as np

    from cutkit.relax.elastic_tissue import ElasticTissue
    from cutkit.relax.kernels import loose_nodes

    model, _ = _boxes([(1, 1, 1), (2, 2, 2), (3, 2, 2), (1, 1, 2)], held_boxes={0})  # the kernel takes its own held
    tis = with_cut_mesh(ElasticTissue(model, step_s=0.004), 10.0)
    n = tis.em.n_nodes
    rng = np.random.default_rng(5)
    checked = 0
    for trial in range(40):
        fixed = rng.random((n, 3)) < (0.0, 0.01, 0.04)[trial % 3]  # any held direction anchors a piece
        held = fixed.any(axis=1)
        nodes = rng.integers(0, n, rng.integers(1, 12)).astype(np.int64)
        for budget in (4, 8, 27, 48, 1000):
            got = loose_nodes(tis.em.adjacency, nodes, fixed, budget, n)
            want = _loose_twin(model.tets, n, held, nodes, budget)
            np.testing.assert_array_equal(got, want, err_msg=f"{trial} {budget}")
            checked += int(want.any())
    assert checked > 20  # loose answers were met, not only held ones
