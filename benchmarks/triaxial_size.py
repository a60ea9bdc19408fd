"""Size and representation on the triaxial test: one case at 1,000 and 8,000 grains, and at 10, 20, 40 spheres a clump.

Reads the outputs of ``benchmarks/triaxial_comparison.py`` runs of one case (each a folder holding
``<shape>-<packing>/results.csv`` and each seed's ``triaxial.csv``), prints a markdown table (grains, spheres a
clump, seeds, e0, peak and ultimate friction angle, CPU) and draws q/p′ and ε_v against ε₁, one colour a run.
The runs, as recorded in docs/simulate.md (the loose rough angular grains, LIGGGHTS, ``mpirun -np 2``)::

    .venv/bin/python benchmarks/triaxial_comparison.py --engine liggghts --mpi 2 --cases rough-angular-loose
    .venv/bin/python benchmarks/triaxial_comparison.py --engine liggghts --mpi 2 --cases rough-angular-loose \\
        --grains 8000 --seeds 1 --out benchmarks/out/triaxial-size-8000 --figure benchmarks/out/triaxial-size-8000/figure.png
    .venv/bin/python benchmarks/triaxial_comparison.py --engine liggghts --mpi 2 --cases rough-angular-loose \\
        --spheres 20 --seeds 1 --out benchmarks/out/triaxial-clump-20 --figure benchmarks/out/triaxial-clump-20/figure.png
    (and --spheres 40 into benchmarks/out/triaxial-clump-40, likewise)
    .venv/bin/python benchmarks/triaxial_size.py --case rough-angular-loose \\
        benchmarks/out/triaxial-comparison-liggghts benchmarks/out/triaxial-size-8000 \\
        benchmarks/out/triaxial-clump-20 benchmarks/out/triaxial-clump-40
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from triaxial_comparison import ROOT, _stat, engine_name, finish_figure, read_case, save_figure  # noqa: E402


def load(folder: Path, case: str) -> dict:
    run = read_case(folder / case)
    rows = run["rows"]
    return {**run, "label": f"{rows[0]['grains']} grains, {rows[0]['setting_spheres']} spheres a clump"}


def table(runs: list[dict]) -> str:
    lines = ["| grains | spheres a clump | seeds | e₀ | peak φ (at ε₁) | ultimate φ (last 5 %) | problems | CPU s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in runs:
        f = lambda key: [float(x[key]) for x in r["rows"]]  # noqa: E731
        problems = sum(1 for x in r["rows"] if x["problems"])
        cpu = "" if "cpu_s" not in r["run"] else f"{r['run']['cpu_s']:.0f}"
        lines.append(f"| {r['rows'][0]['grains']} | {r['rows'][0]['setting_spheres']} | {len(r['rows'])} "
                     f"| {_stat(f('initial_void_ratio'), '.3f')} | {_stat(f('peak_friction_deg'), '.1f')}° "
                     f"({_stat([100 * x for x in f('peak_axial_strain')], '.1f')} %) "
                     f"| {_stat(f('ultimate_friction_deg'), '.1f')}° | {problems} "
                     f"| {cpu} |")
    return "\n".join(lines)


def figure(runs: list[dict], title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 5.0), dpi=120)
    for k, r in enumerate(runs):
        colour = f"C{k}"
        for j, curve in enumerate(r["curves"]):
            e1 = [100 * float(x["axial_strain"]) for x in curve]
            label = r["label"] + (f" ({len(r['curves'])} seeds)" if len(r["curves"]) > 1 else "") if j == 0 else None
            ax.plot(e1, [float(x["q_over_p"]) for x in curve], color=colour, lw=1.1, label=label)
            bx.plot(e1, [100 * float(x["volumetric_strain"]) for x in curve], color=colour, lw=1.1)
    finish_figure(fig, ax, bx, title)
    return fig


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path, help="triaxial_comparison.py output folders (--out)")
    ap.add_argument("--case", default="rough-angular-loose", help="the case's folder name in each, e.g. "
                    "rough-angular-loose")
    ap.add_argument("--figure", type=Path, default=ROOT / "docs/img/triaxial-size.png")
    args = ap.parse_args(argv)
    missing = [str(f / args.case) for f in args.folders if not (f / args.case / "results.csv").is_file()]
    if missing:
        print(f"no results.csv in {', '.join(missing)}", file=sys.stderr)
        return 2
    runs = [load(f, args.case) for f in args.folders]
    print(table(runs))
    r = runs[0]["rows"][0]
    title = (f"{args.case}: drained triaxial, σ′₃ = {float(r['confining_kpa']):g} kPa, μ = "
             f"{float(r['setting_friction']):g}, I = {float(r['setting_inertial_number']):g} ({engine_name(r)})")
    fig = figure(runs, title)
    return save_figure(fig, args.figure)


if __name__ == "__main__":
    sys.exit(main())
