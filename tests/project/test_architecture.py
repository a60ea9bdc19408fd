"""The house rules on the source, checked statically (no grainforge module is imported to check them).

- The import contracts of ``pyproject.toml`` (``[tool.importlinter]``: the layers, and algorithms that
  never reach ``click`` or ``grainforge.cli``), run by import-linter.
- No import cycles among grainforge modules, counting imports made inside functions too (a lazy
  import that closes a cycle is still a cycle), and counting the parent packages an import runs:
  ``import a.b.c`` executes ``a/b/__init__.py`` as well, so it is an import of ``a.b`` too.
- The layout table of docs/design/architecture.md is the package tree.
- Method modules export parameters and pure functions only: no ``cli_command``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src"
PACKAGE = "grainforge"

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
    # cli.group imports its commands inside _register(), cli.main the group inside main()
    assert "grainforge.cli.generate" in graph["grainforge.cli.group"]
    assert "grainforge.cli.group" in graph["grainforge.cli.main"]


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


def test_import_contracts_are_kept():
    """pyproject.toml's import contracts (layers; algorithms without the CLI), by import-linter."""
    from importlinter.cli import lint_imports

    assert lint_imports(config_filename=str(SRC.parent / "pyproject.toml"), no_cache=True) == 0


def _layout_table() -> dict[str, tuple[str, set[str]]]:
    """docs/design/architecture.md's layout table: part -> (layer, modules named in its last column)."""
    text = (SRC.parent / "docs" / "design" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## Layout", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 4 and cells[0].startswith("`"):
            part = cells[0].strip("`")
            named = set(re.findall(r"`([\w/]+)`", cells[3]))
            rows[part] = (cells[1], named)
    return rows


def test_layout_table_is_the_package_tree():
    root = SRC / PACKAGE
    parts = {p.name + "/" for p in root.iterdir() if (p / "__init__.py").exists()}
    parts |= {p.name for p in root.glob("*.py") if p.name not in {"__init__.py", "_version.py"}}
    table = _layout_table()
    assert set(table) == parts, "docs/design/architecture.md's layout table lists other parts than src/grainforge"
    for part, (_, named) in table.items():
        if not part.endswith("/") or part == "cli/":
            continue  # a module; cli's row names commands by example
        folder = root / part
        actual = {p.stem for p in folder.glob("*.py") if p.name != "__init__.py"}
        actual |= {p.name + "/" for p in folder.iterdir() if p.is_dir() and p.name != "__pycache__"}
        missing = actual - named
        unknown = {n for n in named - actual if not list(folder.rglob(n.rstrip("/") + ("" if n.endswith("/") else ".py")))}
        assert not missing and not unknown, f"{part}: not in the table {sorted(missing)}, not in the tree {sorted(unknown)}"


def test_layout_layers_are_the_contract_layers():
    import tomllib

    config = tomllib.loads((SRC.parent / "pyproject.toml").read_text(encoding="utf-8"))
    (layers,) = [c["layers"] for c in config["tool"]["importlinter"]["contracts"] if c["type"] == "layers"]
    names = {"cli": "commands", "viz": "pictures"}
    for part in layers[2].split(" : "):
        names[part] = "jobs"
    for part in layers[3].split(" : "):
        names[part] = "algorithms"
    for part in layers[4].split(" : "):
        names[part] = "base"
    for part, (layer, _) in _layout_table().items():
        assert names[part.removesuffix("/").removesuffix(".py")] == layer, part


#: the most lines of code a function in src/ may have (docstrings, comments and blank lines aside)
MAX_FUNCTION_LINES = 80


def function_lengths() -> list[tuple[int, str]]:
    """(lines of code, ``module:function``) of every function and method in the package, longest first."""
    rows = []
    for name, path in MODULES.items():
        if ".dem.scripts." in name:
            continue  # the engine scripts run in Yade's interpreter (tests/dem/test_dem_scripts.py)
        text = path.read_text(encoding="utf-8")
        lines = text.splitlines()
        for node in ast.walk(ast.parse(text)):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            first = node.body[0]
            doc = (first.end_lineno - first.lineno + 1) if isinstance(first, ast.Expr) and \
                isinstance(first.value, ast.Constant) and isinstance(first.value.value, str) else 0
            code = [ln for ln in lines[node.lineno - 1:node.end_lineno] if ln.strip() and not ln.strip().startswith("#")]
            rows.append((len(code) - doc, f"{name}:{node.name}"))
    return sorted(rows, reverse=True)


def test_no_function_is_longer_than_80_lines_of_code():
    long = [f"{n} lines: {where}" for n, where in function_lengths() if n > MAX_FUNCTION_LINES]
    assert long == [], "split these where their steps have names of their own:\n" + "\n".join(long)


def test_the_longest_functions_are_listed_in_the_architecture_notes():
    text = (SRC.parent / "docs" / "design" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## The longest functions", 1)[1].split("\n## ", 1)[0]
    listed = re.findall(r"^\| \d+ \| `grainforge\.([\w.]+):(\w+)`", section, flags=re.M)
    longest = [tuple(where.removeprefix("grainforge.").split(":")) for _, where in function_lengths()[:15]]
    assert sorted(listed) == sorted(longest), "docs/design/architecture.md's fifteen longest functions are others"
