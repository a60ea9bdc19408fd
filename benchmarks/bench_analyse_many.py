"""``grainforge analyse`` on many grain files: the μCT-study case (a whole scanned population at once).

Target: 1,000 grains of 20,000 faces (FSO, icosphere level 5: 20,480 faces) with every
descriptor, the fractal dimension included, in ≤ 60 s on the project machine's 2 cores.

Makes the grain files once (``--cache``, default ``benchmarks/out/analyse-many``), then runs
``analyse_files`` — what ``grainforge analyse FOLDER --workers N`` runs — and prints wall time,
CPU time (this process and its workers) and the per-grain rates, with the load average.
A run on fewer grains (``--count 200``) extrapolates linearly (the work is per file).

Usage: ``python benchmarks/bench_analyse_many.py [--count 1000] [--workers 2]``
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path


def make_grains(folder: Path, count: int) -> list[Path]:
    from grainforge.methods import get
    from grainforge.population.generate import grain_file_name, write_run

    names = [folder / grain_file_name("fso", i, "stl") for i in range(count)]
    if not all(p.is_file() for p in names):
        t = time.perf_counter()
        write_run("fso", get("fso").Params(subdivisions=5), seeds=range(count), out=folder, overwrite=True)
        print(f"made {count} grain files in {time.perf_counter() - t:.1f} s")
    return names


def cpu_seconds() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF)
    return own.ru_utime + own.ru_stime


def timed_analyse(path: str):
    """``analyse_file`` with every descriptor, and the CPU seconds it took in its worker."""
    from grainforge.analysis.measure import analyse_file

    c = time.process_time()
    rows = analyse_file(path, fractal=True, fourier=True)
    return rows, time.process_time() - c


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=Path(__file__).parent / "out" / "analyse-many")
    args = ap.parse_args()

    from grainforge.analysis.measure import PRELOAD
    from grainforge.runtime.workers import ordered_map

    files = make_grains(args.cache, args.count)
    load0 = os.getloadavg()
    t, c = time.perf_counter(), cpu_seconds()
    rows = 0
    worker_cpu = 0.0
    # the same pool and task as analyse_files (grainforge analyse), timed per file in the worker
    for file_rows, cpu_file in ordered_map(timed_analyse, map(str, files), workers=args.workers, preload=PRELOAD):
        rows += len(file_rows)
        worker_cpu += cpu_file
    main_cpu = cpu_seconds() - c
    wall, cpu = time.perf_counter() - t, main_cpu + worker_cpu
    load1 = os.getloadavg()
    print(f"analyse: {rows} rows from {len(files)} files ({args.workers} workers), 20,480 faces each")
    print(f"  wall {wall:.1f} s ({wall / len(files) * 1e3:.0f} ms/grain); "
          f"CPU {cpu:.1f} s ({cpu / len(files) * 1e3:.0f} ms/grain, workers included: "
          f"{worker_cpu / len(files) * 1e3:.0f} ms in analyse_file, {main_cpu / len(files) * 1e3:.0f} ms in this process)")
    print(f"  extrapolated to 1,000 grains: wall {wall / len(files) * 1000:.0f} s, "
          f"CPU {cpu / len(files) * 1000:.0f} s (= {cpu / len(files) * 1000 / args.workers:.0f} s "
          f"on {args.workers} idle cores)")
    print(f"  load average {load0[0]:.2f} before, {load1[0]:.2f} after, on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
