"""A twin fit through the CLI, timed, with every criterion's figure (docs/fit.md, docs/benchmarks.md).

Runs ``grainforge fit SAND --out OUT [--method M] [--count N] [options]`` as a user would (the
console script beside this interpreter), times it, and prints its stderr log (the estimate, one
line per phase, the verdict) and ``fit-stats.csv`` as a Markdown table: per descriptor mean, sd
and KS; the six Spearman correlations; the twins' share within 0.03 and the unreachable share.
The design cache is the user's (``$GRAINFORGE_CACHE``); ``--fresh-cache DIR`` uses an empty one
so that the design is measured and timed too.  Usage::

    nice .venv/bin/python benchmarks/fit_twins.py                                   # Ottawa, rf, 500 twins
    nice .venv/bin/python benchmarks/fit_twins.py --sand tests/data/synthetic-rf-sand.csv --method auto
    nice .venv/bin/python benchmarks/fit_twins.py --sand tests/data/synthetic-1um-sand.csv
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
OTTAWA = ROOT / "examples" / "sand-atlas" / "ottawa-7.3um.csv"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sand", type=Path, default=OTTAWA)
    ap.add_argument("--voxel-size-um", default=None, help="default: 7.3 for Ottawa, else the CSV's column")
    ap.add_argument("--method", default="rf")
    ap.add_argument("--count", default="500")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "fit-twins")
    ap.add_argument("--fresh-cache", type=Path, default=None)
    ap.add_argument("--workers", default="2")
    args, extra = ap.parse_known_args()
    shutil.rmtree(args.out, ignore_errors=True)
    voxel = args.voxel_size_um or ("7.3" if args.sand == OTTAWA else None)
    cmd = ["fit", str(args.sand), "--out", str(args.out), "--method", args.method, "--count", args.count,
           "--workers", args.workers, *(["--voxel-size-um", voxel] if voxel else []), *extra]
    if args.fresh_cache is not None:
        shutil.rmtree(args.fresh_cache, ignore_errors=True)
        cmd += ["--cache-dir", str(args.fresh_cache)]
    exe = Path(sys.executable).with_name("grainforge")
    print(f"$ grainforge {' '.join(cmd)}\nload average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    t = time.perf_counter()
    proc = subprocess.run([str(exe), *cmd], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t
    for line in proc.stderr.splitlines():
        line = line.split("\r")[-1].strip()
        if line and "grain/s" not in line and "it/s" not in line:
            print("  " + line)
    print(f"exit {proc.returncode}; wall clock {wall:.0f} s ({wall / 60:.1f} min); load average "
          f"{os.getloadavg()[0]:.2f}\n")
    if proc.returncode not in (0, 1):
        sys.exit(proc.returncode)
    with open(args.out / "fit-stats.csv", encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    print("| statistic | quantity | sand | generated | difference | criterion | pass |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        cells = [r[k] if not _num(r[k]) else f"{float(r[k]):.3f}" for k in
                 ("statistic", "quantity", "sand", "generated", "difference", "criterion", "pass")]
        print("| " + " | ".join(cells) + " |")


def _num(x: str) -> bool:
    try:
        float(x)
    except ValueError:
        return False
    return x not in ("True", "False")


if __name__ == "__main__":
    main()
