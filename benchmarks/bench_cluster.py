"""``analyse``, ``fit`` and ``simulate`` on a Dask cluster (``--scheduler``): 1 vs 2 workers of a LocalCluster,
against the local run (``analyse`` and ``fit`` in this process, ``simulate`` as the command with ``--workers 1``).

Each Dask run goes through what the commands run (:func:`grainforge.analysis.measure.analyse_files` and
:func:`grainforge.fit.fit_sand` with a :class:`grainforge.runtime.cluster.DaskExecutor`); the script checks that
every run's output is byte-identical to the local one and prints a table of wall times, with the load
average (the project machine is shared: read the 2-worker speed-up against it).

``simulate`` is a ``--quick`` tilt sweep of ``--seeds`` seeds (one Yade run each) run as the command, its
``results.csv`` compared.

Usage: ``python benchmarks/bench_cluster.py [--files 40] [--twins 20] [--seeds 2]``
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

RF_SAND = Path(__file__).resolve().parents[1] / "tests" / "data" / "synthetic-rf-sand.csv"


def make_grains(folder: Path, count: int) -> list[Path]:
    from grainforge.methods import get
    from grainforge.population.generate import grain_file_name, write_run

    names = [folder / grain_file_name("fso", i, "stl") for i in range(count)]
    if not all(p.is_file() for p in names):
        write_run("fso", get("fso").Params(subdivisions=4), seeds=range(count), out=folder, overwrite=True)
    return names


def analyse(files, executor=None) -> tuple[float, str]:
    """Wall seconds and the CSV text of ``analyse FILES --csv`` (every descriptor)."""
    from grainforge.analysis.measure import ANALYSE_COLUMNS, analyse_files
    from grainforge.io import csv_text

    t = time.perf_counter()
    rows = [r for file_rows in analyse_files(files, workers=executor.workers if executor else 1,
                                             executor=executor, fractal=True, fourier=True) for r in file_rows]
    return time.perf_counter() - t, csv_text(rows, ANALYSE_COLUMNS(True, atlas=False), units=True)


def fit(twins: int, executor=None) -> tuple[float, dict[str, bytes]]:
    """Wall seconds and the four outputs' bytes of a small rf fit (its design measured afresh)."""
    from grainforge.fit import fit_sand, read_sand, write_outputs

    sand = read_sand(RF_SAND)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        result = fit_sand(sand, "rf", count=twins, refine=1, reseed=1, design_grains=50, population_grains=10,
                          population_slopes="model", max_across=12.0, cache=Path(tmp) / "cache", workers=1,
                          executor=executor)
        seconds = time.perf_counter() - t
        paths = write_outputs(sand, result, Path(tmp) / "out")
        return seconds, {p.name: p.read_bytes() for p in paths}


def simulate(grains: Path, seeds: int, address: str | None = None) -> tuple[float, bytes]:
    """Wall seconds and ``results.csv`` of ``grainforge simulate tilt GRAINS --quick --seeds N`` (one Yade run a
    seed), on this machine with ``--workers 1`` or on the cluster at ``address``."""
    import subprocess
    import sys

    exe = str(Path(sys.executable).with_name("grainforge"))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "o"
        where = ["--scheduler", address] if address else ["--workers", "1"]
        t = time.perf_counter()
        r = subprocess.run([exe, "simulate", "tilt", str(grains), "--quick", "--seeds", str(seeds), "--out", str(out),
                            *where], capture_output=True, text=True)
        seconds = time.perf_counter() - t
        if r.returncode not in (0, 3):
            raise SystemExit(f"simulate failed ({r.returncode}): {r.stderr.strip()}")
        return seconds, (out / "results.csv").read_bytes()


def warm() -> bool:
    """Import what the tasks use (untimed: a long run pays it once per worker)."""
    import importlib

    for name in ("grainforge.fit", "grainforge.analysis.measure", "grainforge.analysis.atlas", "grainforge.methods.rf",
                 "grainforge.methods.fso", "grainforge.population", "skimage.measure", "scipy.ndimage", "trimesh"):
        importlib.import_module(name)
    return True


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--files", type=int, default=40)
    ap.add_argument("--twins", type=int, default=20)
    ap.add_argument("--seeds", type=int, default=2, help="seeds of the quick simulate sweep (0: none)")
    ap.add_argument("--cache", type=Path, default=Path(__file__).parent / "out" / "cluster-grains")
    args = ap.parse_args()

    import distributed

    from grainforge.runtime.cluster import dask_executor

    files = make_grains(args.cache, args.files)
    angular = args.cache / "angular"
    if args.seeds and not (angular / "manifest.csv").is_file():
        from grainforge.methods import get
        from grainforge.population.generate import write_run

        write_run("angular", get("angular").Params(subdivisions=3), seeds=range(3), out=angular, size=2.0,
                  overwrite=True)
    warm()
    load0 = os.getloadavg()
    rows = []
    a_local, csv_local = analyse(files)
    f_local, out_local = fit(args.twins)
    s_local, sim_local = simulate(angular, args.seeds) if args.seeds else (float("nan"), b"")
    rows.append(("local (simulate: --workers 1)", a_local, f_local, s_local, "reference"))
    for n in (1, 2):
        with distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                      silence_logs=40) as cluster:
            with dask_executor(cluster.scheduler_address) as ex:
                ex.client.run(warm)
                a, csv = analyse(files, ex)
                f, out = fit(args.twins, ex)
            sim_s, sim = simulate(angular, args.seeds, cluster.scheduler_address) if args.seeds else (float("nan"), b"")
        same = csv == csv_local and out == out_local and sim == sim_local
        rows.append((f"Dask LocalCluster, {n} worker(s)", a, f, sim_s, "yes" if same else "NO"))
    load1 = os.getloadavg()
    print(f"analyse {args.files} FSO grains (5,120 faces, every descriptor); fit: rf, {args.twins} twins, "
          f"50 design grains, 12 voxels across; simulate: tilt --quick, {args.seeds} seed(s)")
    print("| run | analyse (s) | fit (s) | simulate (s) | byte-identical to local |")
    print("|---|---|---|---|---|")
    for name, a, f, sim_s, same in rows:
        print(f"| {name} | {a:.1f} | {f:.1f} | {sim_s:.1f} | {same} |")
    print(f"load average (1, 5, 15 min): before {load0[0]:.1f} {load0[1]:.1f} {load0[2]:.1f}, "
          f"after {load1[0]:.1f} {load1[1]:.1f} {load1[2]:.1f}; {os.cpu_count()} cores")
    if any(r[-1] == "NO" for r in rows):
        raise SystemExit("a Dask run's output differs from the local run's")


if __name__ == "__main__":
    main()
