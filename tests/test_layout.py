"""The package's layout holds: imports point downstream only, no cycles, no
private name crosses a module boundary, and the public API sits at the top.

The import graph is read from the source with ``ast`` (imports inside
functions included), so a lazy import cannot hide a cycle.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "aniso3d"

#: Stages in data-flow order: a module may import from its own stage or an
#: earlier one, never a later one. The bench measures builds and renderers;
#: the front ends (CLI, viewer) sit on top of everything, the bench included. The package's ``__init__`` is the façade
#: over all of them and is exempt.
STAGES = {
    "aniso3d.errors": 0,
    "aniso3d.files": 0,
    "aniso3d.grid": 0,
    "aniso3d.metrics": 0,
    "aniso3d.build": 1,
    "aniso3d.rendering": 2,
    "aniso3d.bench": 3,
    "aniso3d.app": 4,
}


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def stage_of(module: str) -> tuple[str, int]:
    for prefix, rank in sorted(STAGES.items(), key=lambda kv: -len(kv[0])):
        if module == prefix or module.startswith(prefix + "."):
            return prefix, rank
    raise AssertionError(f"module {module} belongs to no stage; add it to STAGES in {__file__}")


def resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_graph() -> tuple[dict[str, set[str]], list[str]]:
    """Module -> the aniso3d modules it imports; and every private name
    imported from another module, as 'importer: from X import _name'."""
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    private: list[str] = []
    for mod, path in modules.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        is_package = path.name == "__init__.py"
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                src = resolve(mod, is_package, node)
                for a in node.names:
                    # "from aniso3d.build import scenes" imports a module.
                    targets.append(f"{src}.{a.name}" if f"{src}.{a.name}" in modules else src)
                    if a.name.startswith("_") and src.startswith("aniso3d") and src != mod:
                        private.append(f"{mod}: from {src} import {a.name}")
            for t in targets:
                if t.startswith("aniso3d") and t in modules and t != mod:
                    graph[mod].add(t)
    return graph, private


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    colour: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        colour[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if colour.get(n) == 1:
                return stack[stack.index(n):] + [n]
            if n not in colour and (found := visit(n)):
                return found
        stack.pop()
        colour[m] = 2
        return None

    for m in sorted(graph):
        if m not in colour and (found := visit(m)):
            return found
    return None


def test_find_cycle_sees_a_cycle_and_a_dag():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_no_import_cycles():
    graph, _ = import_graph()
    # Packages' __init__ modules re-export their children; an edge from a
    # child to its own package's __init__ would be a cycle too, so keep them.
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_imports_point_downstream():
    graph, _ = import_graph()
    bad = []
    for mod, targets in graph.items():
        if mod == "aniso3d":
            continue
        src_stage, src_rank = stage_of(mod)
        for t in targets:
            if t == "aniso3d":
                bad.append(f"{mod} imports the package façade 'aniso3d'")
                continue
            dst_stage, dst_rank = stage_of(t)
            if dst_rank > src_rank or (dst_rank == src_rank and dst_stage != src_stage and src_rank > 0):
                bad.append(f"{mod} ({src_stage}) imports {t} ({dst_stage})")
    assert not bad, "upstream imports:\n" + "\n".join(sorted(bad))


def test_no_private_names_cross_modules():
    _, private = import_graph()
    assert not private, "private names imported across modules:\n" + "\n".join(private)


def test_public_api_at_the_top():
    code = (
        "import aniso3d\n"
        "names = ['Camera', 'Renderer', 'render', 'load_mesh', 'build_texture', 'PointCloud', 'scenes',"
        " 'Mesh', 'AnisoTexture', 'Lighting']\n"
        "missing = [n for n in names if not hasattr(aniso3d, n)]\n"
        "assert not missing, missing\n"
        "assert callable(aniso3d.render) and callable(aniso3d.scenes.tree)\n"
        "assert set(aniso3d.__all__) >= set(names)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_importing_the_package_does_not_import_front_ends():
    """``import aniso3d`` must not drag in the CLI, the viewer or pyglet."""
    code = (
        "import sys, aniso3d\n"
        "bad = [m for m in sys.modules if m.startswith(('aniso3d.app', 'aniso3d.bench', 'pyglet'))]\n"
        "assert not bad, bad\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_every_module_has_a_docstring():
    missing = [
        module_name(p)
        for p in PACKAGE.rglob("*.py")
        if p.stat().st_size and ast.get_docstring(ast.parse(p.read_text())) is None
    ]
    assert not missing, "modules without a docstring saying what they hold: " + ", ".join(missing)


def test_every_subpackage_ships_in_the_wheel():
    """pyproject.toml lists packages by hand; a new subpackage left out of the
    list would be missing from the wheel while every test here still passed."""
    import tomllib

    listed = set(tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {module_name(p) for p in PACKAGE.rglob("__init__.py")}
    assert found <= listed, f"subpackages missing from pyproject.toml's packages: {sorted(found - listed)}"
