"""The README's commands and its Python example run as written."""

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _blocks(lang):
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def test_ci_runs_the_readme_test_command():
    test_command = _blocks("bash")[1].strip()
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    assert ci == test_command
    assert ".venv/bin/ruff check . && .venv/bin/python -m pytest -q" in ci


def test_lint_and_markers_are_configured():
    text = (ROOT / "pyproject.toml").read_text()
    assert "[tool.ruff.lint]" in text and '"ruff' in text
    assert 'markers = ["slow:' in text


@pytest.mark.slow
def test_python_example_runs(tmp_path, monkeypatch):
    from cutkit.assign.defaults import DEFAULT_MATERIALS
    from cutkit.io.model_h5 import write_model
    from cutkit.mesh.generate import box_mesh
    from cutkit.model.tetmodel import BoundaryConditions, Materials, TetModel

    (code,) = _blocks("python")
    # a slab where the example cuts the knee: skin at y = 5, x 0..80, z 60..100 mm
    points, tets = box_mesh((20, 4, 10), spacing=(4.0, 4.0, 4.0), origin=(0.0, 5.0, 60.0))
    ends = np.flatnonzero((points[:, 2] == 60.0) | (points[:, 2] == 100.0))
    row = dict(label=1, name="muscle", **DEFAULT_MATERIALS["muscle"])
    (tmp_path / "cutkit-demo").mkdir()
    write_model(tmp_path / "cutkit-demo" / "knee.h5",
                TetModel.from_arrays(points, tets, materials=Materials.from_rows([row]),
                                     boundary=BoundaryConditions(fixed_nodes=ends)))
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    assert (tmp_path / "my-cut" / "summary.json").is_file()
    assert (tmp_path / "my-cut" / "cut.mp4").stat().st_size > 1000
    assert list((tmp_path / "my-cut" / "pictures").glob("*_cut.png"))
