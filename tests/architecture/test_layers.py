"""The layout's rules, checked on the source: data flows one way, ``ctp -> api -> sim -> planner ->
analysis``; no circle between modules; each engine (HiGHS, MuJoCo, OMPL, ...) is imported in its
own room only.

Every import counts: top-level, function-local and ``TYPE_CHECKING`` ones alike, since each is a
dependency a reader must follow. The checker is tested on a small synthetic tree first, so a rule
that cannot fail would show.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[2]

#: Packages from the bottom up: a package may import only those at its level or below.
LAYERS = ("analysis", "planner", "sim", "api", "ctp")

#: Third-party engines and the only modules (or packages) that may import them.
ENGINE_ROOMS: dict[str, tuple[str, ...]] = {
    "highspy": ("analysis.solvers.highs",),
    "cdd": ("analysis.solvers.cdd",),
    "mujoco": ("sim",),
    "ompl": ("planner.transfer", "planner.object_motion"),
    "pinocchio": ("analysis.urdf",),
    "coal": ("analysis.detect", "analysis.mesh"),
    "ray": ("api.workers", "ctp.batch"),
    "fastapi": ("api",),
    "typer": ("ctp",),
    "matplotlib": ("ctp.plot",),
}


@dataclass(frozen=True)
class Import:
    module: str  # the importing module, e.g. "planner.graph"
    target: str  # what it imports, resolved to a module where it is one, e.g. "analysis.scene"
    line: int


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(known: set[str], name: str) -> str:
    """The longest prefix of ``name`` that is a known module (``analysis.scene.Box`` -> ``analysis.scene``)."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        candidate = ".".join(parts[:k])
        if candidate in known:
            return candidate
    return name


def collect_imports(root: Path, packages: tuple[str, ...]) -> list[Import]:
    """Every import statement in the packages' modules, resolved against the modules that exist."""
    files = [p for pkg in packages for p in sorted((root / pkg).rglob("*.py")) if (root / pkg).is_dir()]
    known = {module_name(root, p) for p in files}
    out = []
    for path in files:
        mod = module_name(root, path)
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                out += [Import(mod, _resolve(known, a.name), node.lineno) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:  # relative import: anchor at this module's package
                    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    name = ".".join([*base, node.module] if node.module else base)
                else:
                    name = node.module or ""
                # ``from pkg import sub`` imports the submodule ``pkg.sub`` when there is one
                for a in node.names:
                    sub = f"{name}.{a.name}"
                    out.append(Import(mod, sub if sub in known else _resolve(known, name), node.lineno))
    return out


def _top(name: str) -> str:
    return name.split(".")[0]


def _inside(module: str, rooms: tuple[str, ...]) -> bool:
    return any(module == r or module.startswith(r + ".") for r in rooms)


def layer_violations(imports: list[Import], layers: tuple[str, ...] = LAYERS) -> list[str]:
    level = {p: i for i, p in enumerate(layers)}
    return [f"{i.module}:{i.line} imports {i.target} (upward: {_top(i.module)} is below {_top(i.target)})"
            for i in imports
            if _top(i.target) in level and level[_top(i.target)] > level[_top(i.module)]]


def module_cycles(imports: list[Import], packages: tuple[str, ...] = LAYERS) -> list[list[str]]:
    """Circles between the project's modules (strongly connected components with more than one)."""
    G = nx.DiGraph()
    G.add_edges_from((i.module, i.target) for i in imports if _top(i.target) in packages and i.target != i.module)
    # a package's __init__ that re-exports its own modules is no circle: drop edges into the parent package
    G.remove_edges_from([(a, b) for a, b in list(G.edges) if a.startswith(b + ".")])
    return [sorted(c) for c in nx.strongly_connected_components(G) if len(c) > 1]


def engine_violations(imports: list[Import], rooms: dict[str, tuple[str, ...]] = ENGINE_ROOMS) -> list[str]:
    return [f"{i.module}:{i.line} imports {i.target} (only {', '.join(rooms[_top(i.target)])} may)"
            for i in imports if _top(i.target) in rooms and not _inside(i.module, rooms[_top(i.target)])]


# -- the checker on a tiny tree with known answers -------------------------------------------------


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def test_checker_finds_upward_imports_cycles_and_engines_out_of_their_room(tmp_path: Path) -> None:
    _write(tmp_path, {
        "analysis/__init__.py": "",
        "analysis/a.py": "from analysis import b\n",
        "analysis/b.py": "def f():\n    from analysis.a import g  # function-local: still a dependency\n",
        "analysis/c.py": "import highspy\nfrom planner.x import y\n",
        "analysis/solvers/__init__.py": "",
        "analysis/solvers/highs.py": "import highspy\n",
        "planner/__init__.py": "from planner.x import y\n",
        "planner/x.py": "from . import z\nfrom analysis.c import h\n",
        "planner/z.py": "import mujoco\n",
    })
    imports = collect_imports(tmp_path, LAYERS)
    assert layer_violations(imports) == ["analysis.c:2 imports planner.x (upward: analysis is below planner)"]
    assert sorted(module_cycles(imports)) == [["analysis.a", "analysis.b"],
                                              ["analysis.c", "planner.x"]]
    assert sorted(engine_violations(imports)) == [
        "analysis.c:1 imports highspy (only analysis.solvers.highs may)",
        "planner.z:1 imports mujoco (only sim may)",
    ]


def test_checker_passes_a_clean_tree(tmp_path: Path) -> None:
    _write(tmp_path, {
        "analysis/__init__.py": "",
        "analysis/a.py": "import numpy as np\n",
        "planner/__init__.py": "from planner.x import y\n",
        "planner/x.py": "from analysis.a import np\nfrom planner import z\n",
        "planner/z.py": "",
    })
    imports = collect_imports(tmp_path, LAYERS)
    assert ("planner.x", "planner.z") in {(i.module, i.target) for i in imports}
    assert layer_violations(imports) == [] and module_cycles(imports) == [] and engine_violations(imports) == []


# -- the project itself -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def project_imports() -> list[Import]:
    imports = collect_imports(ROOT, LAYERS)
    assert len({i.module for i in imports}) > 40  # the whole source was read
    return imports


def test_data_flows_one_way(project_imports: list[Import]) -> None:
    assert layer_violations(project_imports) == []


def test_no_circle_between_modules(project_imports: list[Import]) -> None:
    assert module_cycles(project_imports) == []


def test_engines_stay_in_their_rooms(project_imports: list[Import]) -> None:
    assert engine_violations(project_imports) == []
