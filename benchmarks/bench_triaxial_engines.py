"""The drained triaxial test in Yade (a periodic cell) against LIGGGHTS (a box of six servo-controlled walls).

The volume-equivalent spheres of the paper's rough spheres (``examples/paper-rough-spheres.toml``,
``--as-spheres``) at equal contact settings (k_n = E r, k_s/k_n, μ, the damping of docs/simulate.md), dense,
σ′₃ = 20 kPa, the same seeds in each engine, one engine run at a time (LIGGGHTS serial). One row per engine: the
ultimate and peak friction angles per seed, mean ± sd, the initial void ratio, the lateral stress error, steps,
CPU and wall time, and the CPU time per grain and time step.

    .venv/bin/python benchmarks/bench_triaxial_engines.py --grains 250 --seeds 3 --axial-strain 0.1 \\
        --inertial-number 2e-3

``--clumps`` runs the rough spheres as clumps of ``--spheres`` spheres instead (the cost per grain and step of a
clump). It writes out/bench-triaxial-engines/<engine>/ (the command's outputs) and
out/bench-triaxial-engines/triaxial-engines.csv. CPU time: the engine processes' (children); the machine's load
average is printed.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RECIPE = ROOT / "examples/paper-rough-spheres.toml"


def run_engine(engine: str, settings, as_spheres: bool, out: Path):
    """One engine's seeds (one run at a time): the rows and (CPU s, wall s) of its engine runs."""
    from grainforge.simulate import build_population, run_test
    from grainforge.simulate.results import write_report

    templates = build_population([RECIPE], settings, as_spheres=as_spheres)
    out.mkdir(parents=True, exist_ok=True)
    c0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.time()
    rows = run_test("triaxial", templates, settings=settings, out=out, label=engine, overwrite=True, workers=1, engine=engine)
    c1, t1 = resource.getrusage(resource.RUSAGE_CHILDREN), time.time()
    write_report(rows, out, test="triaxial", settings=settings)
    return rows, (c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime, t1 - t0)


def summary(engine: str, rows, cpu: float, wall: float) -> dict:
    """The table row of one engine's seeds."""
    def stat(key):
        a = np.array([r[key] for r in rows], dtype=np.float64)
        return float(a.mean()), float(a.std(ddof=1)) if len(a) > 1 else float("nan"), a

    ult, ult_sd, ults = stat("ultimate_friction_deg")
    peak, peak_sd, _ = stat("peak_friction_deg")
    e0, e0_sd, _ = stat("initial_void_ratio")
    grain_steps = sum(r["grains"] * r["steps"] for r in rows)
    return {"engine": engine, "ultimate_deg": ult, "ultimate_sd_deg": ult_sd,
            "ultimate_per_seed": ", ".join(f"{a:.1f}" for a in ults), "peak_deg": peak, "peak_sd_deg": peak_sd,
            "e0": e0, "e0_sd": e0_sd,
            "lateral_error_median": float(np.median([r["lateral_stress_error_median"] for r in rows])),
            "steps_per_run": float(np.mean([r["steps"] for r in rows])),
            "cpu_s": cpu, "wall_s": wall,
            "cpu_us_per_grain_step": 1e6 * cpu / grain_steps, "problems": "; ".join(r["problems"] for r in rows
                                                                                  if r["problems"])}


def main(argv=None) -> int:
    from grainforge.io import write_csv
    from grainforge.simulate import TriaxialSettings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grains", type=int, default=250)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--axial-strain", type=float, default=0.1)
    ap.add_argument("--inertial-number", type=float, default=2e-3)
    ap.add_argument("--packing", default="dense", choices=["dense", "loose"])
    ap.add_argument("--damping", type=float, default=TriaxialSettings().damping,
                    help="Yade's local damping (LIGGGHTS: the viscous damping of the same restitution)")
    ap.add_argument("--engines", default="yade,liggghts", help="engines compared, comma-separated")
    ap.add_argument("--clumps", action="store_true", help="the rough spheres as clumps, not their spheres")
    ap.add_argument("--spheres", type=int, default=10, help="spheres per clump (--clumps)")
    ap.add_argument("--out", type=Path, default=ROOT / "out/bench-triaxial-engines",
                    help="the engines' outputs go to OUT/<engine>/")
    args = ap.parse_args(argv)
    settings = TriaxialSettings(grains=args.grains, seeds=args.seeds, axial_strain=args.axial_strain,
                                inertial_number=args.inertial_number, packing=args.packing, spheres=args.spheres,
                                damping=args.damping)
    shape = f"clumps of {args.spheres} spheres" if args.clumps else "spheres"
    print(f"# triaxial, {shape}, {args.grains} grains, {args.packing}, ε_a {args.axial_strain:g}, "
          f"I = {args.inertial_number:g}, damping {args.damping:g}, {args.seeds} seed(s); load average {os.getloadavg()[0]:.1f}", flush=True)
    table = []
    for engine in args.engines.split(","):
        rows, (cpu, wall) = run_engine(engine, settings, not args.clumps, args.out / engine)
        rec = summary(engine, rows, cpu, wall)
        table.append(rec)
        print(f"| {engine} | {rec['ultimate_deg']:.1f}° ± {rec['ultimate_sd_deg']:.1f}° ({rec['ultimate_per_seed']}) "
              f"| {rec['peak_deg']:.1f}° ± {rec['peak_sd_deg']:.1f}° | {rec['e0']:.3f} | "
              f"{100 * rec['lateral_error_median']:.1f} % | {rec['steps_per_run']:.0f} | {cpu:.0f} s | {wall:.0f} s | "
              f"{rec['cpu_us_per_grain_step']:.2f} µs | {rec['problems'] or '-'} |", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "triaxial-engines.csv", table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
