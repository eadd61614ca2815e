"""The settle cache: a model settles once, and a cached run simulates exactly what an uncached one does."""

import numpy as np
import pytest

from _tissues import with_cut_mesh
from cutkit.assign.defaults import DEFAULT_MATERIALS
from cutkit.cutting.trajectory import straight_incision
from cutkit.mesh.generate import box_mesh
from cutkit.model.tetmodel import BoundaryConditions, Materials, Prestress, TetModel
from cutkit.relax import settle_cache
from cutkit.simulate import SimulateOptions, simulate


def prestressed_block(prestrain=0.15, E=None):
    """A 16 x 6 x 8 mm block fixed at both ends, prestrained along z: its settle moves every node."""
    points, tets = box_mesh((8, 3, 4), spacing=(2.0, 2.0, 2.0))
    ends = np.flatnonzero((points[:, 2] == 0) | (points[:, 2] == 8.0))
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    if E is not None:
        row["E"] = E
    return TetModel.from_arrays(
        points, tets, materials=Materials.from_rows([row]), boundary=BoundaryConditions(fixed_nodes=ends),
        prestress=Prestress(label=np.array([1], np.int32), fibre_direction=np.array([[0.0, 0.0, 1.0]]),
                            prestrain=np.array([prestrain])))


def cut(model, out):
    traj = straight_incision([3.0, 0.0, 4.3], [13.0, 0.0, 4.3], inward=[0, 1, 0], depth=3.0, approach=2.0,
                             press_time=0.2, cut_time=0.3, rate=100)
    return simulate(model, traj, out, SimulateOptions(fps=10, hold_s=0.1))


def _result(out):
    """What a run wrote that depends on the simulation: the cut model's arrays and the forces."""
    from cutkit.io.model_h5 import read_model

    m = read_model(out / "model.h5")
    return m.points, m.tets, m.point_data["displacement"], (out / "forces.csv").read_text()


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("CUTKIT_CACHE_DIR", str(folder))
    return folder / "settle"


def test_a_cached_settle_simulates_exactly_what_a_solved_one_does(tmp_path, cache, monkeypatch):
    model = prestressed_block()
    first = cut(model, tmp_path / "a")
    assert first["settle"]["cached"] is False and first["settle"]["iterations"] >= 1
    assert len(list(cache.glob("*.npz"))) == 1
    second = cut(model, tmp_path / "b")
    assert second["settle"]["cached"] is True
    assert {k: v for k, v in second["settle"].items() if k != "cached"} == \
        {k: v for k, v in first["settle"].items() if k != "cached"}
    for a, b in zip(_result(tmp_path / "a"), _result(tmp_path / "b")):
        if isinstance(a, str):
            assert a == b
        else:
            np.testing.assert_array_equal(a, b)  # to the bit
    # off: the same again, solved
    monkeypatch.setenv("CUTKIT_CACHE_DIR", "off")
    assert settle_cache.cache_dir() is None
    third = cut(model, tmp_path / "c")
    assert third["settle"]["cached"] is False
    np.testing.assert_array_equal(_result(tmp_path / "a")[2], _result(tmp_path / "c")[2])


def settled(model):
    """A fresh element tissue of ``model`` settled as ``simulate`` settles it: (report, positions)."""
    from cutkit.relax.elastic_tissue import ElasticTissue

    tis = with_cut_mesh(ElasticTissue(model, step_s=0.004), 10.0)
    report = tis.settle(8, 1e-3)
    return report, tis.positions.copy()


def test_other_materials_or_prestress_settle_again(cache):
    settled(prestressed_block())
    assert settled(prestressed_block(E=60e3))[0]["cached"] is False
    assert settled(prestressed_block(prestrain=0.1))[0]["cached"] is False
    assert len(list(cache.glob("*.npz"))) == 3
    assert settled(prestressed_block(prestrain=0.1))[0]["cached"] is True


@pytest.mark.parametrize("damage", ["foreign", "truncated"])
def test_a_corrupt_cache_file_is_solved_again_and_replaced(cache, damage):
    model = prestressed_block()
    first, x_first = settled(model)
    (path,) = cache.glob("*.npz")
    data = path.read_bytes()
    path.write_bytes(b"not a cache file" if damage == "foreign" else data[:len(data) // 2])
    again, x_again = settled(model)
    assert again["cached"] is False and again["iterations"] == first["iterations"]
    np.testing.assert_array_equal(x_first, x_again)
    hit, x_hit = settled(model)  # replaced by a good one
    assert hit["cached"] is True
    np.testing.assert_array_equal(x_first, x_hit)


def test_an_unwritable_cache_folder_leaves_the_settle_uncached(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a file where the folder would be")
    monkeypatch.setenv("CUTKIT_CACHE_DIR", str(blocker))
    assert settled(prestressed_block())[0]["cached"] is False
    assert settled(prestressed_block())[0]["cached"] is False
