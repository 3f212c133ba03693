"""Layering: every import edge of linefit and slam against the layers of docs/architecture.md.

The static test reads the ```` ```layers ```` block of ``docs/architecture.md`` (one layer per
line, lowest first; ``a | b`` are peers), collects every import of a ``linefit``/``slam`` module
in every module of ``linefit/`` and ``slam/`` (``import x``, ``from x import y``, relative
imports, imports inside functions and under ``TYPE_CHECKING``, and ``importlib.import_module``
of a literal module name in a module that calls it) and reports every edge that goes to a higher
layer or between two peers, and every module that belongs to no layer, in one assertion.

The runtime tests import modules in a fresh interpreter and look at ``sys.modules``: linefit
loads none of gtsam, filterpy, matplotlib, the CLI libraries or slam; the layers below
``slam.plotting`` load no plotting or CLI code.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "architecture.md"
PACKAGES = ("linefit", "slam")
TOP_PACKAGE = "slam"  # the package module itself: importable by any module of slam if lazy
# what the package module may import at import time: slam.blas selects the BLAS kernels before
# numpy is loaded (stdlib only; tests/test_blas.py checks that importing slam loads no numpy)
TOP_PACKAGE_EAGER = {"slam.blas"}

FORBIDDEN_FOR_LINEFIT = ["gtsam", "filterpy", "matplotlib", "typer", "click", "tqdm", "slam"]
# "name": the module and its submodules; "prefix*": every module whose name starts with prefix
FORBIDDEN_FOR_ALGORITHMS = [
    "matplotlib",
    "typer",
    "click",
    "tqdm",
    "slam.cli",
    "slam.plotting",
    "slam.plotting_*",
]
LOWEST_PRESENTATION_LAYER = "slam.plotting"


# ---------------------------------------------------------------------------------------------
# the layers and the modules
# ---------------------------------------------------------------------------------------------
def parse_layers(text: str) -> list[list[str]]:
    """The layers of the ```` ```layers ```` block, lowest first; each a list of peers."""
    match = re.search(r"^```layers[ \t]*\n(.*?)^```", text, flags=re.MULTILINE | re.DOTALL)
    assert match, f"no ```layers block in {ARCHITECTURE}"
    layers = []
    for line in match.group(1).splitlines():
        if line.strip():
            layers.append([name.strip() for name in line.split(" | ")])
    return layers


LAYERS = parse_layers(ARCHITECTURE.read_text(encoding="utf-8"))
LAYER_OF = {name: i for i, peers in enumerate(LAYERS) for name in peers}


def project_modules() -> dict[str, Path]:
    """Every module of linefit/ and slam/ by dotted name (a package by its own name)."""
    out = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = project_modules()


def entry_of(module: str) -> str | None:
    """The layer entry whose name is the longest dotted prefix of ``module`` (None: none)."""
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        prefix = ".".join(parts[:k])
        if prefix in LAYER_OF:
            return prefix
    return None


def matches(module: str, pattern: str) -> bool:
    """``pattern`` ``"a.b"``: ``a.b`` and its submodules; ``"a.b*"``: names starting ``a.b``."""
    if pattern.endswith("*"):
        return module.startswith(pattern[:-1])
    return module == pattern or module.startswith(pattern + ".")


# ---------------------------------------------------------------------------------------------
# import edges
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Edge:
    """``source`` imports ``target`` at ``path:line``; ``lazy``: inside a function."""

    source: str
    target: str
    path: Path
    line: int
    lazy: bool

    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def _resolve(name: str) -> str | None:
    """The project module ``name`` denotes (its longest existing dotted prefix), or None."""
    if name.split(".")[0] not in PACKAGES:
        return None
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k])
        if candidate in MODULES:
            return candidate
    return None


def _base_of_relative(module: str, is_package: bool, level: int, name: str | None) -> str:
    parts = module.split(".")
    package = parts if is_package else parts[:-1]
    base = package[: len(package) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def _function_lines(tree: ast.AST) -> set[int]:
    """Line numbers of every statement inside a function body."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            for inner in ast.walk(node):
                if hasattr(inner, "lineno") and inner is not node:
                    lines.add(inner.lineno)
    return lines


def imports_of(module: str) -> list[Edge]:
    """Every import of a project module in ``module`` (static, from the source)."""
    path = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    in_function = _function_lines(tree)
    is_package = path.name == "__init__.py"
    targets: list[tuple[str, int]] = []
    uses_importlib = False
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets += [(alias.name, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = _base_of_relative(module, is_package, node.level, node.module)
            targets.append((base, node.lineno))
            # `from pkg import sub` imports the submodule pkg.sub
            targets += [(f"{base}.{alias.name}", node.lineno) for alias in node.names]
        elif isinstance(node, ast.Call):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            uses_importlib |= name in ("import_module", "__import__")
    if uses_importlib:  # literal module names in a module that imports by name
        docstrings = {
            id(n.body[0].value)
            for n in ast.walk(tree)
            if isinstance(n, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
            and n.body
            and isinstance(n.body[0], ast.Expr)
        }
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and id(node) not in docstrings
                and node.value in MODULES
            ):
                targets.append((node.value, node.lineno))
    edges = set()
    for name, line in targets:
        target = _resolve(name)
        if target is not None and target != module:
            edges.add(Edge(module, target, path, line, line in in_function))
    return sorted(edges, key=lambda e: (e.line, e.target))


def layering_violations() -> list[str]:
    """Every edge to a higher layer or between peers, every module in no layer.

    One line per (importing module, imported module), with the lines of the imports.
    """
    problems = []
    unplaced_importers: dict[str, set[str]] = {}
    for module in MODULES:
        edges = imports_of(module)
        if module == TOP_PACKAGE:
            eager = [e for e in edges if not e.lazy and e.target not in TOP_PACKAGE_EAGER]
            problems += [
                f"{e.where()}: {TOP_PACKAGE} (the package) imports {e.target} at import time"
                for e in eager
            ]
            continue
        source = entry_of(module)
        bad: dict[str, tuple[str, list[str]]] = {}
        for edge in edges:
            if edge.target == TOP_PACKAGE:
                if module.split(".")[0] != TOP_PACKAGE:
                    bad.setdefault(edge.target, ("upward", []))[1].append(str(edge.line))
                continue
            target = entry_of(edge.target)
            if target is None:
                unplaced_importers.setdefault(edge.target, set()).add(module)
                continue
            if source is None:
                continue  # reported below as a module in no layer
            kind = None
            if LAYER_OF[target] > LAYER_OF[source]:
                kind = "upward"
            elif LAYER_OF[target] == LAYER_OF[source] and target != source:
                kind = "peers"
            if kind:
                bad.setdefault(edge.target, (kind, []))[1].append(str(edge.line))
        where = MODULES[module].relative_to(ROOT)
        for target, (kind, lines) in sorted(bad.items()):
            problems.append(
                f"{where}:{','.join(lines)}: {module} [{source}] imports {target} "
                f"[{entry_of(target)}] ({kind})"
            )
    for module in MODULES:
        if module != TOP_PACKAGE and entry_of(module) is None:
            importers = ", ".join(sorted(unplaced_importers.get(module, ()))) or "nobody"
            problems.append(
                f"{MODULES[module].relative_to(ROOT)}: {module} is in no layer "
                f"(imported by {importers})"
            )
    return problems


def test_the_layer_block_names_each_layer_once_and_existing_modules():
    names = [name for peers in LAYERS for name in peers]
    assert len(names) == len(set(names)), names
    assert names[0] == "linefit"
    missing = [name for name in names if name not in MODULES]
    assert not missing, f"layers without a module: {missing}"


def test_the_import_scanner_sees_lazy_type_checking_and_submodule_imports():
    # slam.graph's package module imports its submodules only under TYPE_CHECKING and by name
    targets = {edge.target for edge in imports_of("slam.graph")}
    assert {"slam.graph.batch", "slam.graph.problem", "slam.graph.isam2"} <= targets
    # `from linefit.errors import X` names the module linefit.errors
    assert "linefit.errors" in {edge.target for edge in imports_of("slam.errors")}
    # relative imports: `from .factors import f` in slam/graph/batch.py and slam/graph/__init__.py
    assert _base_of_relative("slam.graph.batch", False, 1, "factors") == "slam.graph.factors"
    assert _base_of_relative("slam.graph", True, 1, "factors") == "slam.graph.factors"
    assert _base_of_relative("slam.graph.batch", False, 2, "lines") == "slam.lines"
    assert entry_of("slam.graph.factors") == "slam.graph"
    assert entry_of("slam.plotting_map") is None  # longest *dotted* prefix, not a string prefix


def test_every_import_edge_respects_the_layers():
    problems = layering_violations()
    assert not problems, f"{len(problems)} layering violation(s):\n" + "\n".join(problems)


# ---------------------------------------------------------------------------------------------
# what importing a layer loads
# ---------------------------------------------------------------------------------------------
def loaded_modules(modules: list[str]) -> set[str]:
    """``sys.modules`` of a fresh interpreter after importing ``modules``."""
    code = (
        "import sys, importlib\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        "print('\\n'.join(sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=False, cwd=ROOT
    )
    assert out.returncode == 0, out.stderr
    return set(out.stdout.split())


def test_forbidden_patterns_catch_packages_submodules_and_prefixed_modules():
    def hit(module: str) -> bool:
        return any(matches(module, p) for p in FORBIDDEN_FOR_ALGORITHMS)

    assert hit("slam.plotting") and hit("slam.plotting.figures")
    assert hit("slam.plotting_map") and hit("slam.plotting_slam") and hit("slam.plotting_compare")
    assert hit("slam.cli.cmd_slam") and hit("matplotlib.pyplot")
    assert not hit("slam.clip") and not hit("slam.config") and not hit("slam.graph")


def test_linefit_imports_none_of_the_heavy_or_upper_layers():
    linefit_modules = [m for m in MODULES if m.split(".")[0] == "linefit"]
    mods = loaded_modules(linefit_modules)
    bad = sorted(m for m in mods for name in FORBIDDEN_FOR_LINEFIT if matches(m, name))
    assert not bad, bad


ALGORITHM_ENTRIES = [
    name
    for peers in LAYERS[1 : LAYER_OF.get(LOWEST_PRESENTATION_LAYER, len(LAYERS))]
    for name in peers
]


@pytest.mark.parametrize("entry", ALGORITHM_ENTRIES)
def test_slam_algorithms_import_no_plotting_or_cli(entry):
    modules = [m for m in MODULES if entry_of(m) == entry]
    if not modules:
        pytest.skip(f"{entry} not present")
    mods = loaded_modules(modules)
    bad = sorted(m for m in mods for name in FORBIDDEN_FOR_ALGORITHMS if matches(m, name))
    assert not bad, (entry, bad)
