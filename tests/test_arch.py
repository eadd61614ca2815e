"""The architecture check (tools/arch_check.py): the code matches its baseline, and each kind of violation is caught."""

import importlib.util
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load():
    spec = importlib.util.spec_from_file_location("arch_check", ROOT / "tools" / "arch_check.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["arch_check"] = mod  # dataclasses look their module up while the class is made
    spec.loader.exec_module(mod)
    return mod


arch = _load()


def test_the_code_matches_the_baseline(capsys):
    """No violation outside tools/arch_baseline.txt, and no line there that no longer occurs."""
    found = arch.check(ROOT)
    new, gone = arch.compare(found, arch.read_baseline(arch.BASELINE))
    assert not new, "new architecture violations:\n" + "\n".join(f"{v.file}:{v.line}: {v.kind}: {v.message}"
                                                                 for v in new)
    assert not gone, "fixed, remove from tools/arch_baseline.txt:\n" + "\n".join(gone)
    assert arch.main([]) == 0
    assert "private-import" in capsys.readouterr().out  # the counts per kind are printed


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))


LONG_BODY = "".join(f"    v{i} = {i}\n" for i in range(85))


#: The synthetic package's cutting (``cut``) and physics (``phys``), which meet in ``meet``.
APART = {"cut": {"phys"}, "phys": {"cut"}, "meet": {"cut", "phys"}}


@pytest.fixture
def synthetic(tmp_path):
    """A small package with one violation of each kind (and allowed look-alikes)."""
    _write(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a/__init__.py": "",
        "pkg/a/_priv.py": "def x():\n    return 1\n",
        "pkg/a/mod.py": """
            from pkg.a._priv import x  # private module of its own subpackage: allowed


            def _y():
                return x()
        """,
        "pkg/build/__init__.py": "",
        "pkg/build/thing.py": "VALUE = 1\n",
        "pkg/run/__init__.py": "",
        "pkg/run/user.py": """
            import pkg.build.thing
            from pkg.a._priv import x
            from pkg.a.mod import _y
            from pkg.a import mod as M


            class Holder:
                def set(self, obj):
                    self._own = 1  # its own attribute: allowed
                    obj._other = 2
                    obj._arr[0] = 3


            def uses():
                return M._y(), x(), _y(), pkg.build.thing.VALUE
        """,
        "pkg/run/c1.py": """
            def later():
                from pkg.run import c2  # a function-local import still makes the cycle
                return c2
        """,
        "pkg/run/c2.py": "from pkg.run import c1\n",
        "pkg/cut/__init__.py": "",
        "pkg/cut/step.py": "from pkg.meet import delta  # the meeting place: allowed\nfrom pkg.phys import model\n",
        "pkg/phys/__init__.py": "",
        "pkg/phys/model.py": "from pkg.meet import delta\n",
        "pkg/meet/__init__.py": "",
        "pkg/meet/delta.py": "VALUE = 1\n",
        "pkg/run/long.py": "def long_one():\n" + LONG_BODY + "    return 0\n",
        "pkg/build/long.py": "def long_but_build_side():\n" + LONG_BODY + "    return 0\n",
        "pkg/build/kern.py": """
            from numba import njit
            import numba


            @njit(cache=True)
            def wide(a, b, c, d, e, f, g, h, i, j):
                return a


            @numba.jit(nopython=True)
            def also_wide(a, b, c, d, e, f, g, h, i, j, k):
                return a


            @njit(cache=True)
            def nine(a, b, c, d, e, f, g, h, i):
                return a


            @njit(cache=True, inline="always")
            def inlined_arithmetic(a, b, c, d, e, f, g, h, i, j):
                return a


            def plain_python(a, b, c, d, e, f, g, h, i, j):
                return a
        """,
    })
    return tmp_path


def test_each_kind_of_violation_is_reported(synthetic):
    found = arch.check(synthetic, packages={"pkg": "pkg"}, run_side={"run"}, build_side={"build"}, apart=APART)
    entries = {v.entry for v in found}
    assert entries == {
        "private-import pkg/run/user.py -> pkg.a._priv.x",
        "private-import pkg/run/user.py -> pkg.a.mod._y",
        "private-read pkg/run/user.py::M._y",
        "private-write pkg/run/user.py::Holder.set::obj._other",
        "private-write pkg/run/user.py::Holder.set::obj._arr",
        "cycle pkg.run.c1 | pkg.run.c2",
        "run-imports-build pkg/run/user.py -> pkg.build.thing",
        "cutting-meets-physics pkg/cut/step.py -> pkg.phys.model",
        "long-function pkg/run/long.py::long_one",
        "kernel-arguments pkg/build/kern.py::wide",
        "kernel-arguments pkg/build/kern.py::also_wide",
    }
    by_entry = {v.entry: v for v in found}
    assert by_entry["private-import pkg/run/user.py -> pkg.a._priv.x"].line == 3  # file:line of the import
    assert by_entry["long-function pkg/run/long.py::long_one"].line == 1
    assert arch.counts(found) == {"private-import": 2, "private-read": 1, "private-write": 2, "cycle": 1,
                                  "run-imports-build": 1, "cutting-meets-physics": 1, "long-function": 1,
                                  "kernel-arguments": 2}


def test_a_new_violation_or_a_fixed_baseline_line_fails(synthetic):
    found = arch.check(synthetic, packages={"pkg": "pkg"}, run_side={"run"}, build_side={"build"}, apart=APART)
    baseline = sorted(v.entry for v in found)
    assert arch.compare(found, baseline) == ([], [])
    new, gone = arch.compare(found, baseline[1:])  # a violation the baseline does not know
    assert [v.entry for v in new] == baseline[:1] and gone == []
    new, gone = arch.compare(found, baseline + ["cycle pkg.x | pkg.y"])  # a baseline line now fixed
    assert new == [] and gone == ["cycle pkg.x | pkg.y"]


def test_the_baseline_file_round_trips(synthetic, tmp_path):
    found = arch.check(synthetic, packages={"pkg": "pkg"}, run_side={"run"}, build_side={"build"}, apart=APART)
    path = tmp_path / "baseline.txt"
    arch.write_baseline(path, found)
    assert arch.read_baseline(path) == [v.entry for v in found]
