"""Sweep specs: runs of a product and explicit lists, content keys, and one-line errors naming the key."""

import pytest

from cutkit.cli.main import main
from cutkit.errors import InputError
from cutkit.sweep import load_spec, model_hash, slab_model
from cutkit.sweep.worker import simulate_options, with_materials

BASE = """
[options]
material_model = "springs"
hold_s = 0.2

[[models]]
name = "slab"
slab = { shape = [4, 3, 4] }

[[trajectories]]
name = "gen"
incision = { start = [1.0, -1.0, 4.1], end = [7.0, -1.0, 4.1], depth = 2.0 }
"""


def spec_file(tmp_path, extra="", base=BASE):
    p = tmp_path / "s.toml"
    p.write_text(base + extra)
    return p


def test_product_and_explicit_runs(tmp_path):
    spec = load_spec(spec_file(tmp_path, """
[product]
material.muscle.F_enter = [0.5, 1.0, 1.5]
incision.depth = [2.0, 3.0]

[[runs]]
option.hold_s = 0.4
material.1.E = 5000.0
"""))
    assert len(spec.runs) == 7
    assert spec.param_names == ["material.muscle.F_enter", "incision.depth", "option.hold_s", "material.1.E"]
    assert spec.runs[0].params == {"material.muscle.F_enter": 0.5, "incision.depth": 2.0}
    assert spec.runs[-1].params == {"option.hold_s": 0.4, "material.1.E": 5000.0}
    assert spec.options == {"frames": False, "write_model": False, "png": False, "material_model": "springs",
                            "hold_s": 0.2}
    spec.resolve()
    keys = [r.key for r in spec.runs]
    assert len(set(keys)) == 7 and all(len(k) == 16 for k in keys)
    again = load_spec(spec_file(tmp_path, "\n[product]\nincision.depth = [3.0, 2.0]\n"
                                          "material.muscle.F_enter = [1.0, 0.5, 1.5]\n"))
    again.resolve()
    assert {r.key for r in again.runs} == set(keys[:6])  # same runs, same keys, whatever the order


def test_without_product_every_model_with_every_trajectory(tmp_path):
    spec = load_spec(spec_file(tmp_path, '\n[[trajectories]]\nname = "file"\nfile = "cut.csv"\n'))
    assert [(r.model, r.trajectory, r.params) for r in spec.runs] == [("slab", "gen", {}), ("slab", "file", {})]


def test_model_hash_is_of_the_content():
    a, b = slab_model((4, 3, 4)), slab_model((4, 3, 4))
    assert model_hash(a) == model_hash(b)
    b.provenance["note"] = "another file name"
    assert model_hash(a) == model_hash(b)
    assert model_hash(a) != model_hash(slab_model((4, 3, 4), prestrain=0.1))
    changed = with_materials(a, {"material.muscle.E": 1234.0})
    assert model_hash(changed) != model_hash(a)
    assert a.materials["E"][0] != 1234.0 and changed.materials["E"][0] == 1234.0  # the shared model is untouched


@pytest.mark.parametrize("extra, message", [
    ("\n[sweeep]\n", "s.toml: sweeep: unknown table (known: sweep, options, models, trajectories, product, runs)"),
    ("\n[sweep]\nretries = -1\n", "s.toml: sweep.retries: must be >= 0, got -1"),
    ("\n[product]\nmaterial.muscle.F_enter = 0.5\n",
     "s.toml: product.material.muscle.F_enter: must be a non-empty list of values, got 0.5"),
    ("\n[product]\nmaterial.muscle.F_enter = ['a']\n",
     "s.toml: product.material.muscle.F_enter: must be a number, got 'a'"),
    ("\n[product]\nmaterials.muscle.E = [1.0]\n",
     "s.toml: product.materials.muscle.E: unknown parameter (names start with material., option., incision.)"),
    ("\n[product]\noption.hold = [1.0]\n", "s.toml: product.option.hold: unknown simulate option (known: "),
    ("\n[product]\nincision.dept = [1.0]\n", "s.toml: product.incision.dept: unknown incision parameter (known: "),
    ("\n[product]\nmodels = ['knee']\n", "s.toml: product.models: no model named 'knee' (known: slab)"),
    ("\n[[runs]]\ntrajectory = 'along'\n",
     "s.toml: runs[0].trajectory: must name one of the trajectories (gen), got 'along'"),
])
def test_bad_spec_is_one_line_naming_the_key(tmp_path, extra, message):
    with pytest.raises(InputError) as err:
        load_spec(spec_file(tmp_path, extra))
    assert str(err.value).startswith(message)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("extra, message", [
    ("\n[product]\nmaterial.bone.E = [1.0]\n",
     "s.toml: material.bone.E: model 'slab' has no label 'bone' (its labels: 1 (muscle))"),
    ("\n[product]\nmaterial.muscle.F_entr = [1.0]\n",
     "s.toml: material.muscle.F_entr: unknown material field 'F_entr' (known: E, "),
])
def test_labels_and_fields_are_checked_against_the_model(tmp_path, extra, message):
    spec = load_spec(spec_file(tmp_path, extra))
    with pytest.raises(InputError) as err:
        spec.resolve()
    assert str(err.value).startswith(message)


def test_run_values_are_checked_by_the_run():
    with pytest.raises(InputError, match=r"^material.muscle.F_enter: must be >= 0, got -1$"):
        with_materials(slab_model((2, 2, 2)), {"material.muscle.F_enter": -1})
    with pytest.raises(InputError, match="hold-s must be a number >= 0, got -1"):
        simulate_options({"frames": False}, {"option.hold_s": -1.0})


def test_cli_bad_spec_is_one_line(tmp_path, capsys):
    path = spec_file(tmp_path, "\n[product]\noption.hold = [1.0]\n")
    assert main(["sweep", str(path), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cutkit: error: s.toml: product.option.hold: unknown simulate option")
    assert not (tmp_path / "out").exists()
