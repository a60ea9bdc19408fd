"""The population of a virtual test: grain files or a recipe made into clump templates."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .settings import Settings

__all__ = ["check_inputs", "build_population", "ChosenGrains", "choose_grains", "template_make_seconds"]


def _sphere_mesh(d: float):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    from ..geometry.moments import sphere_diameter

    scale = d / sphere_diameter(m.volume)
    return np.asarray(m.vertices) * scale, np.asarray(m.faces, dtype=np.int64)


def _template(args):
    from ..dem.template import prepare
    from ..geometry.moments import signed_volume, sphere_diameter

    vertices, faces, name, settings, source, k, as_spheres, shape, spacing, clump_accuracy = args
    if as_spheres:
        d = float(sphere_diameter(signed_volume(vertices, faces)))
        vertices, faces = _sphere_mesh(d)
        t = prepare(vertices, faces, name=name, unit=1e-3, density=settings.density, spheres=1, source=source,
                    rng=k)
        # a sphere's clump is the sphere itself
        from ..dem.clump import Clump

        sphere = Clump(np.zeros((1, 3)), np.array([t.d_eq / 2.0]), 1.0, 0.0, t.clump.resolution)
        # and its bounding radius the sphere's (or the mesh's, the larger): not that of the one-sphere clump
        # prepare() made and this replaces, which may reach past the mesh (the scene spaces grains by it)
        radius = max(t.d_eq / 2.0, float(np.linalg.norm(t.vertices, axis=1).max()))
        return replace(t, clump=sphere, info={**t.info, "bounding_radius": radius})
    return prepare(vertices, faces, name=name, unit=1e-3, density=settings.density, spheres=settings.spheres,
                   source=source, rng=k, shape=shape, levelset_spacing=spacing, target_iou=clump_accuracy)


def _scaled_to(vertices, faces, size):
    from ..geometry.moments import signed_volume, sphere_diameter

    d = float(sphere_diameter(signed_volume(vertices, faces)))
    return vertices * (size / d)


def _is_recipe(paths: Sequence[Path]) -> bool:
    return len(paths) == 1 and paths[0].suffix.lower() == ".toml"


def template_make_seconds(templates: int, available: int, make_seconds: float, pool: int | None = None) -> float:
    """Seconds per template of making the templates, their choice included (for :func:`check_size`).

    The choice (:func:`choose_grains`) generates (a recipe) or reads and
    measures ``pool`` grains (default
    :func:`grainforge.dem.template_choice.pool_size`), at ``make_seconds`` +
    :data:`~grainforge.dem.template_choice.MEASURE_SECONDS` each; their cost
    is shared out over the ``min(templates, available)`` templates.

    Parameters
    ----------
    templates : int
        Templates wanted (``settings.templates``).
    available : int
        Grains the inputs hold (:func:`check_inputs`).
    make_seconds : float
        Seconds to make one grain (0 for files).
    pool : int, optional
        Grains measured to choose from; default :func:`grainforge.dem.template_choice.pool_size`.

    Returns
    -------
    float
        Seconds per template.

    Examples
    --------
    >>> round(template_make_seconds(40, 500, 0.03), 3)  # a pool of 200 grains for 40 templates
    0.48
    """
    from ..dem.template_choice import MEASURE_SECONDS, pool_size

    k = max(1, min(templates, available))
    pool = pool_size(templates, available) if pool is None else min(available, max(pool, k))
    return float(make_seconds + pool * (make_seconds + MEASURE_SECONDS) / k)


@dataclass(frozen=True)
class ChosenGrains:
    """The grains chosen as a test's templates (:func:`choose_grains`).

    Attributes
    ----------
    recipe : Path or None
        The recipe the grains are generated from, or None (grain files).
    picks : list
        The recipe's grain indices, or the files' paths.
    names, sources : list of str
        The templates' names and where each grain comes from.
    table : (K, 5) ndarray
        Their descriptors (:data:`grainforge.dem.representative.DESCRIPTORS`, size in mm).
    choice : grainforge.dem.representative.TemplateChoice
    available, measured : int
        Grains the inputs hold; grains generated or read and measured to choose from.
    """

    recipe: Path | None
    picks: list
    names: list
    sources: list
    table: np.ndarray
    choice: object
    available: int
    measured: int

    def summary(self) -> str:
        """The one line ``simulate`` prints: what was chosen from what, and the KS figures.

        Returns
        -------
        str
            The line, e.g. how many grains were chosen from how many measured, with the KS statistics.
        """
        from ..dem.template_choice import _summary

        return _summary(self.choice, len(self.picks), self.available, self.measured)

    def write_csv(self, path: str | os.PathLike) -> Path:
        """``templates.csv`` (:func:`grainforge.dem.template_choice.write_templates_csv`).

        Parameters
        ----------
        path : path
            The CSV file to write.

        Returns
        -------
        Path
            The file written (one row per template: name, source, descriptors; size in mm).
        """
        from ..dem.template_choice import write_templates_csv

        return write_templates_csv(path, names=self.names, sources=self.sources, table=self.table,
                                   choice=self.choice)


def _recipe_mesh(recipe, i: int):
    from ..fabrication.scale import to_size
    from ..methods import generate
    from ..population import draw_grain

    seed, params, size = draw_grain(recipe, i)
    g = to_size(generate(recipe.method, params, seed), size, recipe.size_definition)
    return np.asarray(g.vertices, dtype=np.float64), np.asarray(g.faces, dtype=np.int64)


def _recipe_descriptors(args):
    from ..dem.template_choice import mesh_descriptors

    return mesh_descriptors(*_recipe_mesh(*args))


def choose_grains(inputs: Sequence[str | os.PathLike], settings: Settings, *, pool: int | None = None,
                  workers: int = 1, progress: Callable[[int, int], None] | None = None) -> ChosenGrains:
    """The ``settings.templates`` grains of the inputs whose descriptors are distributed as the population's.

    From a recipe, a pool of ``pool`` grains (default
    :func:`grainforge.dem.template_choice.pool_size`: 4 × templates, at least
    200, at most 2,000) evenly spread over its grains is generated and
    measured on ``workers`` processes; from files, the candidates of
    :func:`grainforge.dem.template_choice.choose_files` (a manifest's measures,
    or a pool of files measured). Then
    :func:`grainforge.dem.representative.choose_representative` picks the
    templates (seed :data:`~grainforge.dem.template_choice.CHOICE_SEED`). With
    ``settings.size`` every grain is scaled to one size: size is not matched.
    ``progress(done, total)`` is called after each grain measured.

    Parameters
    ----------
    inputs : sequence of path
        Mesh files, run folders, manifests (sizes in mm), or one TOML recipe.
    settings : Settings
        The runs' settings (``templates``; ``size``, mm, or None).
    pool : int, optional
        Grains generated or measured to choose from; default
        :func:`grainforge.dem.template_choice.pool_size`.
    workers : int
        Processes measuring the pool.
    progress : callable, optional
        ``progress(done, total)`` after each grain measured.

    Returns
    -------
    ChosenGrains
        The chosen grains, their descriptors and the choice's statistics.

    Raises
    ------
    ValueError
        For inputs that hold no grain or a recipe that cannot be read.
    """
    from ..dem.representative import choose_representative, descriptor_matrix
    from ..dem.template_choice import CHOICE_SEED, choose_files, pool_size, pool_workers, spread

    k = settings.templates
    paths = [Path(p) for p in inputs]
    if _is_recipe(paths):
        from ..population import load_recipe
        from ..runtime.workers import ordered_map

        recipe = load_recipe(paths[0])
        n = recipe.count
        candidates = spread(n, pool_size(k, n) if pool is None else min(n, max(pool, k)))
        rows = []
        tasks = [(recipe, int(i)) for i in candidates]
        for done, row in enumerate(ordered_map(_recipe_descriptors, tasks, workers=pool_workers(workers, len(tasks)),
                                               preload=["grainforge.methods", "grainforge.analysis"]), start=1):
            rows.append(row)
            if progress is not None:
                progress(done, len(tasks))
        table = descriptor_matrix(rows)
        if settings.size is not None:
            table[:, -1] = settings.size
        choice = choose_representative(table, k, rng=CHOICE_SEED)
        picks = [int(i) for i in candidates[choice.indices]]
        return ChosenGrains(paths[0], picks, [f"{recipe.method}-{i:04d}" for i in picks],
                            [f"{paths[0]} grain {i}" for i in picks], table[choice.indices], choice, n, len(tasks))
    from ..io.inputs import mesh_paths

    files = mesh_paths(paths)
    chosen = choose_files(paths, files, k=k, workers=workers, progress=progress, pool=pool,
                          size=settings.size)
    names = [f"g{j:04d}-{f.stem}"[:60] for j, f in enumerate(chosen.paths)]
    return ChosenGrains(None, chosen.paths, names, [str(f) for f in chosen.paths], chosen.table, chosen.choice,
                        chosen.available, chosen.measured)


def check_inputs(inputs: Sequence[str | os.PathLike]) -> tuple[int, float]:
    """Cheap checks of the inputs before any work: a readable recipe, or paths that hold grain files.

    A recipe that ``grainforge batch`` would refuse as too large (its count
    beyond a day of computing, e.g. ``count = 2**63 - 1``) is refused too:
    the simulated grains stand for that population.

    Parameters
    ----------
    inputs : sequence of path
        Mesh files, run folders, manifests, or one TOML recipe.

    Returns
    -------
    (int, float)
        The grains available (files, or the recipe's count) and the seconds
        to make one (0 for files).

    Raises
    ------
    ValueError
        Naming the input that is missing, unreadable or holds no grain.
    """
    paths = [Path(p) for p in inputs]
    if _is_recipe(paths):
        from ..population import check_recipe_size, draw_grain, load_recipe
        from ..runtime.estimate import grain_seconds

        recipe = load_recipe(paths[0])
        check_recipe_size(recipe)
        return recipe.count, grain_seconds(recipe.method, draw_grain(recipe, 0)[1])
    from ..io.inputs import mesh_paths

    return len(mesh_paths(paths)), 0.0


def build_population(inputs: Sequence[str | os.PathLike], settings: Settings, *, as_spheres: bool = False,
                     progress: Callable[[int, int], None] | None = None, shape: str = "clump",
                     spacing: float = 0.05, chosen: ChosenGrains | None = None,
                     clump_accuracy: float | None = None) -> list:
    """Clump templates (:class:`grainforge.dem.template.GrainTemplate`) of the population.

    Parameters
    ----------
    inputs : sequence of path
        Mesh files, run folders, manifests (sizes in mm), or one TOML recipe
        (grains generated at the recipe's sizes). ``settings.templates`` of
        their grains are chosen by :func:`choose_grains` (representative of
        the population's shapes and sizes), unless ``chosen`` gives them.
    settings : Settings
        The runs' settings (``templates``, ``spheres``, ``size`` in mm or None).
    as_spheres : bool
        Replace every grain by its volume-equivalent sphere (the sphere
        baseline of a comparison: same sizes, same mass, no shape).
    progress : callable, optional
        Called as ``progress(done, total)`` after each template.
    shape : {"clump", "levelset"}
        The grains' contact geometry: clumps of ``settings.spheres`` spheres, or
        level sets (:func:`grainforge.dem.levelset.level_set`) of grid ``spacing``
        (a fraction of the equivalent diameter), as ``grainforge dem`` makes them.
    spacing : float
        Level sets only: the grid spacing, a fraction of each grain's equivalent diameter.
    clump_accuracy : float, optional
        Build every clump to this intersection over union with its grain
        (:func:`grainforge.dem.clump.clump`, ``target_iou``), with at most
        ``settings.spheres`` spheres.
    chosen : ChosenGrains, optional
        The grains to make into templates, from :func:`choose_grains`.

    Returns
    -------
    list of GrainTemplate
        One template per chosen grain, in the order of ``chosen``.

    Raises
    ------
    ValueError
        For inputs that hold no grain, a recipe that cannot be read, or a mesh
        that is not a valid solid (named).
    """
    if chosen is None:
        chosen = choose_grains(inputs, settings)
    items = []
    if chosen.recipe is not None:
        from ..population import load_recipe

        recipe = load_recipe(chosen.recipe)
        for i, name, source in zip(chosen.picks, chosen.names, chosen.sources):
            items.append((*_recipe_mesh(recipe, i), name, source))
    else:
        from ..dem.inputs import read_grain

        for f, name, source in zip(chosen.picks, chosen.names, chosen.sources):
            items.append((*read_grain(f), name, source))
    out = []
    for k, (v, f, name, source) in enumerate(items):
        if settings.size is not None:
            v = _scaled_to(v, f, settings.size)
        out.append(_template((v, f, name, settings, source, k, as_spheres, shape, spacing, clump_accuracy)))
        if progress is not None:
            progress(k + 1, len(items))
    return out
