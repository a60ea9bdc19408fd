"""The 14-grain polyhedron pour of 2 mm grains, timed in every engine that takes polyhedra.

    .venv/bin/python benchmarks/bench_dem_polyhedron.py                    # Yade and LAMMPS, defaults
    .venv/bin/python benchmarks/bench_dem_polyhedron.py --engines lammps --vertices 8 12 16
    .venv/bin/python benchmarks/bench_dem_polyhedron.py --clump            # the clump decks too

Generates the README's grains (``grainforge generate fso --count 14 --seed 100 --size 2
--fractal-dimension 2.4 --length-ratio 7 --amplitude 0.1``), writes ``grainforge dem
--shape polyhedron`` decks (``--vertices`` as given, else the engine's default), runs each engine
from inside its deck exactly as docs/dem.md says and prints one row per run: the vertex count, wall
and CPU seconds of the engine (children's user + system time), steps, steps per CPU second, the
deck's last line (``SETTLED in N steps`` / ``NOT SETTLED after …``), the exit status and the load
average. A run that passes ``--timeout`` (default 300 s) is stopped and reported as such. It also
prints, per vertex count, the contact shape's volume against the mesh's (the hull of the kept
vertices; for LAMMPS also dilated by its rounded radius), mean and range over the grains.

Results: docs/benchmarks.md ("DEM polyhedron pour").
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

GRAINS = ["generate", "fso", "--count", "14", "--seed", "100", "--size", "2", "--fractal-dimension", "2.4",
          "--length-ratio", "7", "--amplitude", "0.1"]
COMMAND = {"yade": ["yade", "-n", "-x", "run.py"], "lammps": ["lmp", "-in", "in.run"],
           "liggghts": ["liggghts", "-in", "in.run"]}


def grainforge(*args):
    exe = Path(sys.executable).with_name("grainforge")
    subprocess.run([str(exe) if exe.exists() else "grainforge", *args], check=True, capture_output=True, text=True)


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def last_line(text: str) -> str:
    lines = [l for l in text.splitlines() if l.strip()]
    return lines[-1] if lines else ""


def run_engine(engine: str, deck: Path, timeout: float) -> dict:
    c0, w0 = children_cpu(), time.perf_counter()
    try:
        proc = subprocess.run(COMMAND[engine], cwd=deck, capture_output=True, text=True, timeout=timeout,
                              stdin=subprocess.DEVNULL)
        status, line = proc.returncode, last_line(proc.stdout)
    except subprocess.TimeoutExpired:
        status, line = None, f"stopped after {timeout:.0f} s"
    wall, cpu = time.perf_counter() - w0, children_cpu() - c0
    return {"wall": wall, "cpu": cpu, "status": status, "line": line}


def volumes(deck: Path, engine: str) -> tuple[float, float, float]:
    """Mean, min, max of contact-shape volume / mesh volume over the deck's grains."""
    from scipy.spatial import ConvexHull

    info = json.loads((deck / "grains.json").read_text())
    ratios = []
    for g in info["grains"]:
        v = np.loadtxt(deck / g["polyhedron"], comments="#")
        hull = ConvexHull(v)
        vol = hull.volume
        if engine == "lammps":  # the hull dilated by the rounded radius r: V + S r + (mean width) ... exactly
            r = 0.5 * g["rounded_diameter"]
            # Steiner: V + S r + M r² + 4/3 π r³, M = integral of mean curvature = sum over edges of
            # length × exterior angle / 2
            M = 0.0
            eq = hull.equations
            edges = {}
            for k, s in enumerate(hull.simplices):
                for a, b in ((s[0], s[1]), (s[1], s[2]), (s[2], s[0])):
                    edges.setdefault((min(a, b), max(a, b)), []).append(k)
            for (a, b), fs in edges.items():
                if len(fs) == 2:
                    ang = np.arccos(np.clip(eq[fs[0], :3] @ eq[fs[1], :3], -1.0, 1.0))
                    M += 0.5 * np.linalg.norm(v[a] - v[b]) * ang
            vol = vol + hull.area * r + M * r * r + 4.0 / 3.0 * np.pi * r**3
        ratios.append(vol / g["volume"])
    return float(np.mean(ratios)), float(np.min(ratios)), float(np.max(ratios))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--engines", nargs="+", default=["yade", "lammps"], choices=["yade", "lammps"])
    p.add_argument("--vertices", nargs="+", type=int, default=[None], help="vertex counts (default: each engine's)")
    p.add_argument("--timeout", type=float, default=300.0)
    p.add_argument("--clump", action="store_true", help="also the 14-grain clump pour (30 spheres) per engine")
    p.add_argument("--keep", type=Path, default=None, help="keep the decks under this folder")
    args = p.parse_args(argv)

    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench-dem-poly-"))
    root.mkdir(parents=True, exist_ok=True)
    grains = root / "grains"
    if not grains.exists():
        grainforge(*GRAINS, "--out", str(grains))
    print(f"14 FSO grains of 2 mm in {grains}; {os.cpu_count()} cores")
    print("| engine | shape | vertices | contact volume / mesh volume: mean (min–max) | engine wall s | CPU s "
          "| last line | exit | load average |")
    print("|---|---|---:|---|---:|---:|---|---:|---|")
    jobs = [(e, "polyhedron", k) for e in args.engines for k in args.vertices]
    if args.clump:
        jobs += [(e, "clump", None) for e in ("yade", "liggghts", "lammps")]
    for engine, shape, k in jobs:
        if shutil.which(COMMAND[engine][0]) is None:
            print(f"| {engine} | {shape} | – | – | – | – | not installed | – | – |")
            continue
        deck = root / f"{engine}-{shape}-{k or 'default'}"
        extra = ["--shape", shape] + (["--vertices", str(k)] if k else [])
        grainforge("dem", str(grains), "--out", str(deck), "--engine", engine, "--overwrite", *extra)
        info = json.loads((deck / "grains.json").read_text())
        nv = sorted({g.get("vertices", 0) for g in info["grains"]})
        vol = volumes(deck, engine) if shape == "polyhedron" else None
        load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
        r = run_engine(engine, deck, args.timeout)
        vtext = f"{vol[0]:.3f} ({vol[1]:.3f}–{vol[2]:.3f})" if vol else "–"
        print(f"| {engine} | {shape} | {'/'.join(map(str, nv)) if vol else '–'} | {vtext} | {r['wall']:.1f} "
              f"| {r['cpu']:.1f} | {r['line']} | {r['status']} | {load} |", flush=True)
    if not args.keep:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
