"""The public API's style, checked statically (the source is parsed, no grainforge module is imported).

For every public function, and every public method of a public class, of the parts in :data:`SCOPE`
(public: named in the module's ``__all__``, or not underscored when the module has no ``__all__``;
modules whose name starts with an underscore are private and left out):

- its docstring has a numpydoc ``Parameters`` section naming every parameter when it takes any, and a
  ``Returns`` or ``Yields`` section when it returns something (a function annotated ``-> None`` returns
  nothing);
- randomness is passed as ``rng`` (None, an int seed, a SeedSequence or a Generator, normalised by
  :mod:`grainforge.rng`): no parameter is called ``seed``, and no module but ``grainforge/rng.py``
  calls ``default_rng`` itself;
- with five or more parameters, at most the first two can be given by position, the options after
  them are keyword-only.

The exceptions are :data:`ALLOWED`, each with its reason, and the engine scripts of :data:`ENGINE_SCRIPTS`
(not grainforge's API).  Parts not yet in :data:`SCOPE` are to be added as they are brought to the style.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "src" / "grainforge"

#: top-level modules and packages of grainforge held to the style. cli/ stays out: its functions are click
#: commands, whose docstrings are their --help text (numpydoc sections would be printed to the user) and whose
#: parameters are the command's options, declared and documented by click's decorators
SCOPE = (
    "grain.py", "params.py", "units.py", "rng.py",
    "geometry", "outline", "io", "runtime",
    "methods", "analysis", "fabrication",
    "viz", "dem", "fit", "population", "simulate",
)

#: folders in SCOPE whose modules (all but ``__init__.py``) are not grainforge's Python API: the engine scripts
#: of dem/scripts/ run in an engine's own interpreter (Yade's Python, the LAMMPS decks' converters), never
#: import grainforge and are never imported by it; a deck carries their text (their ``__init__.py``, which
#: renders them, is in scope)
ENGINE_SCRIPTS = ("dem/scripts",)

#: (rule, "module:qualname") -> why it stays as it is
ALLOWED: dict[tuple[str, str], str] = {
    ("positional", "grainforge.geometry.solid:moller_trumbore"): (
        "moller_trumbore(p0, d, tri, *, det_min, relative): a ray (origins, directions) and the triangles it meets "
        "are three arrays of data, matched row by row; the thresholds are keyword-only"
    ),
    ("positional", "grainforge.outline.contours:descriptor_spectrum"): (
        "descriptor_spectrum(d2, d3, d8, *, decay, modes): the descriptor triplet (D2, D3, D8) is the datum, written "
        "as the three numbers of the literature; decay and modes are keyword-only"
    ),
    ("positional", "grainforge.fabrication.tray:build_tray"): (
        "build_tray(source, printer, out, *, ...): what to print, on which printer and into which file are all "
        "required, and read in that order as the command line does; the options are keyword-only"
    ),
    ("positional", "grainforge.dem.engines:write_deck"): (
        "write_deck(engine, templates, out, *, overwrite, rolling_friction): the engine, the grains and the deck's "
        "folder are all required, in the order `grainforge dem` reads them (each engine's writer takes "
        "(templates, out)); the options are keyword-only"
    ),
    ("positional", "grainforge.viz.render:contact_sheet"): (
        "contact_sheet(meshes, labels, out, *, ...): the meshes, one label each and the PNG file are the data "
        "(contact_sheet_figure takes the first two); the drawing options are keyword-only"
    ),
    ("positional", "grainforge.geometry.voxel:inside_mask"): (
        "inside_mask(vertices, faces, grid, *, axis, rule): a mesh (vertices and faces) and the grid of cells to "
        "test are the data; the conventions are keyword-only"
    ),
    ("positional", "grainforge.dem.clump:clump_quality"): (
        "clump_quality(vertices, faces, centres, radii, *, resolution): a mesh (vertices and faces) and the spheres "
        "measured against it (centres and radii) are four arrays of data, matched pairwise; the grid is keyword-only"
    ),
    ("positional", "grainforge.dem.clump:clump_accuracy"): (
        "clump_accuracy(vertices, faces, centres, radii, *, resolution): a mesh and the spheres measured against it "
        "are four arrays of data, as clump_quality; the grid is keyword-only"
    ),
    ("seed", "grainforge.dem.liggghts:template_fix"): (
        "seed is the number written into the deck's fix particletemplate/multisphere, LIGGGHTS's own random seed "
        "(a prime > 10000 from deck_seeds, as LIGGGHTS demands); no random number is drawn in Python"
    ),
    ("seed", "grainforge.dem.liggghts:node_insertion"): (
        "seed is the number written into the deck's fix insert/pack, LIGGGHTS's own random seed (a prime from "
        "deck_seeds); the grain's orientation, drawn in Python, comes in as quat from grain_orientations"
    ),
    ("positional", "grainforge.fit.sand:write_sand"): (
        "write_sand(path, equivalent_diameter, values, *, voxel_size, opening): the file and the table's two "
        "columns of data (each grain's size and its descriptors' values, matched grain by grain); the voxel size "
        "and the opening fraction are keyword-only"
    ),
    ("positional", "grainforge.fit.made_grains:MeasurePool.run"): (
        "run(method, fixed, jobs, *, progress, opening): the grains measured are the method, the parameters they "
        "share and each job's own (parameters, seed, resolution), as measure_settings takes them; the bar and "
        "the opening fraction are keyword-only"
    ),
    ("positional", "grainforge.fit.twins:invert"): (
        "invert(model, targets, across, *, offsets, start, scale): the model and the grains it is solved for "
        "(their target descriptors and resolutions, matched row by row); the solver's options are keyword-only"
    ),
    ("positional", "grainforge.fit.twins:identifiability"): (
        "identifiability(u, across, y, *, folds, rng): a design is three arrays matched row by row (settings, "
        "resolutions, measured descriptors), in ForwardModel.fit's order; the folds and their rng are keyword-only"
    ),
    ("seed", "grainforge.fit.recipes:recipe_text"): (
        "seed is the root seed written into the recipe text (its seed = ..., from which batch draws each grain's "
        "own stream); recipe_text draws no random number"
    ),
    ("seed", "grainforge.fit.recipes:twin_recipe_text"): (
        "seed is the root seed written into the twins' recipe (and seeds the grains' own, written where one "
        "differs from batch's); twin_recipe_text draws no random number"
    ),
    ("positional", "grainforge.simulate.triaxial:triaxial_angles"): (
        "triaxial_angles(axial_strain, q_over_p, volumetric_strain, *, window, last, slope_strain): a triaxial "
        "curve is three columns of triaxial.csv matched record by record; the windows are keyword-only"
    ),
    ("seed", "grainforge.simulate.settings:scene_settings"): (
        "seed is the run's seed number (the k of --seeds), written into grains.json and result.json so that a run "
        "is remade from its record; the orientations are drawn from it by grain_orientations (through "
        "grainforge.rng), and a Generator could not be written down"
    ),
    ("seed", "grainforge.simulate.triaxial:triaxial_scene_settings"): (
        "seed is the triaxial run's seed number (the k of --seeds), written into grains.json and result.json; the "
        "orientations are drawn from it by grain_orientations, as scene_settings"
    ),
    ("seed", "grainforge.simulate.engine:write_test_deck"): (
        "seed is the run's seed number (the k of --seeds) written into its deck (grains.json's scene, with which the "
        "Yade scene seeds its own random.Random; LIGGGHTS's primes) and naming its folder; every stream of the run "
        "is derived from it by the deck writers, so a deck is remade from the number its results record"
    ),
    ("seed", "grainforge.simulate.liggghts_scenes:run_deck_files"): (
        "seed is the run's seed number written into the LIGGGHTS deck: its fix insert/particletemplate seeds "
        "(primes of the seed table) and the layout's stream (SeedSequence([seed, 28]) through grainforge.rng) are "
        "derived from it, so a deck is remade from the number its results record"
    ),
    ("seed", "grainforge.simulate.liggghts_scenes:write_test_deck"): (
        "seed is the run's seed number written into the LIGGGHTS deck, as liggghts_scenes.run_deck_files"
    ),
    ("seed", "grainforge.simulate.liggghts_triaxial:triaxial_deck_files"): (
        "seed is the triaxial run's seed number written into the LIGGGHTS deck: LIGGGHTS's own seeds (primes of the "
        "seed table) and the lattice's stream (SeedSequence([seed, 28]) through grainforge.rng) are derived from "
        "it, so a deck is remade from the number its results record"
    ),
    ("seed", "grainforge.simulate.liggghts_triaxial:write_deck"): (
        "seed is the triaxial run's seed number written into the LIGGGHTS deck, as liggghts_triaxial.triaxial_deck_files"
    ),
}

SECTION_NAMES = ("Parameters", "Returns", "Yields")


def _files() -> list[Path]:
    files = []
    for part in SCOPE:
        path = PACKAGE / part
        files += [path] if path.is_file() else sorted(path.rglob("*.py"))
    scripts = {PACKAGE / folder for folder in ENGINE_SCRIPTS}
    return [f for f in files if (f.name == "__init__.py" or not f.name.startswith("_"))
            and not (f.parent in scripts and f.name != "__init__.py")]


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _exported(tree: ast.Module) -> set[str] | None:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return set(ast.literal_eval(node.value))
    return None


def _is_property(fn: ast.FunctionDef) -> bool:
    for d in fn.decorator_list:
        name = d.attr if isinstance(d, ast.Attribute) else getattr(d, "id", None)
        if name in {"property", "cached_property", "setter", "getter", "deleter"}:
            return True
    return False


def _public(name: str, exported: set[str] | None) -> bool:
    return not name.startswith("_") and (exported is None or name in exported)


def _public_functions() -> list[tuple[str, ast.FunctionDef, bool]]:
    """("module:qualname", node, is_method) of every public function and method in :data:`SCOPE`."""
    found = []
    for path in _files():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        exported = _exported(tree)
        module = _module_name(path)

        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and _public(node.name, exported):
                found.append((f"{module}:{node.name}", node, False))
            elif isinstance(node, ast.ClassDef) and _public(node.name, exported):
                for item in node.body:
                    if isinstance(item, ast.FunctionDef) and not item.name.startswith("_") and not _is_property(item):
                        found.append((f"{module}:{node.name}.{item.name}", item, True))
    return found


FUNCTIONS = _public_functions()
IDS = [name for name, _, _ in FUNCTIONS]


def _parameters(fn: ast.FunctionDef, method: bool) -> tuple[list[str], list[str]]:
    """(positional-or-keyword names, keyword-only names) without ``self``/``cls``."""
    positional = [a.arg for a in fn.args.posonlyargs + fn.args.args]
    static = any(getattr(d, "id", None) == "staticmethod" for d in fn.decorator_list)
    if method and not static and positional:
        positional = positional[1:]
    return positional, [a.arg for a in fn.args.kwonlyargs]


def _own_nodes(fn: ast.FunctionDef):
    """The nodes of ``fn``'s body, leaving out nested functions, lambdas and classes."""
    stack = list(fn.body)
    while stack:
        node = stack.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if not isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
                stack.append(child)


def _returns_something(fn: ast.FunctionDef) -> bool:
    if fn.returns is not None:
        return not (isinstance(fn.returns, ast.Constant) and fn.returns.value in (None, "None"))
    return any(
        isinstance(n, (ast.Yield, ast.YieldFrom)) or (isinstance(n, ast.Return) and n.value is not None)
        for n in _own_nodes(fn)
    )


def _section_starts(lines: list[str]) -> dict[str, int]:
    """numpydoc section name -> index of its first line after the underline."""
    return {
        lines[i].strip(): i + 2
        for i in range(len(lines) - 1)
        if lines[i].strip() and lines[i].strip()[0].isupper() and len(lines[i + 1].strip()) >= 3
        and set(lines[i + 1].strip()) == {"-"}
    }


def _sections(fn: ast.FunctionDef) -> set[str]:
    return set(_section_starts((ast.get_docstring(fn) or "").splitlines())) & set(SECTION_NAMES)


def _documented_parameters(fn: ast.FunctionDef) -> set[str]:
    """The names the Parameters section describes (``x, y : float`` names two; ``*args`` is ``args``)."""
    lines = (ast.get_docstring(fn) or "").splitlines()
    starts = _section_starts(lines)
    if "Parameters" not in starts:
        return set()
    first = starts["Parameters"]
    last = min([s - 2 for s in starts.values() if s > first] + [len(lines)])
    names = set()
    for line in lines[first:last]:
        if line and not line[0].isspace():
            names |= {n.strip().lstrip("*") for n in line.split(" : ")[0].split(",")}
    return names


def _allowed(rule: str, name: str) -> bool:
    return (rule, name) in ALLOWED


def test_scope_is_found():
    # the walk sees the parts in scope (a renamed folder would make every check below pass vacuously)
    modules = {name.split(":")[0].split(".")[1] for name in IDS}
    wanted = {p.removesuffix(".py") for p in SCOPE}
    assert modules == wanted
    assert len(FUNCTIONS) > 300


def test_allow_list_names_existing_functions():
    for rule, name in ALLOWED:
        assert rule in {"positional", "parameters", "returns", "seed"}, rule
        assert name in IDS, f"{name} is allowed but is not a public function in scope"


@pytest.mark.parametrize("name", IDS)
def test_docstring_sections(name):
    _, fn, method = FUNCTIONS[IDS.index(name)]
    positional, keywords = _parameters(fn, method)
    sections = _sections(fn)
    takes = bool(positional or keywords or fn.args.vararg or fn.args.kwarg)
    if takes and not _allowed("parameters", name):
        assert "Parameters" in sections, f"{name}: its docstring has no numpydoc Parameters section"
        every = positional + keywords + [a.arg for a in (fn.args.vararg, fn.args.kwarg) if a is not None]
        missing = [p for p in every if p not in _documented_parameters(fn)]
        assert not missing, f"{name}: its Parameters section does not describe {', '.join(missing)}"
    if _returns_something(fn) and not _allowed("returns", name):
        assert sections & {"Returns", "Yields"}, f"{name}: returns a value, its docstring has no Returns section"


@pytest.mark.parametrize("name", IDS)
def test_randomness_is_rng(name):
    _, fn, method = FUNCTIONS[IDS.index(name)]
    positional, keywords = _parameters(fn, method)
    if not _allowed("seed", name):
        assert "seed" not in positional + keywords, f"{name}: randomness is passed as rng, not seed"


@pytest.mark.parametrize("name", IDS)
def test_options_are_keyword_only(name):
    _, fn, method = FUNCTIONS[IDS.index(name)]
    positional, keywords = _parameters(fn, method)
    if len(positional) + len(keywords) >= 5 and not _allowed("positional", name):
        assert len(positional) <= 2, (
            f"{name}: {len(positional)} parameters can be given by position ({', '.join(positional)}); "
            "put a * after the first one or two"
        )


def test_one_rng_normaliser():
    # a Generator is made from an rng argument in one place, grainforge.rng, so that every public function
    # accepts the same values (None, int, SeedSequence, Generator) and refuses the others alike
    calls = []
    for path in _files():
        if path == PACKAGE / "rng.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call):
                f = node.func
                name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
                if name in {"default_rng", "RandomState"}:
                    calls.append(f"{_module_name(path)}:{node.lineno}")
    assert not calls, f"use grainforge.rng.as_generator: {calls}"
