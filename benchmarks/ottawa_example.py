"""The README's worked example end to end, timed: Ottawa sand → recipe → 500 grains → measured files.

1. ``grainforge fit examples/sand-atlas/ottawa-7.3um.csv --voxel-size-um 7.3 --out OUT/fit``
2. ``grainforge batch OUT/fit/recipe.toml --out OUT/grains``
3. ``grainforge analyse OUT/grains --voxel-size-mm 0.0073 --no-fractal --csv OUT/grains.csv`` — the
   STL files as a user gets them, read back and voxelised in their own orientation (the fit
   measured each grain in memory, in a random orientation)
4. the sand's statistics against those of the files: mean, sd, two-sample KS (scipy), and the
   verdict of the fit's acceptance criteria (KS ≤ 0.1, |mean difference| ≤ 0.01; docs/fit.md).

Usage: ``python benchmarks/ottawa_example.py [--out DIR] [--method rf]``; prints the times
and a Markdown table.  About 5 min on the idle 2-core machine.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAND = ROOT / "examples" / "sand-atlas" / "ottawa-7.3um.csv"
NAMES = ("sphericity", "convexity", "flatness", "elongation")


def run(args: list[str]) -> float:
    t = time.perf_counter()
    exe = Path(sys.executable).with_name("grainforge")  # the console script beside this interpreter
    subprocess.run([str(exe), *args], check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def main():
    import numpy as np
    from scipy.stats import ks_2samp

    from grainforge.fit import read_sand

    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "ottawa-example")
    ap.add_argument("--method", default="rf")
    args = ap.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    args.out.mkdir(parents=True)
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    times = {
        "fit": run(["fit", str(SAND), "--voxel-size-um", "7.3", "--method", args.method, "--out", str(args.out / "fit")]),
        "batch": run(["batch", str(args.out / "fit" / "recipe.toml"), "--out", str(args.out / "grains")]),
        "analyse": run(["analyse", str(args.out / "grains"), "--voxel-size-mm", "0.0073", "--no-fractal",
                        "--csv", str(args.out / "grains.csv")]),
    }
    print(", ".join(f"{k} {v:.0f} s" for k, v in times.items()) + f"; total {sum(times.values()) / 60:.1f} min; "
          f"load average {os.getloadavg()[0]:.2f}")
    sand = read_sand(SAND, 7.3).table()
    with open(args.out / "grains.csv", encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    print(f"\n{len(rows)} grain files measured\n")
    print("| descriptor | sand mean ± sd | files mean ± sd | mean diff (≤ 0.01) | KS (≤ 0.1) |")
    print("|---|---|---|---|---|")
    ok = True
    for j, k in enumerate(NAMES):
        g = np.array([float(r[f"atlas_{k}"]) for r in rows])
        d, ks = g.mean() - sand[:, j].mean(), ks_2samp(sand[:, j], g).statistic
        ok &= abs(d) <= 0.01 and ks <= 0.1
        print(f"| {k} | {sand[:, j].mean():.3f} ± {sand[:, j].std(ddof=1):.3f} | {g.mean():.3f} ± "
              f"{g.std(ddof=1):.3f} | {d:+.4f} | {ks:.3f} |")
    print(f"\nthe files {'pass' if ok else 'do NOT pass'} the criteria")


if __name__ == "__main__":
    main()
