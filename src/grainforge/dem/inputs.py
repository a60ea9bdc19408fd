"""Grain files to templates: resolve inputs (files, run folders, manifests), prepare in parallel."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..rng import RNGLike, as_generator
from .enclosure import enclosure_problems

__all__ = [
    "template_seconds",
    "GRAIN_SIZE_RANGE",
    "MIN_GRAIN_SIZE",
    "read_grain",
    "load_template",
    "build_templates",
    "check_level_set_files",
    "enclosure_problems",
    "pour_counts",
    "pour_copies",
    "MAX_POUR_GRAINS",
]

#: equivalent diameters (m) a deck accepts: 10 µm (fine silt; below, contact time steps and the engines'
#: absolute tolerances leave SI units) to 10 m (boulders)
GRAIN_SIZE_RANGE = (1e-5, 10.0)
#: a larger smallest size where an engine's representation needs one: Yade's polyhedra (CGAL,
#: absolute tolerances) crashed the engine ("malloc_consolidate(): unaligned fastbin chunk") at
#: 12 µm and settled at 20 µm
MIN_GRAIN_SIZE = {("yade", "polyhedron"): 2e-5}

#: the most grains an example pour holds (the LIGGGHTS deck inserts each grain by its own fix,
#: and every deck places them on a lattice above the box: far beyond this is no example pour)
MAX_POUR_GRAINS = 100_000


def template_seconds(shape: str, *, spheres: int = 30, refine_iterations: int = 0, spacing: float = 0.05,
                     accuracy: bool = False) -> float:
    """Rough upper bound of the seconds one grain's DEM template takes on one core.

    Parameters
    ----------
    shape : str
        ``"clump"``, ``"polyhedron"`` or ``"levelset"``.
    spheres, refine_iterations, spacing
        As :func:`grainforge.runtime.estimate.dem_template_seconds`.
    accuracy : bool
        A clump built to an accuracy target: the bisection's measures of the greedy prefixes
        (:func:`grainforge.dem.clump.accuracy_measures`) are added.

    Returns
    -------
    float
        Seconds.

    Examples
    --------
    >>> template_seconds("clump", spheres=40, accuracy=True) > template_seconds("clump", spheres=40)
    True
    """
    from ..runtime.estimate import dem_template_seconds

    each = dem_template_seconds(shape, spheres=spheres, refine_iterations=refine_iterations, spacing=spacing)
    if accuracy and shape == "clump":
        from .clump import ACCURACY_MEASURE_SECONDS, accuracy_measures

        each += ACCURACY_MEASURE_SECONDS * accuracy_measures(spheres)
    return each


def pour_counts(templates: int, grains: int, rng: RNGLike = 0) -> np.ndarray:
    """Copies of each of ``templates`` input grains in a pour of ``grains`` grains, in proportion.

    Every template is taken ``grains // templates`` times; the remaining
    ``grains % templates`` copies go to as many different templates drawn
    without replacement from ``rng``. The counts sum to ``grains``, differ by
    at most one, and are the same for the same arguments (an int ``rng``).

    Parameters
    ----------
    templates : int
        Input grains (templates) the pour draws from (≥ 1).
    grains : int
        Grains in the pour, 1 to :data:`MAX_POUR_GRAINS`.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        The draw of the remaining copies, normalised by :func:`grainforge.rng.as_generator`
        (``grainforge dem --seed``; default 0).

    Returns
    -------
    (templates,) int64
        Copies of each template, in input order.

    Raises
    ------
    ValueError
        If ``templates < 1``, ``grains`` is not in ``[1, MAX_POUR_GRAINS]``, or ``rng`` is not an accepted value.

    Examples
    --------
    >>> pour_counts(3, 7, rng=1).tolist()
    [2, 3, 2]
    >>> int(pour_counts(5, 2).sum()), int(pour_counts(5, 2).max())
    (2, 1)
    """
    if templates < 1:
        raise InputError(f"a pour needs at least one template, got {templates}")
    if not 1 <= grains <= MAX_POUR_GRAINS:
        raise InputError(f"a pour holds 1 to {MAX_POUR_GRAINS} grains, got {grains}")
    counts = np.full(templates, grains // templates, dtype=np.int64)
    extra = as_generator(rng).choice(templates, size=grains % templates, replace=False)
    counts[extra] += 1
    return counts


def pour_copies(templates: int, count: int = 1) -> list[int]:
    """Copies of each of ``templates`` input grains in a pour of ``count`` copies of each.

    Parameters
    ----------
    templates : int
        Input grains (templates).
    count : int
        Copies of each.

    Returns
    -------
    list of int
        ``count`` per template.

    Raises
    ------
    ValueError
        If the pour would hold more than :data:`MAX_POUR_GRAINS` grains.

    Examples
    --------
    >>> pour_copies(3, 2)
    [2, 2, 2]
    """
    if count * templates > MAX_POUR_GRAINS:
        raise InputError(f"{templates} grain files × {count} = {count * templates} grains; a pour "
                         f"holds at most {MAX_POUR_GRAINS}")
    return [count] * templates


def read_grain(path: str | Path, *, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a mesh file, vertices merged by position (as any reader sees it).

    With ``check`` the file is read and checked as ``analyse`` reads and flags it
    (:func:`grainforge.analysis.measure.solid_grain`): a file with a cavity, several or
    overlapping bodies, or a body that is open, inverted or not a solid (self-intersecting)
    is refused.  ``check=False`` only reads it (for a caller that checks the mesh itself);
    coordinates too far from the origin for float32 are refused either way
    (:func:`grainforge.io.read_mesh`).

    Parameters
    ----------
    path : str or path
        A mesh file (STL, OBJ, PLY, 3MF, ... as :func:`grainforge.io.read_mesh` reads), in its own unit.
    check : bool
        Refuse a mesh that is not one valid solid.

    Returns
    -------
    vertices : (V, 3) float64
        In the file's unit, merged by position.
    faces : (F, 3) int64

    Raises
    ------
    ValueError
        If the file is unreadable or (with ``check``) the mesh is not one valid solid; one line
        naming the file.
    """
    if check:
        from ..analysis.measure import solid_grain

        return solid_grain(path)  # sizes: checked in metres by the caller (dem --unit)
    from ..geometry.solid import unique_rows
    from ..io import read_mesh

    mesh = read_mesh(path)
    # merge by exact position (sorted by x, y, z, as np.unique(axis=0) would, several times faster)
    v, inv = unique_rows(np.ascontiguousarray(mesh.vertices, dtype=np.float64))
    f = inv[np.asarray(mesh.faces, dtype=np.int64)]
    return v, f


def load_template(path: str | Path, name: str, kwargs: dict):
    """Read and check ``path`` (:func:`read_grain`) and :func:`~grainforge.dem.template.prepare` it as
    ``name`` (mesh dropped).

    Parameters
    ----------
    path : str or path
        The grain's mesh file.
    name : str
        The template's name (its deck files' stem).
    kwargs : dict
        The options of :func:`~grainforge.dem.template.prepare` (``unit``, ``density``, ``shape``, ...).

    Returns
    -------
    GrainTemplate
        Without its mesh (:meth:`~grainforge.dem.template.GrainTemplate.without_mesh`); its ``source`` is ``path``.

    Raises
    ------
    ValueError
        If the file is unreadable or not one valid solid, or ``prepare`` refuses it.
    """
    from .template import prepare

    v, f = read_grain(path)
    return prepare(v, f, name=name, source=str(path), **kwargs).without_mesh()


def _unique_names(paths: Sequence[Path]) -> list[str]:
    seen: dict[str, int] = {}
    names = []
    for p in paths:
        stem = "".join(c if c.isalnum() or c in "-_." else "_" for c in p.stem)
        k = seen.get(stem, 0)
        seen[stem] = k + 1
        names.append(stem if k == 0 else f"{stem}_{k}")
    return names


def _load_one(args):
    return load_template(*args)


def build_templates(paths: Sequence[Path], *, workers: int = 1,
                    progress: Callable[[Iterable], Iterable] | None = None, counts: Sequence[int] | None = None,
                    **kwargs) -> list:
    """Templates of every grain file, in order (``kwargs`` go to ``prepare``).

    ``counts`` (one per path, e.g. from :func:`pour_counts`) sets each
    template's ``count`` and leaves out the paths counted 0; names are those
    of the full list either way. Runs on ``workers`` processes; the result does
    not depend on the count.

    Parameters
    ----------
    paths : sequence of Path
        The grains' mesh files; each template is named after its file's stem (made safe for file
        names, ``_1``, ``_2``, ... appended to repeated stems).
    workers : int
        Processes (1: this process; fewer than 4 grains are always made here).
    progress : callable, optional
        Wraps the iterable of finished templates (a progress bar), e.g. ``tqdm``.
    counts : sequence of int, optional
        Copies of each path's grain in the pour (0: left out); default: ``kwargs``' ``count``, or 1.
    **kwargs
        Options of :func:`~grainforge.dem.template.prepare` (``unit``, ``density``, ``shape``, ``spheres``, ...).

    Returns
    -------
    list of GrainTemplate
        In the order of ``paths`` (those counted 0 left out), without their meshes.

    Raises
    ------
    ValueError
        If ``counts`` and ``paths`` differ in length, or a grain file is refused (:func:`load_template`).
    """
    names = _unique_names(paths)
    if counts is None:
        tasks = [(p, n, kwargs) for p, n in zip(paths, names)]
    else:
        if len(counts) != len(paths):
            raise InputError(f"{len(counts)} counts for {len(paths)} grain files")
        tasks = [(p, n, {**kwargs, "count": int(c)}) for p, n, c in zip(paths, names, counts) if c > 0]
    wrap = progress or (lambda it: it)
    if workers <= 1 or len(tasks) < 4:
        return list(wrap(map(_load_one, tasks)))
    from ..runtime.workers import ordered_map

    # ordered_map stops its workers at once on an error or a signal (a pool's own shutdown
    # would first run every queued grain to its end)
    return list(wrap(ordered_map(_load_one, tasks, workers=workers, preload=["grainforge.dem.template",
                                                                      "grainforge.dem.clump"])))


def check_level_set_files(paths: Iterable[str | Path], *, unit: float, spacing: float) -> None:
    """Refuse, before any work, a grain file whose level set at ``spacing`` would exceed the node budget.

    Parameters
    ----------
    paths : iterable of path
        The grain files.
    unit : float
        Metres per file unit.
    spacing : float
        The grid spacing, as a fraction of the equivalent diameter.

    Raises
    ------
    ValueError
        :func:`grainforge.dem.template.check_level_set_budget`'s line, after the file's name.
    """
    from .template import check_level_set_budget

    for p in paths:
        v, f = read_grain(p, check=False)
        try:
            check_level_set_budget(v, f, unit=unit, spacing=spacing)
        except ValueError as exc:
            raise InputError(f"{p}: {exc}") from None
