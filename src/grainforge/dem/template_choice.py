"""Representative templates of grain files: their descriptors (a manifest's, or measured), the choice, templates.csv.

``grainforge dem --templates K`` and ``grainforge simulate --templates K``
choose K grains with :func:`grainforge.dem.representative.choose_representative`
from the descriptors of a pool of candidates. The descriptors are the
project's standard mesh measures (:func:`grainforge.analysis.basic_descriptors`,
the columns every manifest carries): Wadell sphericity, convexity V/V_hull,
the minimum-volume box's L ≥ I ≥ S (elongation I/L, flatness S/I, as
``grainforge analyse``) and the equivalent diameter. Files listed in a
manifest among the inputs take the manifest's values (nothing is measured);
other files are read and measured, at most :func:`pool_size` of them.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from .representative import DESCRIPTORS, TemplateChoice, choose_representative, descriptor_matrix

__all__ = ["POOL_FACTOR", "POOL_MIN", "POOL_MAX", "MAX_CANDIDATES", "MEASURE_SECONDS", "TEMPLATES_CSV",
           "CHOICE_SEED", "pool_size", "pool_workers", "spread", "mesh_descriptors", "manifest_descriptors", "ChosenFiles",
           "files_to_measure", "choose_files", "write_templates_csv", "write_chosen_templates"]

#: a pool of candidates to measure (grains to generate, files without manifest values): POOL_FACTOR × K grains,
#: at least POOL_MIN, at most POOL_MAX (or K when K is larger: then every pooled grain is taken)
POOL_FACTOR, POOL_MIN, POOL_MAX = 4, 200, 2000
#: files with a manifest's descriptors are all candidates, up to this many (evenly spaced beyond)
MAX_CANDIDATES = 20_000
#: grains a measuring worker process gets at least (fewer: measured in this process)
MIN_PER_WORKER = 10
#: seconds to read and measure one grain of about 20,000 faces (basic_descriptors: 0.02-0.03 s; reading 0.02-0.03 s)
MEASURE_SECONDS = 0.06
#: the file of the chosen grains' names, descriptors and KS figures, in the output folder
TEMPLATES_CSV = "templates.csv"
#: seed of the choice's random starts: the same inputs and K give the same templates in every run
CHOICE_SEED = 0


def pool_size(k: int, available: int) -> int:
    """Candidates to measure for ``k`` templates out of ``available`` grains.

    Parameters
    ----------
    k : int
        Templates wanted.
    available : int
        Grains the inputs hold.

    Returns
    -------
    int
        :data:`POOL_FACTOR` × ``k``, at least :data:`POOL_MIN`, at most :data:`POOL_MAX` (or ``k`` when
        larger), and never more than ``available``.

    Examples
    --------
    >>> pool_size(40, 500), pool_size(6, 500), pool_size(600, 10_000), pool_size(3000, 10_000), pool_size(40, 90)
    (200, 200, 2000, 3000, 90)
    """
    return int(min(available, max(k, min(max(POOL_FACTOR * k, POOL_MIN), POOL_MAX))))


def pool_workers(workers: int, grains: int) -> int:
    """Processes to measure ``grains`` on: one (this process) below :data:`MIN_PER_WORKER` grains a worker,
    where starting the processes costs more than it saves.

    Parameters
    ----------
    workers : int
        Processes the caller allows.
    grains : int
        Grains to measure.

    Returns
    -------
    int
        Between 1 and ``workers``.

    Examples
    --------
    >>> pool_workers(8, 10), pool_workers(8, 200), pool_workers(2, 200)
    (1, 8, 2)
    """
    return max(1, min(int(workers), grains // MIN_PER_WORKER))


def spread(n: int, m: int) -> np.ndarray:
    """``m`` indices evenly spread over ``range(n)`` (all of them when ``m >= n``), ascending.

    Parameters
    ----------
    n : int
        Items to pick from.
    m : int
        Items wanted: the middle index of each of ``m`` equal parts of ``range(n)``.

    Returns
    -------
    (min(m, n),) int64
        Distinct indices, ascending.

    Examples
    --------
    >>> spread(10, 4).tolist(), spread(3, 5).tolist()
    ([1, 3, 6, 8], [0, 1, 2])
    """
    if m >= n:
        return np.arange(n, dtype=np.int64)
    return ((np.arange(m) + 0.5) * n / m).astype(np.int64)


def mesh_descriptors(vertices, faces) -> dict[str, float]:
    """The five descriptors of one closed mesh (size: its equivalent diameter, in the mesh's unit).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Mesh vertices (any length unit).
    faces : (F, 3) array_like of int
        A closed, outward-oriented triangle mesh.

    Returns
    -------
    dict of str to float
        ``sphericity`` (Wadell), ``convexity`` (V / V_hull), ``flatness`` (S/I), ``elongation`` (I/L) of the
        minimum-volume box's sides L ≥ I ≥ S, and ``size`` (the equivalent diameter).

    Examples
    --------
    >>> import trimesh
    >>> box = trimesh.creation.box(extents=(4.0, 2.0, 1.0))
    >>> {k: round(v, 3) for k, v in mesh_descriptors(box.vertices, box.faces).items()}
    {'sphericity': 0.691, 'convexity': 1.0, 'flatness': 0.5, 'elongation': 0.5, 'size': 2.481}
    """
    from types import SimpleNamespace

    from ..analysis import basic_descriptors

    d = basic_descriptors(SimpleNamespace(vertices=vertices, faces=faces))
    return _from_basic(d)


def _from_basic(d: Mapping[str, float]) -> dict[str, float]:
    L, I, S = float(d["L"]), float(d["I"]), float(d["S"])
    return {"sphericity": float(d["sphericity"]), "convexity": float(d["convexity"]),
            "flatness": S / I if I > 0 else 0.0, "elongation": I / L if L > 0 else 0.0,
            "size": float(d["equivalent_diameter"])}


def _manifest_rows(manifest: Path) -> dict[Path, dict[str, float]]:
    from ..io.inputs import read_manifest
    from ..units import plain

    try:
        rows = read_manifest(manifest, require=("file",))
    except ValueError:
        return {}
    out = {}
    for row in rows:
        row = {plain(k): v for k, v in row.items() if k is not None}
        try:
            out[(manifest.parent / row["file"]).resolve()] = _from_basic(
                {k: float(row[k]) for k in ("sphericity", "convexity", "L", "I", "S", "equivalent_diameter")})
        except (KeyError, TypeError, ValueError):
            continue  # a row without the measures: its file is measured
    return out


def manifest_descriptors(inputs: Iterable[str | os.PathLike]) -> dict[Path, dict[str, float]]:
    """Resolved file path -> descriptors, from every manifest among ``inputs`` (folders' or named ``.csv``).

    Rows without the measured columns are left out (those files are measured).

    Parameters
    ----------
    inputs : iterable of str or path
        The command's inputs: a folder's ``manifest.csv`` is read, a ``.csv`` is read as a manifest,
        anything else is skipped (as is a manifest that cannot be read).

    Returns
    -------
    dict of Path to dict
        Each listed file (resolved, relative to its manifest's folder) -> its five descriptors
        (as :func:`mesh_descriptors`; the size in the grain files' length unit, as the manifest gives it).
    """
    out: dict[Path, dict[str, float]] = {}
    for p in map(Path, inputs):
        manifest = p / "manifest.csv" if p.is_dir() else p if p.suffix.lower() == ".csv" else None
        if manifest is not None and manifest.is_file():
            out.update(_manifest_rows(manifest))
    return out


def _measure_file(path):
    """A candidate's descriptors, read and checked as a template is (:func:`~grainforge.dem.inputs.read_grain`):
    a file that is not one solid is named now, before its descriptors could sway the choice."""
    from .inputs import read_grain

    v, f = read_grain(path)
    return mesh_descriptors(v, f)


@dataclass(frozen=True)
class ChosenFiles:
    """The files chosen as templates (in input order), their descriptors and the choice."""

    paths: list
    table: np.ndarray
    choice: TemplateChoice
    available: int
    measured: int

    def summary(self, k: int) -> str:
        """The one line the commands print: what was chosen from what, and the KS figures.

        Parameters
        ----------
        k : int
            The templates asked for (``--templates``).

        Returns
        -------
        str
            ``templates: 40 of 500 grains, 200 measured; KS against them: sphericity 0.040, ...
            (largest 0.050)``, or the line saying every candidate was taken.
        """
        return _summary(self.choice, k, self.available, self.measured)


def _summary(choice: TemplateChoice, k: int, available: int, measured: int) -> str:
    """``templates: 40 of 500 grains (200 measured); KS against them: sphericity 0.040, ... (largest 0.050)``."""
    n = choice.candidates
    if not choice.selected:
        if n == available:
            return f"templates: all {available} grains ({k} asked): no selection"
        return f"templates: {n} grains evenly spread over the {available}: no selection ({k} asked)"
    of = f"{n} grains" if n == available else f"{n} candidates evenly spread over {available} grains"
    how = f", {measured} measured" if measured else ", descriptors from the manifest"
    figures = ", ".join(f"{name} {value:.3f}" for name, value in choice.ks.items())
    return (f"templates: {len(choice.indices)} of {of}{how}; KS against them: {figures} "
            f"(largest {choice.largest_ks:.3f})")


def _candidates(inputs, paths: Sequence[Path], k: int, pool: int | None):
    """(candidate indices, manifest descriptors, resolved paths, indices to measure)."""
    known = manifest_descriptors(inputs)
    resolved = [p.resolve() for p in paths]
    n = len(paths)
    if all(r in known for r in resolved):
        candidates = spread(n, max(k, MAX_CANDIDATES))
    else:
        candidates = spread(n, pool_size(k, n) if pool is None else min(n, max(pool, k)))
    todo = [int(i) for i in candidates if resolved[i] not in known]
    return candidates, known, resolved, todo


def files_to_measure(inputs: Sequence[str | os.PathLike], paths: Sequence[Path], k: int,
                     pool: int | None = None) -> int:
    """How many files :func:`choose_files` will read and measure (for the commands' estimates).

    Parameters
    ----------
    inputs : sequence of str or path
        The command's inputs (their manifests give descriptors).
    paths : sequence of Path
        The grain files resolved from ``inputs``.
    k : int
        Templates wanted.
    pool : int, optional
        Candidates to draw from (default :func:`pool_size`).

    Returns
    -------
    int
        Candidate files without a manifest's descriptors.

    Examples
    --------
    >>> import tempfile, trimesh
    >>> with tempfile.TemporaryDirectory() as d:
    ...     files = [Path(d) / f"g{i}.stl" for i in range(3)]
    ...     for f in files:
    ...         _ = trimesh.creation.icosphere(subdivisions=1).export(f)
    ...     files_to_measure([d], files, 2)
    3
    """
    return len(_candidates(inputs, list(paths), k, pool)[3])


def choose_files(inputs: Sequence[str | os.PathLike], paths: Sequence[Path], *, k: int, workers: int = 1,
                 progress: Callable[[int, int], None] | None = None, pool: int | None = None,
                 size: float | None = None) -> ChosenFiles:
    """Choose ``k`` of ``paths`` (resolved from ``inputs`` by :func:`~grainforge.io.inputs.mesh_paths`).

    Candidates are every file when a manifest among the inputs gives them all
    (up to :data:`MAX_CANDIDATES`), else ``pool`` (default :func:`pool_size`)
    files evenly spread over the list; those a manifest does not give are read
    and measured on ``workers`` processes, ``progress(done, total)`` after each.
    With ``size``, every grain is to be scaled to it: sizes are not matched
    (the table's sizes are ``size``).

    The choice is :func:`grainforge.dem.representative.choose_representative` with ``rng=CHOICE_SEED``:
    the same inputs and ``k`` give the same templates in every run.

    Parameters
    ----------
    inputs : sequence of str or path
        The command's inputs (their manifests give descriptors).
    paths : sequence of Path
        The grain files resolved from ``inputs``, in input order.
    k : int
        Templates wanted (≥ 1).
    workers : int
        Processes measuring the files.
    progress : callable, optional
        Called as ``progress(done, total)`` after each file measured.
    pool : int, optional
        Candidates when some must be measured (default :func:`pool_size`; at least ``k``).
    size : float, optional
        The one size every grain is scaled to (the table's size column), in the grain files' length unit.

    Returns
    -------
    ChosenFiles
        The chosen files in input order, their descriptors, the choice and the counts of files
        available and measured.

    Raises
    ------
    ValueError
        For ``k < 1``, or a file that cannot be read (named).
    """
    if k < 1:
        raise InputError(f"{{templates}} must be at least 1, got {k}", setting="templates")
    paths = list(paths)
    candidates, known, resolved, todo = _candidates(inputs, paths, k, pool)
    measured = {}
    if todo:
        from ..runtime.workers import ordered_map

        for n, (i, d) in enumerate(zip(todo, ordered_map(_measure_file, [paths[i] for i in todo],
                                                          workers=pool_workers(workers, len(todo)),
                                                          preload=["grainforge.analysis"])), start=1):
            measured[i] = d
            if progress is not None:
                progress(n, len(todo))
    rows = [measured[int(i)] if int(i) in measured else known[resolved[int(i)]] for i in candidates]
    table = descriptor_matrix(rows)
    if size is not None:
        table[:, -1] = size
    choice = choose_representative(table, k, rng=CHOICE_SEED)
    picked = candidates[choice.indices]
    return ChosenFiles([paths[int(i)] for i in picked], table[choice.indices], choice, len(paths), len(todo))


def write_templates_csv(path: str | os.PathLike, *, names: Sequence[str], sources: Sequence[str],
                        table: np.ndarray, choice: TemplateChoice) -> Path:
    """``templates.csv``: one row per chosen grain (name, source, the five descriptors, size in mm), then a row
    ``KS`` holding each descriptor's two-sample KS statistic of the chosen grains against all candidates.

    Parameters
    ----------
    path : str or path
        The file written (replaced if it exists).
    names : sequence of str
        The chosen grains' template names, one per row of ``table``.
    sources : sequence of str
        Their files.
    table : (K, 5) float64
        Their descriptors (:data:`~grainforge.dem.representative.DESCRIPTORS`), the size in mm.
    choice : TemplateChoice
        The choice (its KS figures and candidate count make the last row).

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import tempfile
    >>> t = np.array([[0.9, 0.95, 0.7, 0.6, 0.5], [0.8, 0.9, 0.6, 0.5, 0.6]])
    >>> c = choose_representative(t, 1)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     out = write_templates_csv(Path(d) / "t.csv", names=["a"], sources=["a.stl"], table=t[c.indices], choice=c)
    ...     lines = out.read_text().splitlines()
    >>> lines[0]
    'template,source,sphericity,convexity,flatness,elongation,size_mm'
    >>> lines[-1].split(",")[:2]
    ['KS', 'chosen 1 vs 2 candidates']
    """
    path = Path(path)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["template", "source", *DESCRIPTORS[:-1], "size_mm"])
        for name, source, row in zip(names, sources, table):
            w.writerow([name, source, *(f"{x:.6g}" for x in row)])
        label = (f"chosen {len(choice.indices)} vs {choice.candidates} candidates" if choice.selected
                 else f"all {choice.candidates} candidates taken")
        w.writerow(["KS", label, *(f"{choice.ks[d]:.4f}" for d in DESCRIPTORS)])
    return path


def write_chosen_templates(folder: str | os.PathLike, chosen: ChosenFiles, unit: float) -> Path:
    """``templates.csv`` (:data:`TEMPLATES_CSV`) in a deck's folder: the chosen grains under their deck names.

    Parameters
    ----------
    folder : str or path
        The deck's folder.
    chosen : ChosenFiles
        The grains chosen (:func:`choose_files`), their sizes in file units.
    unit : float
        Metres per file unit; the sizes are written in mm.

    Returns
    -------
    Path
        The file written (:func:`write_templates_csv`).
    """
    from .inputs import _unique_names

    table = chosen.table.copy()
    table[:, -1] *= unit * 1e3
    return write_templates_csv(Path(folder) / TEMPLATES_CSV, names=_unique_names(chosen.paths),
                               sources=[str(p) for p in chosen.paths], table=table, choice=chosen.choice)
