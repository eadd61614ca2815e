"""Structs (namedtuples of arrays) in parallel numba kernels: the way cutkit's kernels write through
them lands, and no parallel kernel writes the way that does not.

With numba 0.68 a ``prange`` loop loses writes made through a struct's field inside the loop
(``s.a[i] = x``) and through names unpacked from a tuple argument (``a, b = s``); writes through
names taken from the fields before the loop (``a = s.a`` or ``a, b = s.a, s.b``) or by index
(``a = s[0]``) land.  The parallel kernels that take structs (``relax._kernels.relax_nodes``,
``relax._volume_kernels.add_volume_forces``, ``isovolume._kernels.count_pieces`` and
``fill_pieces``) use only the latter.
"""

import ast
from collections import namedtuple
from pathlib import Path

import numpy as np
from numba import njit, prange

ROOT = Path(__file__).resolve().parents[1]
Pair = namedtuple("Pair", ["a", "b"])


@njit(parallel=True)
def _by_field_names(s, n):
    a = s.a
    b = s.b
    for i in prange(n):
        a[i] = i
        b[i] = 2 * i


@njit(parallel=True)
def _by_field_tuple(s, n):
    a, b = s.a, s.b
    for i in prange(n):
        a[i] = i
        b[i] = 2 * i


@njit(parallel=True)
def _by_index(s, n):
    a = s[0]
    b = s[1]
    for i in prange(n):
        a[i] = i
        b[i] = 2 * i


def test_writes_through_names_taken_before_the_loop_land():
    for kernel, make in ((_by_field_names, Pair), (_by_field_tuple, Pair), (_by_index, lambda x, y: (x, y))):
        x, y = np.zeros(1000, np.int64), np.zeros(1000, np.int64)
        kernel(make(x, y), 1000)
        assert np.array_equal(x, np.arange(1000)) and np.array_equal(y, 2 * np.arange(1000)), kernel


def _parallel_kernels():
    for path in sorted((ROOT / "cutkit").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for fn in ast.walk(tree):
            if isinstance(fn, ast.FunctionDef) and any(
                    isinstance(d, ast.Call) and any(k.arg == "parallel" and ast.unparse(k.value) == "True"
                                                    for k in d.keywords) for d in fn.decorator_list):
                yield path.relative_to(ROOT), fn


def _lost_writes(fn):
    """Writes the parfors lose: ``x.attr[...] = `` inside a prange, and unpacking a parameter."""
    params = {a.arg for a in fn.args.args}
    found = []
    for node in ast.walk(fn):
        if isinstance(node, ast.For) and isinstance(node.iter, ast.Call) and ast.unparse(node.iter.func) == "prange":
            for inner in ast.walk(node):
                targets = inner.targets if isinstance(inner, ast.Assign) else (
                    [inner.target] if isinstance(inner, ast.AugAssign) else [])
                for t in targets:
                    if isinstance(t, ast.Subscript) and isinstance(t.value, ast.Attribute):
                        found.append(ast.unparse(t))
        if (isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Tuple)
                and isinstance(node.value, ast.Name) and node.value.id in params):
            found.append(ast.unparse(node))
    return found


def test_no_parallel_kernel_writes_the_way_numba_loses():
    kernels = list(_parallel_kernels())
    assert len(kernels) > 20  # the scan finds them
    bad = {f"{path}::{fn.name}": w for path, fn in kernels if (w := _lost_writes(fn))}
    assert bad == {}


def test_the_scan_sees_both_kinds_of_lost_write():
    src = '''
@njit(parallel=True)
def k(s, n):
    a, b = s
    for i in prange(n):
        s.a[i] = i
'''
    fn = ast.parse(src).body[0]
    assert sorted(_lost_writes(fn)) == ["a, b = s", "s.a[i]"]
