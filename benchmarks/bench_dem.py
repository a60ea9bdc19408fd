"""DEM export benchmarks.

    .venv/bin/python benchmarks/bench_dem.py clumps [--clump-python /tmp/clumpbench/bin/python] [--iterations 30]
    .venv/bin/python benchmarks/bench_dem.py deck --count 10000 [--workers 2] [--keep]   (several counts: --count 100 300)

``clumps``: our clump (grainforge.dem.clump) and clump-python's Euclidean
distance-transform method (GenerateClump_Euclidean_3D, div=102, overlap=0.6 as
in its example; rMin=0) side by side on the same three grains (fso, cri, dpa;
d_eq ≈ 2 in grain units) at N = 5…100 spheres. Both are measured by the same
code, grainforge.dem.clump.clump_quality on a d_eq/100 grid. clump-python runs
in its own throwaway venv (it is never a project dependency):

    python3 -m venv /tmp/clumpbench && /tmp/clumpbench/bin/pip install clump-python

Its centres are relative to the bounding-box centre of the mesh; they are
shifted back by that centre before measuring. CPU time = time.process_time of
the clump call alone (ours includes voxelising; clump_quality is not timed).

``deck``: a batch-like folder of COUNT grain files (FSO/CRI/DPA cycled,
written by grainforge.io) -> ``grainforge dem --engine liggghts`` (per-grain
multisphere templates, 30 spheres). Prints wall and CPU time (parent +
workers, polled every 0.2 s) and the peak RSS of the whole process tree. The grain folder
and the deck are removed afterwards unless ``--keep``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

COUNTS = (5, 10, 20, 30, 50, 100)

CP_SCRIPT = r'''
import json, sys, time, io, contextlib
import numpy as np, trimesh
from CLUMP.GenerateClump_Euclidean_3D import GenerateClump_Euclidean_3D
path, n = sys.argv[1], int(sys.argv[2])
m = trimesh.load_mesh(path)
lo, hi = m.vertices.min(axis=0), m.vertices.max(axis=0)
t0, w0 = time.process_time(), time.perf_counter()
with contextlib.redirect_stdout(io.StringIO()):
    mesh, clump = GenerateClump_Euclidean_3D(path, n, 0, 102, 0.6)
cpu, wall = time.process_time() - t0, time.perf_counter() - w0
print(json.dumps({"centres": (np.asarray(clump.positions) + (lo + hi) / 2).tolist(),
                  "radii": np.asarray(clump.radii).ravel().tolist(), "cpu": cpu, "wall": wall}))
'''


def bench_clumps(args):
    import grainforge
    from grainforge.dem.clump import clump, clump_quality
    from grainforge.io import write_mesh

    tmp = Path(tempfile.mkdtemp(prefix="bench-dem-"))
    grains = [("fso", grainforge.fso(rng=1)), ("cri", grainforge.cri(rng=2)), ("dpa", grainforge.dpa(rng=3))]
    cp = args.clump_python if args.clump_python and Path(args.clump_python).exists() else None
    if cp is None:
        print("clump-python: not available (give --clump-python PATH to its venv's python)")
    print(f"load average {os.getloadavg()}; our refinement iterations {args.iterations}")
    print("| grain | N | ours: spheres | coverage | spill % | CPU s (wall) | clump-python EDT: spheres | coverage | spill % | CPU s (wall) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    rows = []
    for name, g in grains:
        v, f = g.vertices, g.faces
        path = tmp / f"{name}.stl"
        write_mesh(g, path)
        for n in COUNTS:
            t0, w0 = time.process_time(), time.perf_counter()
            c = clump(v, f, spheres=n, rng=0, iterations=args.iterations, measure_resolution=100)
            cpu, wall = time.process_time() - t0, time.perf_counter() - w0
            # the same measure for both (not part of the timed call above in spirit: reported separately)
            cov, spill = clump_quality(v, f, c.centres, c.radii, resolution=100)
            t1 = time.process_time()
            clump_quality(v, f, c.centres, c.radii, resolution=100)
            qcpu = time.process_time() - t1
            ours = (c.count, cov, spill, cpu - qcpu, wall - qcpu)
            theirs = None
            if cp:
                out = subprocess.run([cp, "-c", CP_SCRIPT, str(path), str(n)], capture_output=True, text=True)
                if out.returncode == 0:
                    d = json.loads(out.stdout.strip().splitlines()[-1])
                    tc, tr = np.array(d["centres"]).reshape(-1, 3), np.array(d["radii"])
                    tcov, tspill = clump_quality(v, f, tc, tr, resolution=100)
                    theirs = (len(tr), tcov, tspill, d["cpu"], d["wall"])
                else:
                    print("clump-python failed:", out.stderr[-500:], file=sys.stderr)
            rows.append((name, n, ours, theirs))
            t = (f"{theirs[0]} | {theirs[1]:.3f} | {100 * theirs[2]:.2f} | {theirs[3]:.2f} ({theirs[4]:.2f})"
                 if theirs else "- | - | - | -")
            print(f"| {name} | {n} | {ours[0]} | {ours[1]:.3f} | {100 * ours[2]:.2f} | {ours[3]:.3f} ({ours[4]:.3f}) | {t} |",
                  flush=True)
    return rows


def _write_folder(folder: Path, count: int):
    import grainforge
    from grainforge.io import write_mesh

    base = [grainforge.fso(rng=1).scaled(5.0), grainforge.cri(rng=2).scaled(5.0), grainforge.dpa(rng=3).scaled(5.0)]
    for i in range(count):
        g = base[i % 3]
        write_mesh(g, folder / f"{g.method}-{i:05d}.stl")


def _run_tree(cmd):
    """Run ``cmd``; poll its process tree: (wall s, CPU s summed over every process, peak tree RSS MiB)."""
    import psutil

    w0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    root = psutil.Process(proc.pid)
    cpu, peak = {}, 0
    while proc.poll() is None:
        try:
            procs = [root] + root.children(recursive=True)
            rss = 0
            for p in procs:
                try:
                    t = p.cpu_times()
                    cpu[p.pid] = t.user + t.system
                    rss += p.memory_info().rss
                except psutil.Error:
                    pass
            peak = max(peak, rss)
        except psutil.Error:
            pass
        time.sleep(0.2)
    out, err = proc.communicate()
    wall = time.perf_counter() - w0
    if proc.returncode != 0:
        print(err)
        raise SystemExit(1)
    return wall, sum(cpu.values()), peak / 2**20


def bench_deck(args):
    tmp = Path(tempfile.mkdtemp(prefix="bench-dem-deck-"))
    exe = Path(sys.executable).parent / "grainforge"
    print("| grains | workers | wall s | CPU s (all processes) | CPU ms/grain | peak RSS of the process tree MiB | files |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for count in args.count:
        folder = tmp / f"grains{count}"
        folder.mkdir()
        _write_folder(folder, count)
        load = os.getloadavg()
        wall, cpu, rss = _run_tree([str(exe), "dem", str(folder), "--out", str(tmp / f"deck{count}"),
                                    "--engine", "liggghts", "--workers", str(args.workers)])
        files = len(list((tmp / f"deck{count}").iterdir()))
        if not args.keep:  # 10,000 grain files take ~7 GB
            shutil.rmtree(folder)
            shutil.rmtree(tmp / f"deck{count}")
        print(f"| {count} | {args.workers} | {wall:.1f} | {cpu:.1f} | {1000 * cpu / count:.0f} | {rss:.0f} | {files} |"
              f"  (load average before/after {load[0]:.1f}/{os.getloadavg()[0]:.1f})", flush=True)
    if not args.keep:
        shutil.rmtree(tmp, ignore_errors=True)


def main():
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="what", required=True)
    a = sub.add_parser("clumps")
    a.add_argument("--clump-python", default="/tmp/clumpbench/bin/python")
    a.add_argument("--iterations", type=int, default=0, help="our clump's refinement iterations (--refine-iterations)")
    b = sub.add_parser("deck")
    b.add_argument("--count", type=int, nargs="+", default=[10000])
    b.add_argument("--workers", type=int, default=2)
    b.add_argument("--keep", action="store_true", help="keep the grain folder and the deck (removed by default)")
    args = ap.parse_args()
    if args.what == "clumps":
        bench_clumps(args)
    else:
        bench_deck(args)


if __name__ == "__main__":
    main()
