"""import / check / export / info commands and the meshio import-export layer."""

import meshio
import numpy as np
import pytest
from click.testing import CliRunner

from _meshes_check import conforming_mesh, hanging_mesh
from cutkit.cli.main import cli
from cutkit.errors import InputError, MeshError
from cutkit.io.meshes import export_mesh, import_mesh
from cutkit.model.tetmodel import TetModel


def write_mesh(path, points, tets, labels=None, flip=()):
    tets = np.array(tets)
    for i in flip:
        tets[i, [2, 3]] = tets[i, [3, 2]]
    cd = {} if labels is None else {"gmsh:physical": [labels], "gmsh:geometrical": [labels]}
    meshio.write(path, meshio.Mesh(points, [("tetra", tets)], cell_data=cd), file_format="gmsh22")


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_import_check_conforming_passes(tmp_path):
    p, t = conforming_mesh()
    lab = np.array([3] * 6 + [7] * 6)
    write_mesh(tmp_path / "m.msh", p, t, lab, flip=[1, 4])
    r = run("import", tmp_path / "m.msh", "-o", tmp_path / "m.h5")
    assert r.exit_code == 0, r.output
    assert "fixed orientation of 2 negatively oriented tets" in r.output
    r = run("check", tmp_path / "m.h5")
    assert r.exit_code == 0, r.output
    assert "checks passed" in r.output
    assert "│ ok" in r.output and "[green]" not in r.output  # a result cell, not its markup
    r = run("info", tmp_path / "m.h5")
    assert r.exit_code == 0, r.output
    assert "12 nodes, 12 tets, total volume 2 mm^3" in r.output
    assert "(schema version" in r.output


def test_hanging_node_fails_and_is_named(tmp_path):
    p, t = hanging_mesh()
    write_mesh(tmp_path / "h.msh", p, t)
    assert run("import", tmp_path / "h.msh", "-o", tmp_path / "h.h5").exit_code == 0
    r = run("check", tmp_path / "h.h5")
    assert r.exit_code == 1
    centre = int(np.flatnonzero(np.all(p == [1.0, 0.5, 0.5], axis=1))[0])
    assert "hanging nodes" in r.output and str(centre) in r.output
    assert "failed:" in r.output and "no hanging node (conforming)" in r.output
    assert "│ FAIL" in r.output and "[red]FAIL" not in r.output


@pytest.mark.parametrize("ext", [".vtu", ".vtk", ".msh", ".xdmf"])
def test_round_trip_exact(tmp_path, ext):
    rng = np.random.default_rng(1)
    p, t = conforming_mesh()
    p = p + rng.normal(scale=1e-3, size=p.shape)  # non-round coordinates
    lab = rng.integers(1, 5, len(t)).astype(np.int32)
    write_mesh(tmp_path / "src.msh", p, t, lab)
    m = import_mesh(tmp_path / "src.msh")
    np.testing.assert_array_equal(m.points, p)
    export_mesh(m, tmp_path / f"out{ext}")
    back = import_mesh(tmp_path / f"out{ext}")
    np.testing.assert_array_equal(back.points, m.points)
    np.testing.assert_array_equal(back.tets, m.tets)
    np.testing.assert_array_equal(back.labels, lab)
    assert back.provenance["import"]["flipped_tets"] == 0
    assert [f.name for f in tmp_path.iterdir() if f.name.startswith(".")] == []  # no temp file left


def test_export_cli_and_labels_default(tmp_path):
    p, t = conforming_mesh()
    meshio.write(tmp_path / "a.vtu", meshio.Mesh(p, [("tetra", t)]))
    m = import_mesh(tmp_path / "a.vtu")
    assert m.labels.dtype == np.int32 and np.all(m.labels == 1)
    assert run("import", tmp_path / "a.vtu", "-o", tmp_path / "a.h5").exit_code == 0
    r = run("export", tmp_path / "a.h5", tmp_path / "b.vtk")
    assert r.exit_code == 0, r.output
    np.testing.assert_array_equal(meshio.read(tmp_path / "b.vtk").cells_dict["tetra"], t)


def test_bad_inputs_one_line(tmp_path):
    r = run("import", tmp_path / "missing.msh", "-o", tmp_path / "x.h5")
    assert r.exit_code == 2
    assert r.output.strip() == f"cutkit: error: {tmp_path / 'missing.msh'}: no such file"
    (tmp_path / "bad.vtu").write_text("<VTKFile garbage")
    with pytest.raises(InputError, match=r"^cannot read mesh .*bad\.vtu: "):
        import_mesh(tmp_path / "bad.vtu")
    r = run("import", tmp_path / "bad.vtu", "-o", tmp_path / "x.h5")
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1
    meshio.write(tmp_path / "tri.vtu", meshio.Mesh(np.eye(3), [("triangle", [[0, 1, 2]])]))
    with pytest.raises(MeshError, match=r"tri\.vtu contains no tetrahedra \(cell types: triangle\)$"):
        import_mesh(tmp_path / "tri.vtu")
    p, t = conforming_mesh()
    p[3] = np.nan
    meshio.write(tmp_path / "nan.vtu", meshio.Mesh(p, [("tetra", t)]))
    with pytest.raises(MeshError, match=r"nan\.vtu: node 3 has a non-finite coordinate \(1 such nodes\)$"):
        import_mesh(tmp_path / "nan.vtu")
    m = TetModel.from_arrays(*conforming_mesh())
    with pytest.raises(InputError, match=r"unknown mesh file extension '\.xyz'"):
        export_mesh(m, tmp_path / "o.xyz")
    assert not (tmp_path / "o.xyz").exists()
    r = run("info", tmp_path / "nope.h5")
    assert r.exit_code == 2 and "no such file" in r.output


@pytest.mark.parametrize("fmt,name,readname", [("tetgen", "c.node", "c.ele"), ("medit", "c.mesh", "c.mesh")])
def test_import_tetgen_and_medit(tmp_path, fmt, name, readname):
    p, t = conforming_mesh()
    lab = np.arange(len(t), dtype=np.int32) % 3 + 1
    cd = {"medit:ref": [lab]} if fmt == "medit" else {}
    meshio.write(tmp_path / name, meshio.Mesh(p, [("tetra", t)], cell_data=cd), file_format=fmt)
    m = import_mesh(tmp_path / readname)
    np.testing.assert_allclose(m.points, p)
    np.testing.assert_array_equal(m.tets, t)
    np.testing.assert_array_equal(m.labels, lab if fmt == "medit" else 1)
