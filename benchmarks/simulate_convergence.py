"""Representation convergence of the tilt test: failure angle against clump size, and level sets.

For the paper's two CRI presets (examples/paper-rough-spheres.toml, examples/paper-rough-angular.toml)
and their volume-equivalent spheres, this runs `grainforge simulate tilt` with every grain a clump of
N = 10, 20, 40 spheres (``--spheres``), a level set (``--shape levelset``) and a sphere, at otherwise
identical settings, one Yade run per (population, representation, seed), and appends each run's row
to ``<out>/convergence.csv`` as soon as it is measured (a rerun skips the rows already there, so an
interrupted study resumes where it stopped).  Runs go seed by seed (every representation of seed 0
first), so a partial study still holds whole comparisons.  Timing: each run's Yade CPU seconds.

    nice -n 10 .venv/bin/python benchmarks/simulate_convergence.py --grains 50
    .venv/bin/python benchmarks/simulate_convergence.py --grains 50 --report   # table + figure only

It prints the table (mean ± sd over seeds per population and representation, every seed's angle,
CPU per run) and writes docs/img/simulate-convergence.png with ``--figure``.
"""

from __future__ import annotations

import argparse
import csv
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PRESETS = [("rough spheres", ROOT / "examples/paper-rough-spheres.toml"),
           ("rough angular", ROOT / "examples/paper-rough-angular.toml")]
FIELDS = ["preset", "representation", "spheres", "seed", "angle_deg", "cpu_s", "wall_s", "grains", "templates",
          "friction", "tilt_start", "tilt_step", "spacing", "load", "note"]


def representations(spheres, levelset_seeds):
    """(name, as_spheres, shape, N) of every representation, and the seeds each runs."""
    reps = [("sphere", True, "clump", 1)] + [(f"clump {n}", False, "clump", n) for n in spheres]
    return reps + ([("level set", False, "levelset", 0)] if levelset_seeds else [])


def read_rows(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def append_row(path: Path, row: dict) -> None:
    new = not path.is_file()
    with open(path, "a", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        if new:
            w.writeheader()
        w.writerow({k: row.get(k, "") for k in FIELDS})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grains", type=int, default=100, help="grains per tilt layer")
    ap.add_argument("--templates", type=int, default=20, help="clump/level-set templates per population")
    ap.add_argument("--seeds", type=int, default=3, help="seeds of the spheres and of each clump size")
    ap.add_argument("--levelset-seeds", type=int, default=1, help="seeds of the level sets (0: none)")
    ap.add_argument("--spheres", default="10,20,40", help="clump sizes, comma-separated")
    ap.add_argument("--spacing", type=float, default=0.05, help="level-set grid spacing, fraction of d_eq")
    ap.add_argument("--friction", type=float, default=0.5)
    ap.add_argument("--tilt-start", type=float, default=15.0)
    ap.add_argument("--tilt-step", type=float, default=1.0)
    ap.add_argument("--presets", default="rough spheres,rough angular", help="presets to run, comma-separated")
    ap.add_argument("--out", type=Path, default=ROOT / "out/simulate-convergence")
    ap.add_argument("--report", action="store_true", help="no runs: print the table (and figure) of the CSV")
    ap.add_argument("--figure", action="store_true", help="write docs/img/simulate-convergence.png")
    args = ap.parse_args(argv)
    spheres = [int(x) for x in args.spheres.split(",")]
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "convergence.csv"
    if not args.report:
        run_all(args, spheres, path)
    rows = [r for r in read_rows(path) if int(r["grains"]) == args.grains]
    print_table(rows)
    if args.figure and rows:
        from grainforge.io import save_figure

        save_figure(figure(rows), ROOT / "docs/img/simulate-convergence.png")
    return 0


def run_all(args, spheres, path):
    from grainforge.simulate import Settings, build_population, run_test

    def done():  # read again before each run: another process may be running other cells of the study
        return {(r["preset"], r["representation"], int(r["seed"])) for r in read_rows(path)
                if int(r["grains"]) == args.grains}

    chosen = [p.strip() for p in args.presets.split(",")]
    reps = representations(spheres, args.levelset_seeds)
    cache = {}
    for seed in range(max(args.seeds, args.levelset_seeds)):
        for preset, recipe in [(p, r) for p, r in PRESETS if p in chosen]:
            for name, as_spheres, shape, n in reps:
                if seed >= (args.levelset_seeds if shape == "levelset" else args.seeds):
                    continue
                if (preset, name, seed) in done():
                    continue
                settings = Settings(grains=args.grains, templates=args.templates, spheres=max(n, 1), seeds=1,
                                    seed=seed, friction=args.friction, tilt_start=args.tilt_start,
                                    tilt_step=args.tilt_step)
                key = (preset, name)
                if key not in cache:
                    cache[key] = build_population([recipe], settings, as_spheres=as_spheres, shape=shape,
                                                  spacing=args.spacing)
                out = args.out / "runs" / f"{preset.replace(' ', '-')}-{name.replace(' ', '')}"
                t0, c0 = time.time(), resource.getrusage(resource.RUSAGE_CHILDREN)
                (row,) = run_test("tilt", cache[key], settings=settings, out=out, label=preset, overwrite=True)
                c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
                rec = {"preset": preset, "representation": name, "spheres": n, "seed": seed,
                       "angle_deg": f"{row['angle_deg']:.3f}", "cpu_s": f"{cpu:.1f}", "wall_s": f"{time.time() - t0:.1f}",
                       "grains": args.grains, "templates": args.templates, "friction": args.friction,
                       "tilt_start": args.tilt_start, "tilt_step": args.tilt_step,
                       "spacing": args.spacing if shape == "levelset" else "", "load": f"{os.getloadavg()[0]:.1f}",
                       "note": row.get("note", "")}
                append_row(path, rec)
                print(f"{preset:14s} {name:10s} seed {seed}: {row['angle_deg']:.1f} deg, {cpu:.0f} s CPU",
                      flush=True)


def groups(rows):
    out = {}
    for r in rows:
        out.setdefault((r["preset"], r["representation"]), []).append(r)
    return out


def print_table(rows):
    print(f"{'preset':14s} {'representation':14s} {'mean':>6s} {'sd':>5s} {'seeds':>5s}  angles (deg)        "
          f"CPU s/run")
    for (preset, rep), rs in sorted(groups(rows).items(), key=lambda kv: (kv[0][0], order(kv[0][1]))):
        a = np.array([float(r["angle_deg"]) for r in rs])
        cpu = np.mean([float(r["cpu_s"]) for r in rs])
        sd = f"{a.std(ddof=1):5.1f}" if len(a) > 1 else "    -"
        print(f"{preset:14s} {rep:14s} {a.mean():6.1f} {sd} {len(a):5d}  "
              f"{', '.join(f'{x:.1f}' for x in a):20s} {cpu:6.0f}")


def order(rep: str) -> int:
    return 0 if rep == "sphere" else 10**6 if rep == "level set" else int(rep.split()[1])


def figure(rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    g = groups(rows)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), dpi=120, sharey=True)
    for ax, (preset, _) in zip(axes, PRESETS):
        clumps = sorted((order(rep), rs) for (p, rep), rs in g.items() if p == preset and rep.startswith("clump"))
        ns = [n for n, _ in clumps]
        for n, rs in clumps:
            a = np.array([float(r["angle_deg"]) for r in rs])
            ax.plot([n] * len(a), a, "o", color="C0", alpha=0.45, ms=4)
            ax.vlines(n, a.min(), a.max(), color="C0", lw=1)
        if ns:
            ax.plot(ns, [np.mean([float(r["angle_deg"]) for r in rs]) for _, rs in clumps], "s-", color="C0",
                    ms=7, label="clump of N spheres: mean, seeds, range")
        x_ls = (max(ns) if ns else 40) * 1.8
        for (p, rep), rs in g.items():
            if p != preset:
                continue
            a = np.array([float(r["angle_deg"]) for r in rs])
            if rep == "level set":
                ax.plot([x_ls] * len(a), a, "D", color="C3", ms=8, label="level set (the mesh's own surface)")
            elif rep == "sphere":
                ax.axhspan(a.min(), a.max(), color="0.85", zorder=0)
                ax.axhline(a.mean(), color="0.4", ls="--", lw=1, label="volume-equivalent spheres (mean, range)")
        ax.set_xscale("log")
        ticks = ns + [x_ls]
        ax.set_xticks(ticks, [str(n) for n in ns] + ["level\nset"])
        ax.minorticks_off()
        ax.set_xlabel("spheres per clump, N")
        ax.set_title(f"{preset} ({rows[0]['grains']} grains per layer)")
        ax.legend(fontsize=7, loc="best")
    axes[0].set_ylabel(f"tilt failure angle (°), μ = {rows[0]['friction']}")
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    sys.exit(main())
