"""The paper's §3.2 comparison in silico: angle of repose of rough spheres, rough-angular grains and spheres.

The paper measured, on a tilt table, ultimate friction angles of about 38° for CRI "rough spheres"
(Fourier descriptors 0, 0, 0.02) and 43–48° for "rough and angular" grains (0.15, 0.10, 0.03),
printed at a mean diameter of 2 mm.  This script runs `grainforge simulate` on the same two CRI
populations (examples/paper-rough-spheres.toml, examples/paper-rough-angular.toml) and on a sphere
baseline (the rough spheres replaced by their volume-equivalent spheres) with identical settings,
for each contact friction asked for, and prints one row per population and friction:
mean and standard deviation of the angle over seeds, every seed's angle, and the CPU time.

    .venv/bin/python benchmarks/bench_simulate.py                        # repose, mu 0.5, 3 seeds
    .venv/bin/python benchmarks/bench_simulate.py --frictions 0.3,0.5,0.8 --seeds 1
    .venv/bin/python benchmarks/bench_simulate.py --test tilt

It writes out/bench-simulate/<test>-<population>-mu<mu>/ (decks, results.csv, figure),
out/bench-simulate/<test>-comparison.csv and docs/img/simulate-<test>-comparison.png
(with --figure).  Timing: CPU seconds of the Yade runs (children), and wall time.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
POPULATIONS = [
    ("spheres", ROOT / "examples/paper-rough-spheres.toml", True),
    ("rough spheres (0, 0, 0.02)", ROOT / "examples/paper-rough-spheres.toml", False),
    ("rough angular (0.15, 0.10, 0.03)", ROOT / "examples/paper-rough-angular.toml", False),
]
#: the paper's tilt-table ultimate friction angles (degrees), for the figure
PAPER = {"rough spheres (0, 0, 0.02)": (38.0, 38.0), "rough angular (0.15, 0.10, 0.03)": (43.0, 48.0)}


def main(argv=None) -> int:
    from grainforge.io import save_figure, write_csv
    from grainforge.simulate import Settings, build_population, measure_result, run_test, summarise
    from grainforge.simulate.results import write_report

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--test", choices=["repose", "tilt"], default="repose")
    ap.add_argument("--frictions", default="0.5", help="contact friction coefficients, comma-separated")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--grains", type=int, default=Settings().grains)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--tilt-step", type=float, default=Settings().tilt_step, help="degrees (tilt test)")
    ap.add_argument("--tilt-start", type=float, default=Settings().tilt_start, help="degrees (tilt test)")
    ap.add_argument("--out", type=Path, default=ROOT / "out/bench-simulate")
    ap.add_argument("--figure", action="store_true", help="write docs/img/simulate-<test>-comparison.png")
    ap.add_argument("--remeasure", action="store_true",
                    help="do not run Yade: measure the runs already in --out again (after a change of the measurement)")
    args = ap.parse_args(argv)
    frictions = [float(x) for x in args.frictions.split(",")]
    table = []
    print(f"# {args.test}: {args.grains} grains, {args.seeds} seeds; load average {os.getloadavg()[0]:.1f}"
          + (f"; tilt from {args.tilt_start:g} deg in {args.tilt_step:g} deg steps" if args.test == "tilt" else ""))
    print(f"{'population':34s} {'mu':>4s} {'mean':>6s} {'sd':>5s}  angles (deg)            cpu s   wall s")
    for mu in frictions:
        settings = Settings(friction=mu, seeds=args.seeds, grains=args.grains, tilt_step=args.tilt_step,
                            tilt_start=args.tilt_start)
        for label, recipe, as_spheres in POPULATIONS:
            tag = label.split(" (")[0].replace(" ", "-")
            out = args.out / f"{args.test}-{tag}-mu{mu:g}"
            out.mkdir(parents=True, exist_ok=True)
            t0 = time.time()
            c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            if args.remeasure:
                rows = [{"label": label, "seed": settings.seed + k,
                         **measure_result(json.loads((out / f"{args.test}-seed{settings.seed + k}" / "result.json")
                                                     .read_text()))} for k in range(settings.seeds)]
            else:
                templates = build_population([recipe], settings, as_spheres=as_spheres)
                rows = run_test(args.test, templates, settings=settings, out=out, label=label, overwrite=True,
                                workers=args.workers)
            c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            write_report(rows, out, test=args.test, settings=settings)
            s = summarise(rows)
            cpu = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
            angles = ", ".join(f"{r['angle_deg']:.1f}" for r in rows)
            print(f"{label:34s} {mu:4.2f} {s['angle_mean_deg']:6.1f} {s['angle_sd_deg']:5.1f}  {angles:22s} "
                  f"{cpu:7.0f} {time.time() - t0:7.0f}", flush=True)
            table.append({"population": label, "friction": mu, "seeds": s["runs"],
                          "angle_mean_deg": s["angle_mean_deg"], "angle_sd_deg": s["angle_sd_deg"],
                          "angles_deg": angles, "grains": args.grains, "cpu_s": cpu})
    write_csv(args.out / f"{args.test}-comparison.csv", table)
    if args.figure:
        save_figure(comparison_figure(table, args.test), ROOT / f"docs/img/simulate-{args.test}-comparison.png")
    return 0


def comparison_figure(table, test):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [p[0] for p in POPULATIONS]
    fig, ax = plt.subplots(figsize=(7.5, 4.4), dpi=120)
    frictions = sorted({r["friction"] for r in table})
    for j, mu in enumerate(frictions):
        for i, lab in enumerate(labels):
            rows = [r for r in table if r["population"] == lab and r["friction"] == mu]
            if not rows:
                continue
            angles = [float(a) for a in rows[0]["angles_deg"].split(", ")]
            x = i + 0.12 * (j - (len(frictions) - 1) / 2)
            ax.plot([x] * len(angles), angles, "o", color=f"C{j}", alpha=0.5, ms=4)
            ax.errorbar(x, rows[0]["angle_mean_deg"], yerr=rows[0]["angle_sd_deg"] if len(angles) > 1 else None,
                        fmt="s", color=f"C{j}", capsize=4, ms=7,
                        label=f"simulated, μ = {mu:g} ({np.degrees(np.arctan(mu)):.1f}°)" if i == 0 else None)
    for i, lab in enumerate(labels):
        if lab in PAPER:
            lo, hi = PAPER[lab]
            ax.fill_between([i - 0.3, i + 0.3], lo - 0.3, hi + 0.3, color="0.8", zorder=0,
                            label="paper, tilt table (printed grains)" if i == 1 else None)
    ax.set_xticks(range(len(labels)), [lab.replace(" (", "\n(") for lab in labels])
    name = "angle of repose" if test == "repose" else "tilt failure angle"
    ax.set_ylabel(f"{name} (°)")
    ax.set_title(f"virtual {('repose' if test == 'repose' else 'tilt-table')} test in Yade: mean ± sd over seeds")
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    return fig


if __name__ == "__main__":
    sys.exit(main())
