"""The paper's drained triaxial comparison: three shapes, dense and loose, at 20 kPa.

Runs ``grainforge simulate triaxial`` once per case, one engine run at a time (``--workers 1``, under
``nice -n 5``): the volume-equivalent spheres of examples/paper-rough-spheres.toml (``--as-spheres``),
the rough spheres (examples/paper-rough-spheres.toml) and the rough angular grains
(examples/paper-rough-angular.toml), each ``--packing dense`` and ``--packing loose``, at the contact
friction calibrated on the rough spheres' tilt angle (μ = 0.95, docs/simulate.md) and σ′₃ = 20 kPa.
Each case writes its own folder ``<out>/<shape>-<packing>/`` (the command's outputs, plus ``run.json``:
the CPU seconds of the command and of its engine, wall clock, load; ``<out>/runs.log`` has a line for every
run, an interrupted one too); a case whose ``results.csv`` exists is not run again, so an interrupted
comparison resumes at the next case.

Then (or with ``--report-only``, from the existing outputs) it prints a markdown table (e0, peak φ and
its axial strain, ultimate φ, largest dilatancy angle, ε_v at the end, lateral-stress error, steps,
CPU seconds) and draws the paper's triaxial figure: (a) q/p′ and (b) volumetric strain against the
axial strain, one curve per shape and packing (colour = shape, line style = packing), with the
paper's ultimate q/p′ ≈ 1.5 as a reference line.

    .venv/bin/python benchmarks/triaxial_comparison.py --seeds 1 --axial-strain 0.2 --inertial-number 2e-3
    .venv/bin/python benchmarks/triaxial_comparison.py --seeds 1 --axial-strain 0.2 --inertial-number 2e-3 --report-only
    .venv/bin/python benchmarks/triaxial_comparison.py --engine liggghts --mpi 2

The engine runs use this checkout's ``src`` (``PYTHONPATH``), whatever grainforge the interpreter has
installed. The defaults (3 seeds, 25 % of axial strain, I = 1e-3) are the full specification; see
docs/simulate.md for what it costs.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPHERES_TOML = "examples/paper-rough-spheres.toml"
ANGULAR_TOML = "examples/paper-rough-angular.toml"
#: (name, recipe, --as-spheres, colour) of each shape, in the figure's order
SHAPES = [("spheres", SPHERES_TOML, True, "tab:blue"),
          ("rough spheres", SPHERES_TOML, False, "tab:orange"),
          ("rough angular", ANGULAR_TOML, False, "tab:green")]
PACKINGS = [("dense", "-"), ("loose", "--")]
#: the order the cases run in: the paper's two shapes first (the loose specimens, whose compaction is the
#: shorter, before the dense ones of the angular grains), the sphere baseline last
RUN_ORDER = [("rough spheres", "dense"), ("rough spheres", "loose"), ("rough angular", "loose"),
             ("rough angular", "dense"), ("spheres", "dense"), ("spheres", "loose")]
PAPER_ULTIMATE_M = 1.5  # the paper's ultimate q/p' of the rough spheres (phi about 37 deg)
CLI = "import sys; from grainforge.cli.main import main; sys.exit(main())"


def slug(shape: str, packing: str) -> str:
    return f"{shape.replace(' ', '-')}-{packing}"


def phi_of(m: float) -> float:
    """Friction angle (deg) of a stress ratio M = q/p' in triaxial compression: sin phi = 3M/(6 + M)."""
    return math.degrees(math.asin(3 * m / (6 + m)))


def command(args, shape: str, packing: str, out: Path) -> list[str]:
    _, recipe, as_spheres, _ = next(s for s in SHAPES if s[0] == shape)
    cmd = ["nice", "-n", str(args.nice), sys.executable, "-c", CLI, "simulate", "triaxial", str(ROOT / recipe),
           "--packing", packing, "--grains", str(args.grains), "--seeds", str(args.seeds), "--workers", "1",
           "--friction", f"{args.friction:g}", "--rolling-friction", f"{args.rolling_friction:g}", "--confining-kpa", f"{args.confining_kpa:g}",
           "--axial-strain", f"{args.axial_strain:g}", "--inertial-number", f"{args.inertial_number:g}",
           "--out", str(out)]
    if args.engine != "yade":
        cmd[cmd.index("--out"):cmd.index("--out")] = ["--engine", args.engine, "--mpi", str(args.mpi)]
    if as_spheres:
        cmd.insert(cmd.index("--packing"), "--as-spheres")
    elif args.spheres != 10:
        cmd[cmd.index("--out"):cmd.index("--out")] = ["--spheres", str(args.spheres)]
    return cmd


def run_case(args, shape: str, packing: str) -> int:
    out = args.out / slug(shape, packing)
    if (out / "results.csv").is_file():
        print(f"{shape}, {packing}: done before ({out / 'results.csv'})", flush=True)
        return 0
    cmd = command(args, shape, packing, out)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT / "src")] + (
        [os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else [])), OMP_NUM_THREADS="1")
    print(f"{shape}, {packing}: {' '.join(cmd[3:4] + ['-c', repr(CLI)] + cmd[6:])}", flush=True)
    start, load0 = time.time(), os.getloadavg()
    c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run(cmd, env=env, cwd=ROOT)
    c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (c1.ru_utime + c1.ru_stime) - (c0.ru_utime + c0.ru_stime)
    with open(args.out / "runs.log", "a") as fh:  # every run, an interrupted one too (its CPU is spent all the same)
        fh.write(f"{time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime(start))} {slug(shape, packing)} exit "
                 f"{proc.returncode} cpu_s {cpu:.1f} wall_s {time.time() - start:.1f}\n")
    if (out / "results.csv").is_file():  # written on success and on a failed check (exit 3)
        record = {"shape": shape, "packing": packing, "returncode": proc.returncode, "cpu_s": round(cpu, 1),
                  "wall_s": round(time.time() - start, 1),
                  "start_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(start)),
                  "end_utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime()),
                  "load_start": [round(x, 2) for x in load0], "load_end": [round(x, 2) for x in os.getloadavg()],
                  "command": cmd}
        (out / "run.json").write_text(json.dumps(record, indent=1) + "\n")
        print(f"{shape}, {packing}: exit {proc.returncode}, {cpu:.0f} s CPU, {record['wall_s']:.0f} s wall",
              flush=True)
    return proc.returncode


def engine_name(row: dict) -> str:
    """The engine of a results.csv row as the figure's title names it (runs before the column: Yade)."""
    if row.get("engine", "yade") == "liggghts":
        return f"LIGGGHTS, servo walls, mpirun -np {row.get('mpi_ranks', 1)}"
    return "Yade, periodic cell"


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def read_case(d: Path) -> dict:
    """A case folder's results.csv ``rows``, each seed's triaxial.csv ``curves`` and ``run`` (run.json, or {})."""
    rows = read_csv(d / "results.csv")
    curves = [read_csv(d / f"triaxial-seed{r['seed']}" / "triaxial.csv") for r in rows]
    run = json.loads((d / "run.json").read_text()) if (d / "run.json").is_file() else {}
    return {"rows": rows, "curves": curves, "run": run}


def load_cases(out: Path) -> list[dict]:
    """Every case with outputs (:func:`read_case`), with its shape, packing, colour and line style."""
    cases = []
    for shape, _, _, colour in SHAPES:
        for packing, style in PACKINGS:
            d = out / slug(shape, packing)
            if (d / "results.csv").is_file():
                cases.append({"shape": shape, "packing": packing, "colour": colour, "style": style,
                              **read_case(d)})
    return cases


def largest_dilatancy(curve: list[dict]) -> float:
    """Largest dilatancy angle (deg) of a triaxial.csv curve, by the package's own measure
    (:func:`grainforge.simulate.triaxial.triaxial_angles`): rebuilt from the curve, so a run measured before a
    change of that measure reads as the package reads it now."""
    import numpy as np

    from grainforge.simulate.triaxial import triaxial_angles

    col = {k: np.array([float(r[k]) for r in curve]) for k in ("axial_strain", "q_over_p", "volumetric_strain")}
    return float(triaxial_angles(col["axial_strain"], col["q_over_p"], col["volumetric_strain"]).max_dilatancy_deg)


def _stat(values, fmt: str) -> str:
    if len(values) == 1:
        return format(values[0], fmt)
    m = sum(values) / len(values)
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1))
    return f"{format(m, fmt)} ± {format(sd, fmt.replace('+', ''))}"


def critical(rows: list[dict]) -> str:
    """The table's e at the end (the clumps' in brackets) and how many seeds end at a critical state (rows of a
    run before these columns: not measured)."""
    if "critical_state" not in rows[0]:
        return "not measured | not measured"
    e = _stat([float(r["critical_void_ratio"]) for r in rows], ".3f")
    ec = _stat([float(r["critical_void_ratio_clumps"]) for r in rows], ".3f")
    return f"{e} ({ec}) | {sum(r['critical_state'] == 'True' for r in rows)} of {len(rows)}"


def table(cases: list[dict]) -> str:
    head = ("| shape | packing | seeds | e₀ | peak φ (at ε₁) | ultimate φ (last 5 %) | largest ψ | ε_v at the end "
            "| e at the end (clumps') | at a critical state | lateral σ₃ error, median / max | steps | CPU s |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for c in cases:
        rows = c["rows"]
        f = lambda key: [float(r[key]) for r in rows]  # noqa: E731
        ev = [float(curve[-1]["volumetric_strain"]) for curve in c["curves"]]
        psi = [largest_dilatancy(curve) for curve in c["curves"]]
        end = max(float(curve[-1]["axial_strain"]) for curve in c["curves"])
        peak = f"{_stat(f('peak_friction_deg'), '.1f')}° ({_stat([100 * x for x in f('peak_axial_strain')], '.1f')} %)"
        cpu = c["run"].get("cpu_s")
        lines.append(
            f"| {c['shape']} | {c['packing']} | {len(rows)} | {_stat(f('initial_void_ratio'), '.3f')} | {peak} "
            f"| {_stat(f('ultimate_friction_deg'), '.1f')}° | {_stat(psi, '.1f')}° "
            f"| {_stat([100 * x for x in ev], '+.1f')} % (at {100 * end:.0f} %) | {critical(rows)} "
            f"| {100 * max(f('lateral_stress_error_median')):.2f} % / {100 * max(f('lateral_stress_error_max')):.1f} % "
            f"| {int(sum(f('steps'))):,} | {'' if cpu is None else f'{cpu:.0f}'} |")
    total = sum(c["run"].get("cpu_s", 0.0) for c in cases)
    lines.append("")
    lines.append(f"total CPU of the {len(cases)} case(s): {total:.0f} s ({total / 60:.1f} min)")
    return "\n".join(lines)


def finish_figure(fig, ax, bx, title: str) -> None:
    """The triaxial figure's axes, labels, grid, one legend under both panels (inside either it hides
    curves) and title: (a) q/p′ and (b) ε_v against ε₁."""
    ax.set_xlabel("axial strain ε₁ (%)")
    ax.set_ylabel("stress ratio q/p′")
    ax.set_title("(a) stress ratio", loc="left")
    ax.set_ylim(bottom=0)
    bx.axhline(0, color="0.6", lw=0.8)
    bx.set_xlabel("axial strain ε₁ (%)")
    bx.set_ylabel("volumetric strain ε_v (%), compression +")
    bx.set_title("(b) volumetric strain (below 0: dilation)", loc="left")
    for a in (ax, bx):
        a.set_xlim(left=0)
        a.grid(alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="lower center", ncol=4, frameon=False)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout(rect=(0, 0.1, 1, 1))


def save_figure(fig, path: Path) -> int:
    """Write the figure (no software stamp: the same runs give the same bytes) and say where; 0 for main."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, metadata={"Software": None})
    print(f"figure: {path}")
    return 0


def figure(cases: list[dict], title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 5.0), dpi=120)
    for c in cases:
        for k, curve in enumerate(c["curves"]):
            e1 = [100 * float(r["axial_strain"]) for r in curve]
            label = f"{c['shape']}, {c['packing']}" if k == 0 else None
            ax.plot(e1, [float(r["q_over_p"]) for r in curve], c["style"], color=c["colour"], lw=1.3, label=label)
            bx.plot(e1, [100 * float(r["volumetric_strain"]) for r in curve], c["style"], color=c["colour"], lw=1.3,
                    label=label)
    ax.axhline(PAPER_ULTIMATE_M, color="k", ls=":", lw=1,
               label=f"paper: ultimate q/p′ ≈ {PAPER_ULTIMATE_M} (φ ≈ {phi_of(PAPER_ULTIMATE_M):.0f}°)")
    finish_figure(fig, ax, bx, title)
    return fig


def rolling(row: dict) -> str:
    """The figure title's rolling resistance (nothing when none)."""
    mu_r = float(row.get("setting_rolling_friction") or 0.0)
    return f", μ_r = {mu_r:g}" if mu_r > 0 else ""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None,
                    help="folder of the cases' outputs (one sub-folder per shape and packing) [default: "
                    "benchmarks/out/triaxial-comparison, with -liggghts for that engine]")
    ap.add_argument("--engine", choices=["yade", "liggghts"], default="yade",
                    help="Yade's periodic cell or LIGGGHTS's box of servo walls (each seed under mpirun -np --mpi)")
    ap.add_argument("--mpi", type=int, default=2, help="LIGGGHTS: MPI ranks of each run")
    ap.add_argument("--grains", type=int, default=1000)
    ap.add_argument("--seeds", type=int, default=3, help="seeds per case (the full specification: 3)")
    ap.add_argument("--axial-strain", type=float, default=0.25)
    ap.add_argument("--inertial-number", type=float, default=1e-3)
    ap.add_argument("--friction", type=float, default=0.95, help="contact friction (calibrated on the rough "
                    "spheres' tilt angle, 38 deg)")
    ap.add_argument("--rolling-friction", type=float, default=0.0, help="rolling resistance μ_r of every contact "
                    "(0: none)")
    ap.add_argument("--confining-kpa", type=float, default=20.0)
    ap.add_argument("--spheres", type=int, default=10, help="spheres per clump (the sphere baseline: 1)")
    ap.add_argument("--cases", default="", help="run only these, comma-separated slugs, e.g. rough-angular-loose")
    ap.add_argument("--nice", type=int, default=5)
    ap.add_argument("--report-only", action="store_true", help="no runs: the table and figure of existing outputs")
    ap.add_argument("--figure", type=Path, default=None,
                    help="[default: docs/img/triaxial-comparison.png, -liggghts.png for that engine]")
    args = ap.parse_args(argv)
    suffix = "" if args.engine == "yade" else f"-{args.engine}"
    args.out = args.out or ROOT / f"benchmarks/out/triaxial-comparison{suffix}"
    args.figure = args.figure or ROOT / f"docs/img/triaxial-comparison{suffix}.png"
    chosen = [c.strip() for c in args.cases.split(",") if c.strip()]
    known = [slug(s, p) for s, p in RUN_ORDER]
    if any(c not in known for c in chosen):
        ap.error(f"--cases: choose among {', '.join(known)}")
    if not args.report_only:
        args.out.mkdir(parents=True, exist_ok=True)
        for shape, packing in RUN_ORDER:
            if chosen and slug(shape, packing) not in chosen:
                continue
            code = run_case(args, shape, packing)
            if code not in (0, 3):  # 3: a run's own check failed, its outputs are written: go on
                print(f"stopped: {shape}, {packing} exited {code}", file=sys.stderr)
                return code
    cases = load_cases(args.out)
    if not cases:
        print(f"no outputs in {args.out}", file=sys.stderr)
        return 1
    print(table(cases))
    r = cases[0]["rows"][0]
    title = (f"drained triaxial, σ′₃ = {float(r['confining_kpa']):g} kPa, {r['grains']} grains, μ = "
             f"{float(r['setting_friction']):g}{rolling(r)}, I = {float(r['setting_inertial_number']):g}, "
             f"{len(cases[0]['rows'])} seed(s) a case, the rough grains as clumps of {r['setting_spheres']} spheres "
             f"({engine_name(r)})")
    fig = figure(cases, title)
    return save_figure(fig, args.figure)


if __name__ == "__main__":
    sys.exit(main())
