"""The model file: round trip, VTKHDF compatibility, and one clear error per defect."""

import shutil

import h5py
import numpy as np
import pytest

from cutkit.errors import InputError, ModelFormatError
from cutkit.io.model_h5 import SCHEMA_VERSION, read_model, write_model
from cutkit.mesh.generate import box_mesh
from cutkit.model import MATERIAL_FIELDS, BoundaryConditions, Materials, Prestress, TetModel, Texture


def _model():
    points, tets = box_mesh((3, 2, 2), spacing=(1.0, 1.5, 2.0), origin=(-1.0, 2.0, 3.0))
    labels = np.where(points[tets].mean(axis=1)[:, 0] < 0.5, 1, 2).astype(np.int32)
    rows = [
        dict(label=1, name="fat", **{**{k: 1.0 + i for i, k in enumerate(MATERIAL_FIELDS)}, "poisson_ratio": 0.41}),
        dict(label=2, name="muscle", **{**{k: 10.0 + i for i, k in enumerate(MATERIAL_FIELDS)}, "poisson_ratio": 0.3}),
    ]
    rng = np.random.default_rng(0)
    texture = Texture(
        volume=rng.integers(0, 256, (5, 4, 6, 3), dtype=np.uint8),
        spacing=np.array([1.0, 1.5, 2.0]),
        origin=np.array([-1.0, 2.0, 3.0]),
    )
    return TetModel.from_arrays(
        points,
        tets,
        labels,
        materials=Materials.from_rows(rows),
        boundary=BoundaryConditions(
            fixed_nodes=np.array([0, 1, 2]),
            prescribed_nodes=np.array([5]),
            prescribed_displacement=np.array([[0.0, 0.0, 1.0]]),
        ),
        prestress=Prestress(label=np.array([2], np.int32), fibre_direction=np.array([[0.0, 0.0, 1.0]]), prestrain=np.array([0.05])),
        texture=texture,
        texcoords=texture.index_to_texcoord(texture.world_to_index(points)),
        cell_data={"new_tet": np.zeros(len(tets), np.uint8)},
        point_data={"displacement": rng.normal(size=(len(points), 3))},
        provenance={"recipe": "test", "inputs": {"a.nrrd": "sha256:00"}},
        extra={"progressive": {"collapse_u": np.array([3, 4]), "collapse_v": np.array([1, 2])}},
    )


@pytest.fixture
def model_file(tmp_path):
    path = tmp_path / "model.h5"
    write_model(path, _model())
    return path


def test_round_trip_keeps_every_array(model_file):
    a, b = _model(), read_model(model_file)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.tets, b.tets)
    np.testing.assert_array_equal(a.labels, b.labels)
    assert b.materials.name == ["fat", "muscle"]
    for k in MATERIAL_FIELDS:
        np.testing.assert_array_equal(a.materials[k], b.materials[k])
    np.testing.assert_array_equal(a.boundary.fixed_nodes, b.boundary.fixed_nodes)
    np.testing.assert_array_equal(a.boundary.prescribed_displacement, b.boundary.prescribed_displacement)
    np.testing.assert_array_equal(a.prestress.fibre_direction, b.prestress.fibre_direction)
    np.testing.assert_array_equal(a.texture.volume, b.texture.volume)
    np.testing.assert_array_equal(a.texcoords, b.texcoords)
    np.testing.assert_array_equal(a.point_data["displacement"], b.point_data["displacement"])
    np.testing.assert_array_equal(a.cell_data["new_tet"], b.cell_data["new_tet"])
    np.testing.assert_array_equal(a.extra["progressive"]["collapse_u"], b.extra["progressive"]["collapse_u"])
    assert b.provenance["recipe"] == "test"
    assert b.provenance["cutkit_version"]


def test_vtkhdf_reader_gets_the_same_mesh(model_file):
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    reader = vtk.vtkHDFReader()
    reader.SetFileName(str(model_file))
    reader.Update()
    grid = reader.GetOutput()
    model = _model()
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetPoints().GetData()), model.points)
    conn = vtk_to_numpy(grid.GetCells().GetConnectivityArray()).reshape(-1, 4)
    np.testing.assert_array_equal(conn, model.tets)
    assert {grid.GetCellType(i) for i in range(grid.GetNumberOfCells())} == {10}
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetCellData().GetArray("label")), model.labels)
    rgb = vtk_to_numpy(grid.GetPointData().GetArray("texture_rgb"))
    assert rgb.shape == (model.n_points, 3)


def test_texture_rgb_samples_the_volume_at_voxel_centres():
    model = _model()
    tex = model.texture
    ijk = np.array([[0, 0, 0], [4, 3, 5], [2, 1, 3]], float)
    rgb = tex.sample_rgb(tex.index_to_texcoord(ijk))
    np.testing.assert_array_equal(rgb, tex.volume[[0, 4, 2], [0, 3, 1], [0, 5, 3]])


def _edit(path, fn):
    with h5py.File(path, "r+") as f:
        fn(f)


def _replace(name, data):
    def fn(f):
        del f[name]
        f.create_dataset(name, data=data)

    return fn


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda f: f["cutkit"].attrs.__setitem__("schema_version", 99), "schema version 99 is not supported (this cutkit reads versions 1, 2, 3)"),
        (lambda f: f.__delitem__("cutkit"), "not a cutkit model (no /cutkit group)"),
        (lambda f: f.__delitem__("VTKHDF/Points"), "VTKHDF/Points is missing"),
        (_replace("VTKHDF/Points", np.zeros((10, 2))), "VTKHDF/Points has shape (10, 2), expected (*, 3)"),
        (_replace("VTKHDF/Connectivity", np.full(72 * 4, 999, np.int64)), "VTKHDF/Connectivity has node index 999 (tet 0) out of range [0, 36)"),
        (_replace("VTKHDF/CellData/label", np.ones(72, np.float32)), "VTKHDF/CellData/label has dtype float32, expected signed integer or unsigned integer"),
        (_replace("VTKHDF/CellData/label", np.full(72, 7, np.int32)), "VTKHDF/CellData/label has label 7 with no row in /cutkit/materials"),
        (_replace("cutkit/boundary/fixed_nodes", np.array([0, 36])), "cutkit/boundary/fixed_nodes has node index 36 out of range [0, 36)"),
        (_replace("cutkit/materials/E", np.array([1.0, np.nan])), "cutkit/materials/E has non-finite values"),
        (_replace("VTKHDF/Types", np.full(72, 12, np.uint8)), "VTKHDF/Types has cell 0 of VTK type 12; only tetrahedra (10) are allowed"),
    ],
)
def test_each_defect_gets_its_own_one_line_error(model_file, edit, message):
    _edit(model_file, edit)
    with pytest.raises(ModelFormatError) as info:
        read_model(model_file)
    text = str(info.value)
    assert "\n" not in text
    assert text == f"{model_file}: {message}"


def test_nan_coordinates_are_named(model_file):
    def fn(f):
        pts = f["VTKHDF/Points"][()]
        pts[4, 1] = np.nan
        f["VTKHDF/Points"][...] = pts

    _edit(model_file, fn)
    with pytest.raises(ModelFormatError, match=r"VTKHDF/Points has 1 nodes with non-finite coordinates \(first: node 4\)"):
        read_model(model_file)


def test_truncated_file(model_file, tmp_path):
    data = model_file.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: len(data) // 3])
    with pytest.raises(ModelFormatError, match=r"cannot open model file \((truncated|not an HDF5 file or corrupt)\)"):
        read_model(cut)


def test_corrupt_and_missing_files(tmp_path):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"this is not hdf5" * 100)
    with pytest.raises(ModelFormatError, match="cannot open model file"):
        read_model(junk)
    with pytest.raises(InputError, match="no such file"):
        read_model(tmp_path / "absent.h5")


def test_write_is_atomic_on_failure(tmp_path, model_file):
    target = tmp_path / "keep.h5"
    shutil.copy(model_file, target)
    before = target.read_bytes()
    bad = _model()
    bad.labels = bad.labels[:-1]
    with pytest.raises(ModelFormatError, match="labels has shape"):
        write_model(target, bad)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.h5", "model.h5"]


def test_version_1_file_reads_with_the_documented_poisson_ratio(model_file):
    """A version-1 file has no Poisson ratio: reading gives every material 0.45 and says so."""
    import h5py

    from cutkit.io.model_h5 import V1_POISSON_RATIO

    with h5py.File(model_file, "r+") as f:
        f["cutkit"].attrs["schema_version"] = 1
        del f["cutkit/materials/poisson_ratio"]
        del f["cutkit/materials/J_c"]
        del f["cutkit/materials"].attrs["material_model"]
    m = read_model(model_file)
    assert V1_POISSON_RATIO == 0.45
    np.testing.assert_array_equal(m.materials["poisson_ratio"], [0.45, 0.45])
    assert m.materials.material_model == "neohookean"
    assert m.provenance["schema_upgrade"] == {"from_version": 1, "to_version": 3, "poisson_ratio": 0.45,
                                              "material_model": "neohookean", "J_c": 2000.0}


def test_version_2_file_reads_with_the_documented_J_c(model_file):
    """A version-2 file has no fracture toughness: reading gives every material V2_J_C and says so."""
    import h5py

    from cutkit.io.model_h5 import V2_J_C
    from cutkit.assign.defaults import DEFAULT_MATERIALS

    with h5py.File(model_file, "r+") as f:
        f["cutkit"].attrs["schema_version"] = 2
        del f["cutkit/materials/J_c"]
    m = read_model(model_file)
    assert V2_J_C == DEFAULT_MATERIALS["muscle"]["J_c"]
    np.testing.assert_array_equal(m.materials["J_c"], [V2_J_C, V2_J_C])
    assert m.provenance["schema_upgrade"] == {"from_version": 2, "to_version": 3, "J_c": V2_J_C}


def test_material_model_round_trips_and_a_bad_one_is_named(model_file, tmp_path):
    import dataclasses

    import h5py

    from cutkit.errors import ModelFormatError

    m = _model()
    write_model(tmp_path / "s.h5", dataclasses.replace(m, materials=dataclasses.replace(m.materials,
                                                                                      material_model="springs")))
    assert read_model(tmp_path / "s.h5").materials.material_model == "springs"
    with h5py.File(model_file, "r+") as f:
        f["cutkit/materials"].attrs["material_model"] = "jelly"
    with pytest.raises(ModelFormatError, match="material_model is 'jelly', not one of neohookean, springs"):
        read_model(model_file)
    with h5py.File(model_file, "r+") as f:
        f["cutkit/materials"].attrs["material_model"] = "springs"
        f["cutkit/materials/poisson_ratio"][0] = 0.5
    with pytest.raises(ModelFormatError, match="poisson_ratio has 0.5, outside"):
        read_model(model_file)


def test_schema_version_constant_is_written(model_file):
    with h5py.File(model_file) as f:
        assert int(f["cutkit"].attrs["schema_version"]) == SCHEMA_VERSION
        assert f["VTKHDF"].attrs["Type"] == b"UnstructuredGrid" or f["VTKHDF"].attrs["Type"] == "UnstructuredGrid"


def test_a_row_without_J_c_gets_the_same_default_as_an_older_file():
    from cutkit.io.model_h5 import V2_J_C
    from cutkit.model import MATERIAL_FIELDS, Materials

    row = {k: 1.0 for k in MATERIAL_FIELDS if k != "J_c"}
    m = Materials.from_rows([dict(label=1, name="m", **row)])
    assert m["J_c"][0] == V2_J_C == 2000.0
    with pytest.raises(KeyError):
        Materials.from_rows([dict(label=1, name="m", **{k: 1.0 for k in row if k != "E"})])
