"""``cutkit export``: the deformed configuration with every array each format can carry, in every
meshio format that takes tetrahedra."""

import contextlib
import io

import meshio
import numpy as np
import pytest
from click.testing import CliRunner

from cutkit.cli.main import cli
from cutkit.errors import InputError
from cutkit.io.meshes import DATA_FORMATS, GEOMETRY_ONLY, LABEL_ONLY, REFUSED, export_mesh
from cutkit.io.model_h5 import write_model
from cutkit.mesh.generate import box_mesh
from cutkit.model import MATERIAL_FIELDS, BoundaryConditions, Materials, TetModel, Texture


def _model():
    points, tets = box_mesh((3, 2, 2), spacing=(1.0, 1.5, 2.0), origin=(-1.0, 2.0, 3.0))
    labels = np.where(points[tets].mean(axis=1)[:, 0] < 0.5, 1, 2).astype(np.int32)
    rows = [dict(label=1, name="fat", **{k: 1.0 + i for i, k in enumerate(MATERIAL_FIELDS)}),
            dict(label=2, name="muscle", **{k: 10.0 + i for i, k in enumerate(MATERIAL_FIELDS)})]
    for row in rows:
        if "poisson_ratio" in row:
            row["poisson_ratio"] = 0.3
    rng = np.random.default_rng(0)
    texture = Texture(volume=rng.integers(0, 256, (5, 4, 6, 3), dtype=np.uint8),
                      spacing=np.array([1.0, 1.5, 2.0]), origin=np.array([-1.0, 2.0, 3.0]))
    return TetModel.from_arrays(
        points, tets, labels, materials=Materials.from_rows(rows),
        boundary=BoundaryConditions(fixed_nodes=np.array([0, 1, 2]), prescribed_nodes=np.array([5]),
                                    prescribed_displacement=np.array([[0.0, 0.0, 1.0]])),
        texture=texture, texcoords=texture.index_to_texcoord(texture.world_to_index(points)),
        cell_data={"new_tet": np.zeros(len(tets), np.uint8)},
        point_data={"displacement": rng.normal(scale=0.1, size=(len(points), 3))},
    )


#: One file ending per meshio format that takes tetrahedra (and the reader's name, where it differs).
ENDINGS = {
    "vtu": ".vtu", "vtk": ".vtk", "xdmf": ".xdmf", "gmsh22": ".msh", "hmf": ".hmf", "med": ".med",
    "tecplot": ".dat", "avsucd": ".avs", "medit": ".mesh", "netgen": ".vol", "su2": ".su2",
    "abaqus": ".inp", "ansys": None, "cgns": ".cgns", "flac3d": ".f3grid", "mdpa": ".mdpa", "nastran": ".bdf",
    "permas": ".post", "tetgen": ".ele", "ugrid": ".ugrid", "h5m": ".h5m", "exodus": ".e", "dolfin-xml": ".xml",
}


def test_the_table_names_every_tet_format():
    assert set(DATA_FORMATS) | set(LABEL_ONLY) | set(GEOMETRY_ONLY) | set(REFUSED) == set(ENDINGS)


def _read(path, fmt):
    sink = io.StringIO()
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        return meshio.read(path, file_format="gmsh" if fmt == "gmsh22" else fmt)


@pytest.mark.parametrize("fmt", sorted(f for f, e in ENDINGS.items() if e and f not in REFUSED))
def test_every_format_gets_the_deformed_mesh_and_what_it_can_carry(tmp_path, fmt):
    m = _model()
    path = tmp_path / f"out{ENDINGS[fmt]}"
    done = export_mesh(m, path)
    assert done["format"] == fmt and done["configuration"] == "deformed"
    assert path.exists() and path.stat().st_size > 0
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left
    if fmt == "ugrid":  # meshio writes it but cannot read it back
        return
    back = _read(path, fmt)
    deformed = m.points + m.point_data["displacement"]
    np.testing.assert_allclose(back.points, deformed, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(np.concatenate([c.data for c in back.cells if c.type == "tetra"]), m.tets)
    if fmt in DATA_FORMATS:
        pd = {k.removesuffix("_0"): v for k, v in back.point_data.items()}  # Tecplot splits vectors
        for name in ("displacement", "fixed", "prescribed", "texcoords", "rgb"):
            assert name in pd, (name, sorted(back.point_data))
        np.testing.assert_array_equal(np.asarray(pd["fixed"]).ravel(), [1, 1, 1] + [0] * (m.n_points - 3))
        if fmt != "tecplot":
            np.testing.assert_allclose(back.point_data["displacement"], m.point_data["displacement"], atol=1e-5)
        label_key = "avsucd:material" if fmt == "avsucd" else "label"  # AVS takes the first integer array
        for name in (label_key, "material", "new_tet", "E", "density"):
            assert name in back.cell_data, (name, sorted(back.cell_data))
        np.testing.assert_array_equal(np.concatenate(back.cell_data[label_key]).ravel(), m.labels)
        e = np.where(m.labels == 1, 1.0, 10.0)  # E is the first material column: 1 and 10
        np.testing.assert_allclose(np.concatenate(back.cell_data["E"]).ravel(), e)
    elif fmt in LABEL_ONLY:
        np.testing.assert_array_equal(np.concatenate(back.cell_data[LABEL_ONLY[fmt]]).ravel(), m.labels)


def test_rest_configuration_on_request(tmp_path):
    m = _model()
    assert export_mesh(m, tmp_path / "r.vtu", rest=True)["configuration"] == "rest"
    back = meshio.read(tmp_path / "r.vtu")
    np.testing.assert_array_equal(back.points, m.points)
    np.testing.assert_array_equal(back.point_data["displacement"], m.point_data["displacement"])


@pytest.mark.parametrize("fmt", sorted(REFUSED))
def test_refused_formats_say_why(tmp_path, fmt):
    with pytest.raises(InputError, match=r"^cannot export to .*: meshio's"):
        export_mesh(_model(), tmp_path / f"out{ENDINGS[fmt]}")


def test_cli_export_of_a_textured_model(tmp_path):
    write_model(tmp_path / "m.h5", _model())
    for ext in (".xdmf", ".mesh", ".vtu"):
        r = CliRunner().invoke(cli, ["export", str(tmp_path / "m.h5"), str(tmp_path / f"o{ext}")])
        assert r.exit_code == 0, r.output
        assert "deformed configuration" in r.output
    r = CliRunner().invoke(cli, ["export", str(tmp_path / "m.h5"), str(tmp_path / "o.inp")])
    assert "the abaqus format carries no data arrays" in " ".join(r.output.split())
