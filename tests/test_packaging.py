"""Install layout: one import name, ``cli/`` and ``pipelines/`` under it, a ``cutkit`` command."""

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import cutkit

ROOT = Path(__file__).resolve().parents[1]


def test_cli_and_pipelines_are_subpackages_of_cutkit():
    import cutkit.cli.main
    import cutkit.pipelines

    assert Path(cutkit.cli.main.__file__).parent == ROOT / "cli"
    assert Path(cutkit.pipelines.__file__).parent == ROOT / "pipelines"


@pytest.mark.slow
def test_wheel_holds_only_the_cutkit_import_name(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q", "-w", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        pytest.skip(f"cannot build a wheel here: {proc.stderr.strip().splitlines()[-1:]}")
    (wheel,) = tmp_path.glob("cutkit-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top = {n.split("/")[0] for n in names}
    assert top == {"cutkit", f"cutkit-{cutkit.__version__}.dist-info"}
    assert "cutkit/cli/main.py" in names
    assert "cutkit/pipelines/__init__.py" in names
    assert any(n.startswith("cutkit/pipelines/") and n.endswith(".toml") for n in names)
    entry = next(n for n in names if n.endswith("entry_points.txt"))
    assert "cutkit = cutkit.cli.main:main" in zipfile.ZipFile(wheel).read(entry).decode()
