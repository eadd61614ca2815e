"""Progressive decimation of voxel ellipsoids: invariants, reduction, quality, the record."""

from __future__ import annotations

import numpy as np
import pytest

from _twins_decimate import (
    boundary_faces,
    faces_of,
    hausdorff,
    min_dihedral,
    volume6,
    voxel_ellipsoid,
)
from cutkit.decimate import decimate, extract_level, n_levels, replay
from cutkit.errors import InputError, MeshError
from cutkit.model.tetmodel import BoundaryConditions, TetModel

VOXEL = 1.0


def _model(n=32, **kw):
    points, tets, labels = voxel_ellipsoid(n, inner=0.6)
    return TetModel.from_arrays(points, tets, labels, **kw)


@pytest.fixture(scope="module")
def case():
    """A two-tissue ellipsoid (label 2 inside label 1) with fixed nodes, texcoords and cell data."""
    model = _model(32)
    rng = np.random.default_rng(1)
    fixed = np.sort(rng.choice(model.n_points, 40, replace=False))
    model.boundary = BoundaryConditions(
        fixed_nodes=fixed[:30],
        prescribed_nodes=fixed[30:],
        prescribed_displacement=np.ones((10, 3)),
    )
    model.texcoords = model.points / 40.0
    model.cell_data["tet_index"] = np.arange(model.n_tets, dtype=np.int64)
    model.point_data["node_index"] = np.arange(model.n_points, dtype=np.int64)
    out = decimate(model, ratio=0.1)
    return model, out


def test_ten_times_fewer_tets(case):
    model, out = case
    assert out.n_tets <= model.n_tets // 10
    assert out.provenance["decimate"]["output_tets"] == out.n_tets


def test_min_dihedral_at_least_10_degrees(case):
    _, out = case
    assert min_dihedral(out.points, out.tets).min() >= 10.0 - 1e-9


def test_tets_positive_and_faces_manifold(case):
    model, out = case
    assert volume6(out.points, out.tets).min() > 0
    key, _ = faces_of(out.tets)
    _, counts = np.unique(key, axis=0, return_counts=True)
    assert counts.max() <= 2
    # Closed 2-manifold boundary with the input's Euler characteristic (a sphere).
    bf = boundary_faces(out.points, out.tets)
    edges = np.sort(np.concatenate([bf[:, [0, 1]], bf[:, [1, 2]], bf[:, [2, 0]]]), axis=1)
    _, ec = np.unique(edges, axis=0, return_counts=True)
    assert np.all(ec == 2)
    chi = np.unique(bf).size - ec.size + bf.shape[0]
    assert chi == 2
    # every node is used by a tet
    assert np.unique(out.tets).size == out.n_points


def test_boundary_within_one_voxel(case):
    model, out = case
    d = hausdorff(model.points, boundary_faces(model.points, model.tets), out.points, boundary_faces(out.points, out.tets))
    assert d <= VOXEL


def test_tissue_volumes_within_3_percent(case):
    model, out = case
    for lab in (1, 2):
        v0 = volume6(model.points, model.tets[model.labels == lab]).sum()
        v1 = volume6(out.points, out.tets[out.labels == lab]).sum()
        assert abs(v1 - v0) <= 0.03 * v0, lab


def test_fixed_and_prescribed_nodes_are_kept(case):
    model, out = case
    bc0, bc1 = model.boundary, out.boundary
    np.testing.assert_array_equal(out.points[bc1.fixed_nodes], model.points[bc0.fixed_nodes])
    np.testing.assert_array_equal(out.points[bc1.prescribed_nodes], model.points[bc0.prescribed_nodes])
    np.testing.assert_array_equal(bc1.prescribed_displacement, bc0.prescribed_displacement)


def test_attributes_follow_the_collapses(case):
    model, out = case
    rec = out.extra["progressive"]
    np.testing.assert_array_equal(out.texcoords, out.points / 40.0)
    np.testing.assert_array_equal(out.cell_data["tet_index"], rec["tet_ids"])
    np.testing.assert_array_equal(out.point_data["node_index"], rec["node_ids"])
    np.testing.assert_array_equal(out.labels, model.labels[rec["tet_ids"]])
    np.testing.assert_array_equal(out.points, model.points[rec["node_ids"]])


def test_record_reproduces_the_output_exactly(case):
    model, out = case
    rec = out.extra["progressive"]
    k = n_levels(out)
    assert rec["tet_counts"].shape == (k + 1,) and rec["tet_counts"][0] == model.n_tets
    assert rec["tet_counts"][-1] == out.n_tets
    assert np.all(np.diff(rec["tet_counts"]) < 0)  # every collapse removes a tet
    again = extract_level(out, k)
    np.testing.assert_array_equal(again.tets, out.tets)
    np.testing.assert_array_equal(again.points, out.points)
    np.testing.assert_array_equal(again.labels, out.labels)
    np.testing.assert_array_equal(again.boundary.fixed_nodes, np.unique(out.boundary.fixed_nodes))
    np.testing.assert_array_equal(again.texcoords, out.texcoords)


def test_two_levels_have_the_recorded_tet_counts(case):
    model, out = case
    rec = out.extra["progressive"]
    for level in (0, n_levels(out) // 3):
        lv = extract_level(out, level)
        assert lv.n_tets == rec["tet_counts"][level]
        assert volume6(lv.points, lv.tets).min() > 0
        np.testing.assert_array_equal(lv.points[lv.boundary.fixed_nodes], model.points[model.boundary.fixed_nodes])
    finest = extract_level(out, 0)
    np.testing.assert_array_equal(finest.tets, model.tets)
    assert finest.cell_data == {}  # finer than the model: no per-tet data for the restored tets


def test_coarser_level_keeps_cell_and_point_data(case):
    _, out = case
    mid = extract_level(out, n_levels(out) // 2)
    mid.cell_data["mid_tet"] = np.arange(mid.n_tets)
    mid.point_data["mid_node"] = np.arange(mid.n_points)
    coarse = extract_level(mid, n_levels(out))
    np.testing.assert_array_equal(coarse.tets, out.tets)
    mid_rec = mid.extra["progressive"]
    np.testing.assert_array_equal(mid_rec["tet_ids"][coarse.cell_data["mid_tet"]], out.extra["progressive"]["tet_ids"])
    np.testing.assert_array_equal(mid_rec["node_ids"][coarse.point_data["mid_node"]], out.extra["progressive"]["node_ids"])


def test_decimating_again_continues_the_record(case):
    model, out = case
    half = extract_level(out, n_levels(out) // 2)
    again = decimate(half, target_tets=half.n_tets // 2)
    rec = again.extra["progressive"]
    np.testing.assert_array_equal(rec["collapse_u"][: n_levels(out) // 2], out.extra["progressive"]["collapse_u"][: n_levels(out) // 2])
    replayed = extract_level(again, n_levels(again))
    np.testing.assert_array_equal(replayed.tets, again.tets)
    np.testing.assert_array_equal(replayed.points, again.points)
    t, ids, _ = replay(model.tets, rec["collapse_u"], rec["collapse_v"], model.n_points, n_levels(again))
    assert t.shape[0] == again.n_tets


def test_slivers_are_never_made_worse():
    # A box whose interior nodes are jittered: some input tets are below 10 degrees.
    from cutkit.mesh.generate import box_mesh

    points, tets = box_mesh((8, 8, 8))
    rng = np.random.default_rng(3)
    inner = np.all((points > 0.5) & (points < 7.5), axis=1)
    points[inner] += rng.uniform(-0.3, 0.3, (inner.sum(), 3))
    assert volume6(points, tets).min() > 0
    before = min_dihedral(points, tets)
    assert before.min() < 10.0
    model = TetModel.from_arrays(points, tets)
    out = decimate(model, ratio=0.3)
    after = min_dihedral(out.points, out.tets)
    assert after.min() >= before.min() - 1e-9
    assert np.mean(after < 10.0) <= np.mean(before < 10.0)
    assert out.n_tets < model.n_tets


def test_surface_tolerance_zero_keeps_the_boundary_of_a_box():
    from cutkit.mesh.generate import box_mesh

    points, tets = box_mesh((6, 6, 6))
    model = TetModel.from_arrays(points, tets)
    out = decimate(model, ratio=0.2, surface_tolerance_mm=0.0)
    # Flat sides can be decimated at zero tolerance, but the box must stay the box.
    assert np.isclose(volume6(out.points, out.tets).sum() / 6.0, 216.0)
    np.testing.assert_allclose(out.points.min(axis=0), 0.0)
    np.testing.assert_allclose(out.points.max(axis=0), 6.0)
    corners = np.array([[x, y, z] for x in (0, 6) for y in (0, 6) for z in (0, 6)], float)
    for c in corners:
        assert np.any(np.all(out.points == c, axis=1))


@pytest.mark.parametrize(
    "kwargs, error, message",
    [
        ({}, InputError, "give exactly one of target_tets or ratio"),
        ({"ratio": 0.5, "target_tets": 10}, InputError, "give exactly one of target_tets or ratio"),
        ({"ratio": 1.5}, InputError, "ratio must be the fraction of tets to keep, in (0, 1], got 1.5"),
        ({"target_tets": 0}, InputError, "target_tets must be a positive integer, got 0"),
        ({"ratio": 0.5, "surface_tolerance_mm": -1.0}, InputError, "surface_tolerance_mm must be a finite number >= 0, got -1.0"),
        ({"ratio": 0.5, "min_dihedral_deg": 80.0}, InputError, "min_dihedral_deg must be in [0, 70), got 80.0"),
    ],
)
def test_bad_arguments(kwargs, error, message):
    from cutkit.mesh.generate import box_mesh

    model = TetModel.from_arrays(*box_mesh((2, 2, 2)))
    with pytest.raises(error) as err:
        decimate(model, **kwargs)
    assert str(err.value) == message


def test_inverted_tet_is_refused():
    from cutkit.mesh.generate import box_mesh

    points, tets = box_mesh((2, 2, 2))
    tets[5, [2, 3]] = tets[5, [3, 2]]
    with pytest.raises(MeshError) as err:
        decimate(TetModel.from_arrays(points, tets), ratio=0.5)
    assert str(err.value) == "1 tets are inverted or flat (first: tet 5); decimation needs positively oriented tets"


def test_level_out_of_range_and_missing_record(case):
    _, out = case
    k = n_levels(out)
    with pytest.raises(InputError) as err:
        extract_level(out, k + 1)
    assert str(err.value) == f"level {k + 1} is out of range: the progressive record has levels 0..{k}"
    from cutkit.mesh.generate import box_mesh

    with pytest.raises(InputError) as err:
        extract_level(TetModel.from_arrays(*box_mesh((1, 1, 1))), 0)
    assert "no progressive record" in str(err.value)


def test_cli_decimate_and_extract_level(tmp_path):
    from cutkit.cli.main import main
    from cutkit.io.model_h5 import read_model, write_model

    model = _model(16)
    src = tmp_path / "model.h5"
    write_model(src, model)
    out = tmp_path / "out.h5"
    assert main(["decimate", str(src), "-o", str(out), "--ratio", "0.2"]) == 0
    dec = read_model(out)
    assert dec.n_tets <= model.n_tets * 0.2
    rec = dec.extra["progressive"]
    assert rec["collapse_u"].dtype == np.int64 and rec["tet_counts"][-1] == dec.n_tets
    k = n_levels(dec) // 2
    lvl = tmp_path / "level.h5"
    assert main(["decimate", str(out), "-o", str(lvl), "--level", str(k)]) == 0
    assert read_model(lvl).n_tets == rec["tet_counts"][k]
    # a bad combination is one line on stderr and exit code 2, no output written
    bad = tmp_path / "bad.h5"
    assert main(["decimate", str(src), "-o", str(bad), "--ratio", "0.2", "--level", "3"]) == 2
    assert not bad.exists()


# --------------------------------------------------------------------------- the optional optimiser pass


def _kuhn_cube(shift):
    """A 4^3-voxel Kuhn cube whose first interior node is pushed by ``shift`` voxels (bad tets around it)."""
    from cutkit.decimate.optimize import surface_faces_with_sheets

    points, tets, labels = voxel_ellipsoid(4, radii=(0.9, 0.9, 0.9))
    faces, _ = surface_faces_with_sheets(tets, labels)
    node = np.setdiff1d(np.arange(points.shape[0]), faces)[0]
    bad = points.copy()
    bad[node] += shift * np.array([1.0, 1.0, -1.0]) / np.sqrt(3.0)
    return points, bad, tets, labels, faces


def _fake_gmsh(points, tets, labels, seed=0):
    """A stand-in for gmsh's result: the given mesh with its nodes and tets renumbered."""
    rng = np.random.default_rng(seed)
    perm = rng.permutation(points.shape[0])
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    order = rng.permutation(tets.shape[0])
    return lambda *args: (points[perm].copy(), inv[tets[order]], labels[order])


def test_netgen_pass_reports_its_decision():
    from cutkit.decimate.optimize import optimize
    from cutkit.mesh.check import check_mesh

    model = decimate(_model(14), ratio=0.15)
    out, rep = optimize(model, "netgen")
    assert out.provenance["decimate"]["optimize"] == rep
    assert rep["min_dihedral_before_deg"] == pytest.approx(min_dihedral(model.points, model.tets).min(), abs=1e-6)
    assert check_mesh(out.points, out.tets, out.labels).passed
    if rep["accepted"]:
        assert rep["min_dihedral_after_deg"] > rep["min_dihedral_before_deg"]
        assert min_dihedral(out.points, out.tets).min() == pytest.approx(rep["min_dihedral_after_deg"], abs=1e-6)
    else:  # the input is returned untouched, record included
        assert out.points is model.points and out.tets is model.tets
        assert "progressive" in out.extra and rep["reason"]
    assert rep["max_boundary_shift_mm"] == 0.0  # netgen keeps the bounding surfaces' nodes


def test_optimiser_result_is_kept_when_better_and_nodes_follow(monkeypatch):
    from cutkit.decimate import optimize as O
    from cutkit.mesh.check import check_mesh

    good, bad, tets, labels, faces = _kuhn_cube(0.45)
    fixed = faces[:5, 0]
    model = TetModel.from_arrays(bad, tets, labels)
    model.boundary = BoundaryConditions(fixed_nodes=fixed, prescribed_nodes=np.zeros(0, np.int64),
                                        prescribed_displacement=np.zeros((0, 3)))
    monkeypatch.setattr(O, "_run_gmsh", _fake_gmsh(good, tets, labels))
    out, rep = O.optimize(model)
    assert rep["accepted"], rep["reason"]
    assert rep["min_dihedral_after_deg"] == pytest.approx(45.0) and rep["min_dihedral_before_deg"] < 40.0
    assert rep["nodes_new"] == 1 and rep["max_boundary_shift_mm"] == 0.0
    assert check_mesh(out.points, out.tets, out.labels).passed
    np.testing.assert_array_equal(out.points[out.boundary.fixed_nodes], bad[fixed])  # conditions follow their nodes
    assert np.all(volume6(out.points, out.tets) > 0)
    assert out.provenance["decimate"]["optimize"]["accepted"]


@pytest.mark.parametrize("what, reason", [("texcoords", "texture"), ("boundary", "boundary"), ("worse", "not raised")])
def test_optimiser_result_is_rejected(monkeypatch, what, reason):
    from cutkit.decimate import optimize as O

    good, bad, tets, labels, faces = _kuhn_cube(0.45)
    model = TetModel.from_arrays(bad, tets, labels)
    result = good.copy()
    if what == "texcoords":
        model.texcoords = bad / 4.0  # the moved node's texture coordinate is unknown
    elif what == "boundary":
        result[faces[0, 0]] += 0.01
    else:
        model = TetModel.from_arrays(good, tets, labels)
        result = bad
    monkeypatch.setattr(O, "_run_gmsh", _fake_gmsh(result, tets, labels))
    out, rep = O.optimize(model)
    assert not rep["accepted"] and reason in rep["reason"]
    assert out.points is model.points and out.provenance["decimate"]["optimize"]["reason"] == rep["reason"]


def test_cli_and_recipe_optimize(tmp_path):
    from cutkit.cli.main import main
    from cutkit.io.model_h5 import read_model, write_model
    from cutkit.recipe import load_recipe

    src = tmp_path / "model.h5"
    write_model(src, _model(12))
    out = tmp_path / "out.h5"
    assert main(["decimate", str(src), "-o", str(out), "--ratio", "0.3", "--optimize", "netgen"]) == 0
    rep = read_model(out).provenance["decimate"]["optimize"]
    assert rep["method"] == "netgen" and isinstance(rep["accepted"], bool)
    assert main(["decimate", str(src), "-o", str(tmp_path / "bad.h5"), "--ratio", "0.3", "--optimize", "tetgen"]) == 2
    recipe = tmp_path / "r.toml"
    recipe.write_text("[decimate]\nratio = 0.1\noptimize = 'netgen'\n")
    assert load_recipe(recipe)["decimate"]["optimize"] == "netgen"
    recipe.write_text("[decimate]\nratio = 0.1\noptimize = 'gmsh'\n")
    with pytest.raises(InputError, match="optimize must be 'netgen'"):
        load_recipe(recipe)
