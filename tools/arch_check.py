"""Architecture check of cutkit: reads the source (no imports) and reports what breaks the layering.

Kinds of violation (each reported with file:line and a stable key):

``private-import``
    A module imports a private module or name (a path component or a name
    with a leading underscore) of another top-level subpackage, e.g.
    ``from cutkit.mesh._quality_kernels import x`` or
    ``from cutkit.relax.topology import _helper`` in ``cutkit.simulate``.
    Private modules within one subpackage are that subpackage's business.
``private-read``
    ``alias._name`` where ``alias`` is a module of another subpackage bound
    by an import (``from cutkit.mesh import quality as Q; Q._check``).
``private-write``
    An assignment to ``x._name`` (or to ``x._name[...]``) where ``x`` is not
    ``self`` or ``cls``: a write into another object's internals (the checker cannot tell the
    type of ``x``, so every such write counts).
``cycle``
    A cycle of imports between modules, function-local imports included;
    each strongly connected component is reported once, by its members.
``run-imports-build``
    A run-side module (:data:`RUN_SIDE`) imports a build-side one
    (:data:`BUILD_SIDE`).
``cutting-meets-physics``
    A module imports a subpackage it must stay apart from (:data:`APART`):
    the cutting and the physics never import each other, and the tissue
    store and change message through which they meet import neither.
``long-function``
    A function or method of the run side over :data:`MAX_FUNCTION_LINES`
    lines (``def`` line to last line, decorators not counted).
``kernel-arguments``
    A numba kernel (``@njit`` / ``@jit``, either side) with more than
    :data:`MAX_KERNEL_ARGUMENTS` parameters: pass structs (namedtuples of
    arrays) instead.  Helpers compiled into their caller
    (``inline="always"``: scalar arithmetic) are not kernels.

Known violations are listed in ``tools/arch_baseline.txt`` (one ``kind key``
per line); the check fails on a violation not listed there and on a listed
one that no longer occurs, so the list only shrinks.

Usage::

    python tools/arch_check.py                  # check against the baseline
    python tools/arch_check.py --all            # list every violation with file:line
    python tools/arch_check.py --write-baseline # rewrite the baseline from the code
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Import name -> source folder (relative to the repository root), as in pyproject.toml's package-dir.
PACKAGES = {"cutkit": "cutkit", "cutkit.cli": "cli"}
#: Top-level subpackages of the run side (the runtime: contact, cutting, physics, session).
RUN_SIDE = frozenset({"collision", "cutting", "relax", "scalpel", "haptics", "simulate", "live", "tissue"})
#: Top-level subpackages and modules of the build side (volume to model).
BUILD_SIDE = frozenset({"isovolume", "decimate", "segment", "texture", "assign", "volumes", "build", "recipe"})
#: Longest function allowed on the run side, in lines.
MAX_FUNCTION_LINES = 80
#: Most parameters a numba kernel may take.
MAX_KERNEL_ARGUMENTS = 9
BASELINE = ROOT / "tools" / "arch_baseline.txt"
#: Subpackage -> the subpackages it must not import: the cutting writes the tissue store, the physics
#: (``relax``) reads it, and they meet only through ``cutkit.tissue`` (store, change message, protocol).
APART = {"cutting": frozenset({"relax"}), "relax": frozenset({"cutting"}),
         "tissue": frozenset({"cutting", "relax"})}
KINDS = ("private-import", "private-read", "private-write", "cycle", "run-imports-build", "cutting-meets-physics",
         "long-function", "kernel-arguments")


@dataclass(frozen=True)
class Violation:
    """One finding: ``kind`` and a ``key`` without line numbers (the baseline's line), and where it is."""

    kind: str
    key: str
    file: str
    line: int
    message: str

    @property
    def entry(self) -> str:
        return f"{self.kind} {self.key}"


@dataclass
class Module:
    name: str
    path: Path
    rel: str  # path relative to the root, with forward slashes
    is_package: bool
    tree: ast.Module


def _private(part: str) -> bool:
    return part.startswith("_") and not (part.startswith("__") and part.endswith("__"))


def find_modules(root: Path, packages: dict[str, str]) -> dict[str, Module]:
    """Every ``.py`` file of the packages, by dotted module name."""
    out: dict[str, Module] = {}
    for pkg, folder in packages.items():
        base = root / folder
        for path in sorted(base.rglob("*.py")):
            parts = list(path.relative_to(base).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            if is_package:
                parts = parts[:-1]
            name = ".".join([pkg, *parts])
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            out[name] = Module(name, path, path.relative_to(root).as_posix(), is_package, tree)
    return out


def subpackage(module: str, top: str) -> str:
    """The top-level subpackage (or module) of ``module`` under ``top``: ``cutkit.mesh.quality`` -> ``mesh``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == top else ""


def _resolve_relative(mod: Module, level: int, target: str | None) -> str:
    base = mod.name.split(".")
    if not mod.is_package:
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([target] if target else []))


@dataclass(frozen=True)
class _Import:
    line: int
    target: str  # the module imported (the deepest one that exists)
    path: tuple[str, ...]  # the dotted path as written, names included
    alias: str | None  # the local name bound to a module, if any


def imports_of(mod: Module, modules: dict[str, Module], top: str) -> list[_Import]:
    """The imports of a module within ``top`` (function-local ones too), resolved to modules."""
    out = []
    for node in ast.walk(mod.tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == top or a.name.startswith(top + "."):
                    tgt = _deepest(a.name, modules)
                    out.append(_Import(node.lineno, tgt, tuple(a.name.split(".")),
                                       a.asname if a.asname else None))
        elif isinstance(node, ast.ImportFrom):
            base = _resolve_relative(mod, node.level, node.module) if node.level else (node.module or "")
            if not (base == top or base.startswith(top + ".")):
                continue
            for a in node.names:
                full = f"{base}.{a.name}"
                if full in modules:  # a submodule
                    out.append(_Import(node.lineno, full, tuple(full.split(".")), a.asname or a.name))
                else:
                    out.append(_Import(node.lineno, _deepest(base, modules), tuple(full.split(".")), None))
    return out


def _deepest(name: str, modules: dict[str, Module]) -> str:
    parts = name.split(".")
    while parts and ".".join(parts) not in modules:
        parts.pop()
    return ".".join(parts) if parts else name


def _written(target: ast.AST):
    """The attributes an assignment target writes: ``x._a`` in ``x._a = ...`` and in ``x._a[i] = ...``."""
    if isinstance(target, (ast.Tuple, ast.List)):
        for elt in target.elts:
            yield from _written(elt)
    elif isinstance(target, ast.Starred):
        yield from _written(target.value)
    elif isinstance(target, ast.Subscript):
        inner = target.value
        while isinstance(inner, ast.Subscript):
            inner = inner.value
        if isinstance(inner, ast.Attribute):
            yield inner
    elif isinstance(target, ast.Attribute):
        yield target


def _functions(tree: ast.AST):
    """(qualified name, node) of every function and method, nested ones included."""
    def walk(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                q = f"{prefix}{child.name}"
                yield q, child
                yield from walk(child, q + ".")
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, f"{prefix}{child.name}.")
            else:
                yield from walk(child, prefix)
    yield from walk(tree, "")


def _is_kernel(fn) -> bool:
    """Whether ``fn`` is compiled by numba as a kernel of its own (not inlined into its caller)."""
    for d in fn.decorator_list:
        call = d if isinstance(d, ast.Call) else None
        if ast.unparse(call.func if call else d).split(".")[-1] not in ("njit", "jit"):
            continue
        return not (call and any(k.arg == "inline" and ast.unparse(k.value) == "'always'" for k in call.keywords))
    return False


def _kernel_arguments(mod, add) -> None:
    """``kernel-arguments`` violations of one module."""
    for qual, fn in _functions(mod.tree):
        n = len(fn.args.posonlyargs) + len(fn.args.args) + len(fn.args.kwonlyargs)
        if n > MAX_KERNEL_ARGUMENTS and _is_kernel(fn):
            add("kernel-arguments", f"{mod.rel}::{qual}", mod, fn.lineno,
                f"kernel {qual} takes {n} arguments (> {MAX_KERNEL_ARGUMENTS}): pass structs")


def _enclosing(tree: ast.AST) -> dict[int, str]:
    """id(node) -> qualified name of the function it is in ('<module>' at module level)."""
    owner: dict[int, str] = {}

    def walk(node, name):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                q = child.name if name == "<module>" else f"{name}.{child.name}"
                owner[id(child)] = name
                walk(child, q)
            else:
                owner[id(child)] = name
                walk(child, name)
    walk(tree, "<module>")
    return owner


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (or a self-import), Tarjan's algorithm."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = [0]

    def strongconnect(v):
        # iterative, so deep import chains cannot exhaust the recursion limit
        work = [(v, iter(sorted(graph.get(v, ()))))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        while work:
            node, it = work[-1]
            advanced = False
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph.get(w, ())))))
                    advanced = True
                    break
                if w in on_stack:
                    low[node] = min(low[node], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == node:
                        break
                if len(comp) > 1 or node in graph.get(node, ()):
                    out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strongconnect(v)
    return out


def _cycle_path(comp: list[str], graph: dict[str, set[str]]) -> list[str]:
    """One cycle through the component's first module (for the message)."""
    members = set(comp)
    start = comp[0]
    prev = {start: None}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph.get(v, ())):
            if w == start:
                path = [v]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                return [*reversed(path), start]
            if w in members and w not in prev:
                prev[w] = v
                queue.append(w)
    return [start, start]


def check(root: Path = ROOT, packages: dict[str, str] | None = None, run_side=RUN_SIDE, build_side=BUILD_SIDE,
          max_lines: int = MAX_FUNCTION_LINES, apart: dict | None = None) -> list[Violation]:
    """Every violation in the packages under ``root``.

    Parameters
    ----------
    root : Path
        Repository root.
    packages : dict, optional
        Import name -> source folder relative to ``root`` (default :data:`PACKAGES`);
        the first one is the top package whose subpackages are compared.
    run_side, build_side : set of str
        Top-level subpackage (or module) names of the run and build sides.
    max_lines : int
        Longest run-side function allowed.
    apart : dict, optional
        Subpackage -> subpackages it must not import (default :data:`APART`).

    Returns
    -------
    list of Violation
        Sorted by kind and key; one per key.
    """
    packages = PACKAGES if packages is None else packages
    apart = APART if apart is None else apart
    root = Path(root)
    top = next(iter(packages))
    modules = find_modules(root, packages)
    found: dict[str, Violation] = {}

    def add(kind, key, mod, line, message):
        v = Violation(kind, key, mod.rel, line, message)
        found.setdefault(v.entry, v)

    graph: dict[str, set[str]] = {name: set() for name in modules}
    for mod in modules.values():
        sub = subpackage(mod.name, top)
        module_aliases: dict[str, str] = {}
        for imp in imports_of(mod, modules, top):
            if imp.target in modules and imp.target != mod.name:
                graph[mod.name].add(imp.target)
            other = subpackage(".".join(imp.path), top)
            if other and other != sub:
                private = [p for p in imp.path[1:] if _private(p)]
                if private:
                    add("private-import", f"{mod.rel} -> {'.'.join(imp.path)}", mod, imp.line,
                        f"imports {'.'.join(imp.path)}, private to {top}.{other}")
                if imp.alias:
                    module_aliases[imp.alias] = other
                if other in apart.get(sub, ()):
                    add("cutting-meets-physics", f"{mod.rel} -> {imp.target}", mod, imp.line,
                        f"{top}.{sub} imports {imp.target}: they meet only through {top}.tissue")
                if sub in run_side and other in build_side:
                    add("run-imports-build", f"{mod.rel} -> {imp.target}", mod, imp.line,
                        f"run side ({top}.{sub}) imports the build side ({imp.target})")
        owner = _enclosing(mod.tree)
        for node in ast.walk(mod.tree):
            targets = []
            if isinstance(node, ast.Assign):
                targets = node.targets
            elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
                targets = [node.target]
            for t in targets:
                for sub_t in _written(t):
                    if (isinstance(sub_t, ast.Attribute) and _private(sub_t.attr)
                            and not (isinstance(sub_t.value, ast.Name) and sub_t.value.id in ("self", "cls"))):
                        expr = ast.unparse(sub_t)
                        add("private-write", f"{mod.rel}::{owner.get(id(node), '<module>')}::{expr}", mod,
                            sub_t.lineno, f"writes {expr} (another object's private attribute)")
            if (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Load) and _private(node.attr)
                    and isinstance(node.value, ast.Name) and node.value.id in module_aliases):
                expr = ast.unparse(node)
                add("private-read", f"{mod.rel}::{expr}", mod, node.lineno,
                    f"reads {expr}, private to {top}.{module_aliases[node.value.id]}")
        if sub in run_side:
            for qual, fn in _functions(mod.tree):
                n = fn.end_lineno - fn.lineno + 1
                if n > max_lines:
                    add("long-function", f"{mod.rel}::{qual}", mod, fn.lineno,
                        f"{qual} has {n} lines (> {max_lines})")
        _kernel_arguments(mod, add)
    for comp in _cycles(graph):
        path = _cycle_path(comp, graph)
        mod = modules[comp[0]]
        add("cycle", " | ".join(comp), mod, 1, "import cycle: " + " -> ".join(path))
    return sorted(found.values(), key=lambda v: (KINDS.index(v.kind), v.key))


def read_baseline(path: Path) -> list[str]:
    """The entries (``kind key``) of a baseline file; blank lines and ``#`` comments skipped."""
    if not Path(path).exists():
        return []
    out = []
    for line in Path(path).read_text(encoding="utf-8").splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            out.append(line)
    return out


def compare(found: list[Violation], baseline: list[str]) -> tuple[list[Violation], list[str]]:
    """The violations not in the baseline, and the baseline entries that no longer occur."""
    entries = {v.entry for v in found}
    known = set(baseline)
    return [v for v in found if v.entry not in known], sorted(known - entries)


def counts(found: list[Violation]) -> dict[str, int]:
    """Number of violations of each kind (every kind listed, zeros included)."""
    c = Counter(v.kind for v in found)
    return {k: c.get(k, 0) for k in KINDS}


def write_baseline(path: Path, found: list[Violation]) -> None:
    header = ("# Known architecture violations (tools/arch_check.py): one 'kind key' per line.\n"
              "# The check fails on a violation not listed here and on a line that no longer occurs:\n"
              "# remove a line when its violation is fixed; never add one for new code.\n")
    Path(path).write_text(header + "".join(v.entry + "\n" for v in found), encoding="utf-8")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=ROOT, help="repository root")
    ap.add_argument("--baseline", type=Path, default=None, help="baseline file [tools/arch_baseline.txt]")
    ap.add_argument("--all", action="store_true", help="list every violation, baseline included")
    ap.add_argument("--write-baseline", action="store_true", help="rewrite the baseline from the code")
    args = ap.parse_args(argv)
    baseline_path = args.baseline or args.root / "tools" / "arch_baseline.txt"
    found = check(args.root)
    if args.write_baseline:
        write_baseline(baseline_path, found)
        print(f"wrote {len(found)} entries to {baseline_path}")
        return 0
    new, gone = compare(found, read_baseline(baseline_path))
    shown = found if args.all else new
    for v in shown:
        print(f"{v.file}:{v.line}: {v.kind}: {v.message}")
    for entry in gone:
        print(f"{baseline_path.name}: no longer occurs, remove the line: {entry}")
    per_kind = counts(found)
    new_kind = counts(new)
    print("kind                    found  new")
    for k in KINDS:
        print(f"{k:<22} {per_kind[k]:>6} {new_kind[k]:>4}")
    print(f"{len(found)} violations, {len(new)} not in the baseline, {len(gone)} baseline entries gone")
    return 1 if new or gone else 0


if __name__ == "__main__":
    sys.exit(main())
