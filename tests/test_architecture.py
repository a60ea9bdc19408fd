"""The house rules, checked statically on the source (ast, no imports run).

- Algorithm modules (``grainforge.methods``, ``.analysis``, ``.fabrication``)
  never import click or ``grainforge.cli``, directly or through another module.
- No import cycles among grainforge modules, counting imports made inside
  functions too (a lazy import that closes a cycle is still a cycle), and
  counting the parent packages an import runs: ``import a.b.c`` executes
  ``a/b/__init__.py`` as well, so it is an import of ``a.b`` too.
- No upward import: every top-level module or package of grainforge sits in a
  layer (:data:`LAYERS`, as docs/design/architecture.md draws them) and
  imports only from its own layer or those below.
- Method modules export parameters and pure functions only: no ``cli_command``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = "grainforge"
ALGORITHMS = ("grainforge.methods", "grainforge.analysis", "grainforge.fabrication")

#: the layers, bottom first: a module imports from its own layer and those below, never above
LAYERS = (
    # the base: data, geometry kernels, outlines, files, processes
    ("_version", "params", "units", "grain", "geometry", "outline", "io", "runtime"),
    # algorithms on grains
    ("methods", "analysis", "fabrication"),
    # jobs built from them
    ("population", "fit", "dem", "simulate"),
    # pictures of their results, and the demo that runs them
    ("viz",),
    # the commands
    ("cli",),
)


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted((SRC / PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _is_package(name: str) -> bool:
    return MODULES[name].name == "__init__.py"


def _imports(name: str) -> list[tuple[str, int]]:
    """(imported name, line) of every import statement in module ``name``, anywhere in it."""
    tree = ast.parse(MODULES[name].read_text(encoding="utf-8"))
    base = name.split(".") if _is_package(name) else name.split(".")[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[: len(base) - (node.level - 1)]
                target = ".".join(anchor + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            # ``from pkg import sub`` imports the submodule pkg.sub (pkg itself being its parent, as for
            # every import); ``from pkg import name`` imports pkg
            for a in node.names:
                sub = f"{target}.{a.name}"
                found.append((sub if sub in MODULES else target, node.lineno))
    return found


def _with_parents(importer: str, target: str) -> set[str]:
    """``target`` and the packages between the root and it that importing it runs, leaving out the root
    (every module's) and the importer's own packages (already running when it runs)."""
    parts = target.split(".")
    found = {target}
    for k in range(2, len(parts)):
        parent = ".".join(parts[:k])
        if importer != parent and not importer.startswith(parent + "."):
            found.add(parent)
    return found


def _graph() -> dict[str, set[str]]:
    graph = {}
    for name in MODULES:
        targets = set()
        for t, _ in _imports(name):
            if t in MODULES:
                targets |= _with_parents(name, t)
        targets.discard(name)
        graph[name] = targets
    return graph


def _layer(name: str) -> int | None:
    unit = name.split(".")[1] if "." in name else None
    for level, names in enumerate(LAYERS):
        if unit in names:
            return level
    return None


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, comps = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return comps


def test_graph_sees_lazy_imports():
    """The detector must see imports inside functions (the old cycles were all lazy)."""
    graph = _graph()
    # cli.main imports its commands inside _register()
    assert "grainforge.cli.generate" in graph["grainforge.cli.main"]


def test_graph_counts_parent_packages():
    """Importing a submodule runs its parent package: an import of ``fabrication.threemf`` from ``io``
    is one of ``fabrication`` too (whose init imported ``io``: the cycle the old detector missed)."""
    assert _with_parents("grainforge.io", "grainforge.fabrication.threemf") == {
        "grainforge.fabrication.threemf", "grainforge.fabrication"}
    # a package's own modules importing each other is no import of the package from outside
    assert _with_parents("grainforge.io.stl", "grainforge.io.threemf") == {"grainforge.io.threemf"}
    assert "grainforge.methods" in _graph()["grainforge.population.generate"]


def test_cycle_detector_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles():
    cycles = _cycles(_graph())
    assert cycles == [], "import cycles among grainforge modules: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_every_module_has_a_layer():
    missing = sorted({name.split(".")[1] for name in MODULES if name != PACKAGE and _layer(name) is None})
    assert missing == [], f"put these in a layer of LAYERS (and docs/design/architecture.md): {missing}"


def test_no_upward_imports():
    graph = _graph()
    up = []
    for name, targets in graph.items():
        if name == PACKAGE:
            continue  # the root package re-exports (lazily); every module's parent
        for t in sorted(targets):
            if t != PACKAGE and _layer(t) > _layer(name):
                up.append(f"{MODULES[name].relative_to(SRC)} (layer {_layer(name)}) imports {t} (layer {_layer(t)})")
    assert up == [], "upward imports:\n" + "\n".join(up)


def test_upward_detector_sees_an_upward_import():
    assert _layer("grainforge.io.stl") < _layer("grainforge.fabrication.tray") < _layer("grainforge.cli.main")


@pytest.mark.parametrize("package", ALGORITHMS)
def test_algorithms_do_not_import_the_cli(package):
    bad = []
    for name in MODULES:
        if name != package and not name.startswith(package + "."):
            continue
        for target, line in _imports(name):
            if target == "click" or target.startswith("click.") or target == "grainforge.cli" \
                    or target.startswith("grainforge.cli."):
                bad.append(f"{MODULES[name].relative_to(SRC)}:{line} imports {target}")
    assert bad == []


def test_algorithms_do_not_reach_the_cli_transitively():
    graph = _graph()
    for start in MODULES:
        if not start.startswith(ALGORITHMS):
            continue
        seen, todo = set(), [start]
        while todo:
            v = todo.pop()
            if v in seen:
                continue
            seen.add(v)
            todo += graph[v]
        reached = sorted(m for m in seen if m.startswith("grainforge.cli"))
        assert reached == [], f"{start} reaches {reached}"


def test_method_modules_define_no_commands():
    from grainforge.methods import METHODS

    for path in METHODS.values():
        tree = ast.parse(MODULES[path].read_text(encoding="utf-8"))
        defined = {n.name for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
        assert "cli_command" not in defined, f"{path} defines cli_command: command code belongs in grainforge.cli"


def test_generate_commands_come_from_params_and_hooks(runner):
    """Every registered method has a generate command; hooks add their options; --printer only where it works."""
    from grainforge.cli.main import cli
    from grainforge.fabrication.resolution import supports_matching
    from grainforge.methods import METHODS

    for name in METHODS:
        res = runner.invoke(cli, ["generate", name, "--help"])
        assert res.exit_code == 0, res.output
        assert ("--printer" in res.output) == supports_matching(name), name
    assert "--aspect" in runner.invoke(cli, ["generate", "cri", "--help"]).output
    assert "--target-fractal-dimension" in runner.invoke(cli, ["generate", "dpa", "--help"]).output
    res = runner.invoke(cli, ["generate", "dpa", "--out", "unused", "--printer", "generic-fdm"])
    assert res.exit_code == 2 and "No such option '--printer'" in res.output
