"""What ``grainforge simulate`` can run: the engines, the grain representations each engine's scenes take, per
test, and why a test refuses one its engine has (pure data and one check; the command line offers and refuses
from these)."""

from __future__ import annotations

from ..errors import InputError

__all__ = ["TILT_ONLY", "ENGINES", "SHAPES", "RUNS", "TEST_RUNS", "TEST_SHAPE_WHY", "MPI_ENGINES", "ENGINE_NAMES",
           "check_engine"]

#: settings only the tilt test reads: not offered by `simulate repose`
TILT_ONLY = ("tilt_step", "tilt_start")
#: engines and grain representations the options name (the DEM decks' ones, grainforge dem)
ENGINES = ("yade", "liggghts")
#: representations the scenes run (Yade: both; LIGGGHTS: clumps). Polyhedra are `grainforge dem`'s only:
#: neither engine's scenes take them, so --help does not offer them
SHAPES = ("clump", "levelset")
#: what simulate's scenes can run, per engine
RUNS = {"yade": ("clump", "levelset"), "liggghts": ("clump",)}
#: what a test's scenes run where it differs from RUNS: the triaxial scenes take clumps only
TEST_RUNS = {"triaxial": {"yade": ("clump",), "liggghts": ("clump",)}}
#: why a test refuses a representation its engine has, by (test, engine, shape), said in the refusal: Yade's
#: level-set contact gains kinetic energy in a frictionless collision (benchmarks/levelset_energy.py), so a
#: level-set specimen heats up in the frictionless compaction instead of coming to rest (docs/simulate.md)
TEST_SHAPE_WHY = {("triaxial", "yade", "levelset"): "Yade's level-set contact gains energy in a frictionless "
                                                    "collision, a grain pair parting with 20 times its kinetic "
                                                    "energy: a specimen never comes to rest at the confining "
                                                    "stress; docs/simulate.md"}
#: engines simulate runs under mpirun (--mpi)
MPI_ENGINES = ("liggghts",)
#: the engines' names in progress bars
ENGINE_NAMES = {"yade": "Yade", "liggghts": "LIGGGHTS"}



def check_engine(engine: str, mpi: int | None, shape: str, test: str | None = None) -> None:
    """Refuse an engine/representation/MPI combination the scenes cannot run (one line, before any work).

    Parameters
    ----------
    engine : {"yade", "liggghts"}
        The engine.
    mpi : int or None
        MPI ranks asked for (None: not under mpirun).
    shape : {"clump", "levelset"}
        The grains' representation.
    test : {"repose", "tilt", "triaxial"}, optional
        The test whose scenes run (:data:`TEST_RUNS`); None: any gravity test.

    Raises
    ------
    ValueError
        For an engine with no scene for the test, MPI ranks with an engine that does not run under MPI, or a
        representation the engine's scenes cannot take (whether the engine is installed is checked elsewhere).

    Examples
    --------
    >>> check_engine("liggghts", 2, "clump", "triaxial")
    >>> check_engine("yade", None, "levelset", "triaxial")
    Traceback (most recent call last):
    ...
    grainforge.errors.InputError: shape levelset: simulate triaxial's yade scene takes shape clump only (Yade's level-set contact gains energy in a frictionless collision, a grain pair parting with 20 times its kinetic energy: a specimen never comes to rest at the confining stress; docs/simulate.md)
    """
    runs = TEST_RUNS.get(test, RUNS)
    if not runs[engine]:
        what = f"simulate {test}" if test in TEST_RUNS else "simulate"
        raise InputError(f"{{engine}} {engine}: {what} has no {engine} scene yet (grainforge dem "
                         f"--engine {engine} writes a pour deck); use {{engine}} yade", setting="engine")
    if mpi is not None and engine not in MPI_ENGINES:
        raise InputError(f"{{mpi}}: {engine} runs one process per seed here, not under mpirun; "
                         "use {workers} for runs at once (or {engine} liggghts {mpi} N)",
                         setting=("mpi", "workers", "engine"))
    if shape not in runs[engine]:
        what = f"simulate {test}'s {engine} scene takes" if test in TEST_RUNS else f"simulate's {engine} scenes take"
        why = TEST_SHAPE_WHY.get((test, engine, shape))
        raise InputError(f"{{shape}} {shape}: {what} "
                         f"{', '.join('{shape} ' + s for s in runs[engine])} only ("
                         + (why or f"grainforge dem --shape {shape} writes the deck") + ")", setting="shape")
