"""Yade against LIGGGHTS at equal contact settings, and LIGGGHTS repose heaps under mpirun.

Three measurements, each printing one row per run set (angles per seed, mean ± sd, CPU and wall time):

``compare``
    The tilt test of volume-equivalent spheres (the paper's rough spheres made spheres) in both
    engines, at the same settings (k_n, k_s/k_n, μ, the damping of docs/simulate.md), one seed set.
``scaling``
    One LIGGGHTS repose heap of ``--grains`` on 1 and on 2 MPI ranks: wall and CPU time, and the
    CPU time per grain and step.
``heap``
    The repose heap of the three populations (spheres, rough spheres, rough angular) under
    ``mpirun -np --mpi``; also draws ``heap.png`` (each seed's angle and mean ± sd per population).
``figure``
    Draws ``heap.png`` again from the last ``heap.csv`` (``--figure`` copies it elsewhere too).

    .venv/bin/python benchmarks/bench_simulate_engines.py compare --grains 100 --seeds 3
    .venv/bin/python benchmarks/bench_simulate_engines.py scaling --grains 300
    .venv/bin/python benchmarks/bench_simulate_engines.py heap --grains 2000 --seeds 3 --mpi 2
    .venv/bin/python benchmarks/bench_simulate_engines.py figure --grains 2000 --mpi 2 \
        --figure docs/img/simulate-heap-liggghts.png

It writes out/bench-engines/<mode>-*/ (decks, results.csv, figure) and out/bench-engines/<mode>.csv.
CPU time: the engine processes' (children, MPI ranks included); the machine's load average is printed.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SPHERES = ("spheres", ROOT / "examples/paper-rough-spheres.toml", True)
POPULATIONS = [
    SPHERES,
    ("rough spheres (0, 0, 0.02)", ROOT / "examples/paper-rough-spheres.toml", False),
    ("rough angular (0.15, 0.10, 0.03)", ROOT / "examples/paper-rough-angular.toml", False),
]


def run_set(test, population, settings, out, engine, mpi=None, workers=1):
    """Run one population's seeds; its rows and (cpu s, wall s) of the engine runs."""
    from grainforge.simulate import build_population, run_test
    from grainforge.simulate.results import write_report

    label, recipe, as_spheres = population
    templates = build_population([recipe], settings, as_spheres=as_spheres)
    out.mkdir(parents=True, exist_ok=True)
    c0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.time()
    rows = run_test(test, templates, settings=settings, out=out, label=label, overwrite=True, workers=workers, engine=engine,
                    mpi=mpi)
    c1, t1 = resource.getrusage(resource.RUSAGE_CHILDREN), time.time()
    write_report(rows, out, test=test, settings=settings)
    return rows, (c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime, t1 - t0)


def row_text(name, rows, cpu, wall):
    from grainforge.simulate import summarise

    s = summarise(rows)
    angles = ", ".join(f"{r['angle_deg']:.1f}" for r in rows)
    return (f"{name:44s} {s['angle_mean_deg']:6.1f} {s['angle_sd_deg']:5.1f}  [{angles}]  {cpu:7.0f} {wall:7.0f}",
            {"set": name, "mean_deg": s["angle_mean_deg"], "sd_deg": s["angle_sd_deg"], "angles": angles,
             "cpu_s": cpu, "wall_s": wall, "steps_per_run": float(np.mean([r["steps"] for r in rows])),
             "cpu_us_per_grain_step": 1e6 * cpu / sum(r["grains"] * r["steps"] for r in rows)})


def heap_figure(table, args, paths) -> None:
    """Each population's angles of repose (one dot a seed) with their mean ± sd."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for i, rec in enumerate(table):
        angles = [float(a) for a in str(rec["angles"]).split(",")]
        mean, sd = float(rec["mean_deg"]), float(rec["sd_deg"])
        ax.errorbar(i, mean, yerr=sd, fmt="s", color="k", capsize=8, ms=7, zorder=3)
        ax.plot(i + np.linspace(-0.12, 0.12, len(angles)), angles, "o", color="tab:orange", zorder=4)
        ax.text(i + 0.2, mean, f"{mean:.1f}° ± {sd:.1f}°", va="center")
    ax.set_xticks(range(len(table)), [str(r["set"]).replace("repose, ", "").replace(" (", "\n(")
                                      for r in table])
    ax.set_xlim(-0.5, len(table) - 0.5)
    ax.set_ylabel("angle of repose (°)")
    ranks = f"mpirun -np {args.mpi}" if args.mpi else "1 process"
    ax.set_title(f"LIGGGHTS repose heaps of {args.grains} grains, {ranks}: one dot a seed, mean ± sd", fontsize=10)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    for path in paths:
        if path is not None:
            fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    from grainforge.io import write_csv
    from grainforge.simulate import Settings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=["compare", "scaling", "heap", "figure"])
    ap.add_argument("--grains", type=int, default=100)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--mpi", type=int, default=2, help="ranks of each LIGGGHTS run (heap; 0: no mpirun)")
    ap.add_argument("--workers", type=int, default=1, help="runs at once (compare)")
    ap.add_argument("--engines", default="yade,liggghts", help="engines compared, comma-separated (compare)")
    ap.add_argument("--damping", type=float, default=Settings().damping,
                    help="Yade's local damping (LIGGGHTS: the viscous damping of the same restitution)")
    ap.add_argument("--tilt-step", type=float, default=1.0)
    ap.add_argument("--tilt-start", type=float, default=5.0)
    ap.add_argument("--out", type=Path, default=ROOT / "out/bench-engines")
    ap.add_argument("--figure", type=Path, default=None, help="also write the heap figure here")
    args = ap.parse_args(argv)
    if args.mode == "figure":
        import csv

        with open(args.out / "heap.csv", encoding="utf-8", newline="") as fh:
            heap_figure(list(csv.DictReader(fh)), args, [args.out / "heap.png", args.figure])
        return 0
    print(f"# {args.mode}: {args.grains} grains, {args.seeds} seed(s); load average {os.getloadavg()[0]:.1f}")
    print(f"{'run set':44s} {'mean':>6s} {'sd':>5s}  angles (deg)   cpu s  wall s")
    table = []
    if args.mode == "compare":
        settings = Settings(grains=args.grains, seeds=args.seeds, tilt_step=args.tilt_step,
                            tilt_start=args.tilt_start, damping=args.damping)
        for engine in args.engines.split(","):
            rows, (cpu, wall) = run_set("tilt", SPHERES, settings, args.out / f"compare-{engine}", engine,
                                        workers=args.workers)
            text, rec = row_text(f"tilt, spheres, {engine}, damping {args.damping:g}", rows, cpu, wall)
            print(text, flush=True)
            table.append(rec)
    elif args.mode == "scaling":
        settings = Settings(grains=args.grains, seeds=1)
        for ranks in (None, 2):
            rows, (cpu, wall) = run_set("repose", SPHERES, settings, args.out / f"scaling-np{ranks or 1}",
                                        "liggghts", mpi=ranks)
            text, rec = row_text(f"repose, spheres, {ranks or 1} rank(s)", rows, cpu, wall)
            print(text, flush=True)
            table.append({**rec, "ranks": ranks or 1})
    else:
        settings = Settings(grains=args.grains, seeds=args.seeds)
        for population in POPULATIONS:
            tag = population[0].split(" (")[0].replace(" ", "-")
            rows, (cpu, wall) = run_set("repose", population, settings, args.out / f"heap-{tag}", "liggghts",
                                        mpi=args.mpi or None)
            text, rec = row_text(f"repose, {population[0]}", rows, cpu, wall)
            print(text, flush=True)
            table.append(rec)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / f"{args.mode}.csv", table)
    if args.mode == "heap":
        heap_figure(table, args, [args.out / "heap.png", args.figure])
    for rec in table:
        print(f"# {rec['set']}: {rec['steps_per_run']:.0f} steps per run, "
              f"{rec['cpu_us_per_grain_step']:.2f} µs CPU per grain and step")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
