"""The population of a virtual test: grain files or a recipe made into clump templates."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from .settings import Settings

__all__ = ["check_inputs", "build_population"]


def _sphere_mesh(d: float):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    scale = d / (6.0 * m.volume / math.pi) ** (1.0 / 3.0)
    return np.asarray(m.vertices) * scale, np.asarray(m.faces, dtype=np.int64)


def _template(args):
    from ..dem.template import prepare
    from ..solid import signed_volume

    vertices, faces, name, settings, source, k, as_spheres, shape, spacing, clump_accuracy = args
    if as_spheres:
        d = (6.0 * signed_volume(vertices, faces) / math.pi) ** (1.0 / 3.0)
        vertices, faces = _sphere_mesh(d)
        t = prepare(vertices, faces, name, unit=1e-3, density=settings.density, spheres=1, source=source, rng=k)
        # a sphere's clump is the sphere itself
        from ..dem.clump import Clump

        sphere = Clump(np.zeros((1, 3)), np.array([t.d_eq / 2.0]), 1.0, 0.0, t.clump.resolution)
        return replace(t, clump=sphere)
    return prepare(vertices, faces, name, unit=1e-3, density=settings.density, spheres=settings.spheres,
                   source=source, rng=k, shape=shape, levelset_spacing=spacing, target_iou=clump_accuracy)


def _scaled_to(vertices, faces, size):
    from ..solid import signed_volume

    d = (6.0 * signed_volume(vertices, faces) / math.pi) ** (1.0 / 3.0)
    return vertices * (size / d)


def _is_recipe(paths: Sequence[Path]) -> bool:
    return len(paths) == 1 and paths[0].suffix.lower() == ".toml"


def check_inputs(inputs: Sequence[str | os.PathLike]) -> tuple[int, float]:
    """Cheap checks of the inputs before any work: a readable recipe, or paths that hold grain files.

    A recipe that ``grainforge batch`` would refuse as too large (its count
    beyond a day of computing, e.g. ``count = 2**63 - 1``) is refused too:
    the simulated grains stand for that population.

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
        from ..estimate import grain_seconds
        from ..population import check_recipe_size, draw_grain, load_recipe

        recipe = load_recipe(paths[0])
        check_recipe_size(recipe)
        return recipe.count, grain_seconds(recipe.method, draw_grain(recipe, 0)[1])
    from ..dem.inputs import grain_paths

    return len(grain_paths(paths)), 0.0


def build_population(inputs: Sequence[str | os.PathLike], settings: Settings, *, as_spheres: bool = False,
                     progress: Callable[[int, int], None] | None = None, shape: str = "clump",
                     spacing: float = 0.05, clump_accuracy: float | None = None) -> list:
    """Clump templates (:class:`grainforge.dem.template.GrainTemplate`) of the population.

    Parameters
    ----------
    inputs : sequence of path
        Mesh files, run folders, manifests (sizes in mm), or one TOML recipe
        (its first ``settings.templates`` grains are generated, at the recipe's sizes).
    settings : Settings
    as_spheres : bool
        Replace every grain by its volume-equivalent sphere (the sphere
        baseline of a comparison: same sizes, same mass, no shape).
    progress : callable, optional
        Called as ``progress(done, total)`` after each template.
    shape : {"clump", "levelset"}
        The grains' contact geometry: clumps of ``settings.spheres`` spheres, or
        level sets (:func:`grainforge.dem.levelset.level_set`) of grid ``spacing``
        (a fraction of the equivalent diameter), as ``grainforge dem`` makes them.
    clump_accuracy : float, optional
        Build every clump to this intersection over union with its grain
        (:func:`grainforge.dem.clump.clump`, ``target_iou``), with at most
        ``settings.spheres`` spheres.

    Raises
    ------
    ValueError
        For inputs that hold no grain, a recipe that cannot be read, or a mesh
        that is not a valid solid (named).
    """
    items = []
    paths = [Path(p) for p in inputs]
    if _is_recipe(paths):
        from ..fabrication.scale import to_size
        from ..methods import generate
        from ..population import draw_grain, load_recipe

        recipe = load_recipe(paths[0])
        for i in range(min(settings.templates, recipe.count)):
            seed, params, size = draw_grain(recipe, i)
            g = to_size(generate(recipe.method, params, seed), size, recipe.size_definition)
            items.append((g.vertices, g.faces, f"{recipe.method}-{i:04d}", f"{paths[0]} grain {i}"))
    else:
        from ..dem.inputs import grain_paths, read_grain

        files = grain_paths(paths)
        step = max(1, len(files) // settings.templates) if len(files) > settings.templates else 1
        for k, f in enumerate(files[::step][: settings.templates]):
            v, fc = read_grain(f)
            items.append((v, fc, f"g{k:04d}-{f.stem}"[:60], str(f)))
    out = []
    for k, (v, f, name, source) in enumerate(items):
        if settings.size is not None:
            v = _scaled_to(v, f, settings.size)
        out.append(_template((v, f, name, settings, source, k, as_spheres, shape, spacing, clump_accuracy)))
        if progress is not None:
            progress(k + 1, len(items))
    return out
