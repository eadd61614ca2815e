"""Recipes are validated with one-line errors; assign applies materials, boundaries, prestress."""

from pathlib import Path

import numpy as np
import pytest

from cutkit.assign import DEFAULT_MATERIALS, assign, region_nodes
from cutkit.errors import InputError
from cutkit.mesh.generate import box_mesh
from cutkit.model import MATERIAL_FIELDS, TetModel
from cutkit.recipe import load_recipe

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def _write(tmp_path, text):
    path = tmp_path / "r.toml"
    path.write_text(text)
    return path


def test_knee_recipe_loads_and_resolves_paths():
    r = load_recipe(ROOT / "pipelines" / "knee.toml")
    assert r["recipe"]["volume"] == str(ROOT / "sample_volumes" / "knee_labels.nrrd")
    assert [m["name"] for m in r["materials"]] == ["skin", "fat", "muscle", "tendon", "bone"]
    assert len(r["_sha256"]) == 64


def test_mri_head_recipe_loads_and_its_image_ships_with_nibabel():
    """pipelines/mri_head.toml names no volume (the command line gives nibabel's T1 head test image,
    benchmarks/mri_head.py); one soft tissue, the base held, a lateral prestrain."""
    import nibabel

    from cutkit.volumes import read_volume

    r = load_recipe(ROOT / "pipelines" / "mri_head.toml")
    assert "volume" not in r["recipe"] and r["segment"]["otsu"] is True
    assert [m["name"] for m in r["materials"]] == ["muscle"] and r["prestress"][0]["prestrain"] == 0.05
    image = read_volume(Path(nibabel.__file__).parent / "tests" / "data" / "anatomical.nii")
    assert image.data.shape == (33, 41, 25) and np.allclose(image.spacing, 2.0)


@pytest.mark.parametrize(
    "text, message",
    [
        ("[segmnet]\nlabels = true\n", "unknown table [segmnet]"),
        ("[segment]\nthreshold = 'high'\n", "[segment]: threshold must be a list"),
        ("[segment]\nthreshold = [1, 2, 3]\n", "[segment] threshold must be [low] or [low, high]"),
        ("[isovolume]\nlevel = 'x'\n", "[isovolume]: level must be a number, not 'x'"),
        ("[[materials]]\nlabel = 1\nname = 'skin'\nE = -5\n", "[[materials]] #1: E must be a positive number, got -5"),
        ("[[materials]]\nlabel = 1\nname = 'skin'\nJ_c = -200\n", "[[materials]] #1: J_c must be a number >= 0, got -200"),
        ("[[materials]]\nlabel = 1\nname = 'a'\n[[materials]]\nlabel = 1\nname = 'b'\n", "[[materials]] #2 repeats label 1"),
        ("[[materials]]\nlabel = 1\nname = 'a'\nstiffness = 3\n", "unknown key 'stiffness'"),
        ("[[prestress]]\nlabel = 3\nfibre_direction = [0, 0]\nprestrain = 0.1\n", "fibre_direction must be a list of three numbers"),
        ("[[prestress]]\nlabel = 3\nfibre_direction = [0, 0, 1]\nprestrain = 0.9\n", "prestrain 0.9 is outside (-0.5, 0.5)"),
        ("[boundary]\n[[boundary.fixed_regions]]\naxis = 'w'\nside = 'min'\ndepth_mm = 1\n", "axis must be x, y or z"),
        ("[texture]\nregister = 'elastic'\n", "register must be 'none', 'rigid' or 'affine'"),
        ("this is = = not toml", "not a valid TOML recipe"),
    ],
)
def test_bad_recipes_get_one_line_errors(tmp_path, text, message):
    path = _write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_recipe(path)
    assert message in str(info.value)
    assert str(path) in str(info.value)
    assert "\n" not in str(info.value)


def _bar():
    points, tets = box_mesh((2, 2, 10), spacing=(1.0, 1.0, 1.0))
    centre = points[tets].mean(axis=1)
    labels = np.where(centre[:, 0] < 1.0, 3, 5).astype(np.int32)
    return TetModel.from_arrays(points, tets, labels)


def test_assign_materials_defaults_and_overrides():
    recipe = {"materials": [{"label": 3, "name": "muscle", "E": 12345.0}]}
    m = assign(_bar(), recipe)
    rows = {r["label"]: r for r in m.materials.rows()}
    assert rows[3]["E"] == 12345.0
    assert rows[3]["density"] == DEFAULT_MATERIALS["muscle"]["density"]
    assert rows[5]["name"] == "tissue_5"  # unnamed label: generic soft tissue
    assert set(rows[5]) == {"label", "name", *MATERIAL_FIELDS}


def test_recipe_sets_J_c_and_every_default_has_a_source():
    from cutkit.assign.defaults import DEFAULT_SOURCES

    m = assign(_bar(), {"materials": [{"label": 3, "name": "muscle", "J_c": 200.0}]})
    rows = {r["label"]: r for r in m.materials.rows()}
    assert rows[3]["J_c"] == 200.0
    assert rows[5]["J_c"] == DEFAULT_MATERIALS["muscle"]["J_c"]
    for tissue, row in DEFAULT_MATERIALS.items():
        assert set(DEFAULT_SOURCES[tissue]) == set(row)
        assert all(isinstance(v, str) and v for v in DEFAULT_SOURCES[tissue].values())
    # the published ranges the defaults sit in (J/m^2)
    # skin: the sharp-tool figure (needle insertion), not the tear tests' 17,100-30,400
    assert DEFAULT_MATERIALS["skin"]["J_c"] == 1_136 and "needle" in DEFAULT_SOURCES["skin"]["J_c"]
    assert 550 <= DEFAULT_MATERIALS["muscle"]["J_c"] <= 8_000


def test_assign_fixes_bone_and_leg_ends():
    model = _bar()
    recipe = {
        "boundary": {
            "fixed_labels": [5],
            "fixed_regions": [{"axis": "z", "side": "min", "depth_mm": 0.5}, {"axis": "z", "side": "max", "depth_mm": 0.5}],
        }
    }
    m = assign(model, recipe)
    fixed = set(m.boundary.fixed_nodes.tolist())
    bone_nodes = set(np.unique(model.tets[model.labels == 5]).tolist())
    ends = set(np.flatnonzero((model.points[:, 2] == 0) | (model.points[:, 2] == 10)).tolist())
    assert fixed == bone_nodes | ends


def test_region_nodes_box_and_prescribed():
    model = _bar()
    nodes = region_nodes(model.points, {"box_min": [0, 0, 4.5], "box_max": [2, 2, 5.5]})
    assert sorted(nodes.tolist()) == np.flatnonzero(model.points[:, 2] == 5).tolist()
    recipe = {"boundary": {"prescribed": [{"box_min": [0, 0, 4.5], "box_max": [2, 2, 5.5], "displacement_mm": [0, 1, 0]}]}}
    m = assign(model, recipe)
    assert m.boundary.prescribed_nodes.tolist() == sorted(nodes.tolist())
    np.testing.assert_array_equal(m.boundary.prescribed_displacement, np.tile([0.0, 1.0, 0.0], (nodes.size, 1)))


def test_region_selecting_nothing_is_an_error():
    recipe = {"boundary": {"fixed_regions": [{"box_min": [50, 50, 50], "box_max": [60, 60, 60]}]}}
    with pytest.raises(InputError, match="fixed_regions #1 selects no node"):
        assign(_bar(), recipe)


def test_prestress_direction_is_normalised():
    recipe = {"prestress": [{"label": 3, "fibre_direction": [0, 0, 2], "prestrain": 0.05}]}
    m = assign(_bar(), recipe)
    np.testing.assert_allclose(m.prestress.fibre_direction, [[0, 0, 1]])
    assert m.prestress.prestrain.tolist() == [0.05]
