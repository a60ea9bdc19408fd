"""Benchmark: the paper's print job as one command.

    grainforge tray --method cri --preset rough-angular --count 8000 --size 2 \
        --printer objet-eden-250 --out tray.3mf

Runs the command in a subprocess and reports wall time and the peak resident
memory of the whole process tree (the command plus its worker processes),
sampled every 50 ms, then checks the file: number of objects, and the mesh
resolution chosen.  Prints figures; asserts nothing about time.

Usage: python benchmarks/bench_tray.py [--count N] [--method cri] [--workers 2] [--keep DIR]
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _children(pid: int) -> list[int]:
    out = []
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{tid}/children") as fh:
                out += [int(x) for x in fh.read().split()]
    except OSError:
        pass
    return out


def _rss_tree(pid: int) -> int:
    """Resident set size (bytes) of ``pid`` and all its descendants."""
    total, stack = 0, [pid]
    page = os.sysconf("SC_PAGE_SIZE")
    while stack:
        p = stack.pop()
        try:
            with open(f"/proc/{p}/statm") as fh:
                total += int(fh.read().split()[1]) * page
        except OSError:
            continue
        stack += _children(p)
    return total


def run(cmd: list[str], cwd: Path) -> tuple[float, int, subprocess.CompletedProcess]:
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peak = 0
    while proc.poll() is None:
        peak = max(peak, _rss_tree(proc.pid))
        time.sleep(0.05)
    out, err = proc.communicate()
    wall = time.perf_counter() - t0
    return wall, peak, subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=8000)
    ap.add_argument("--method", default="cri")
    ap.add_argument("--preset", default="rough-angular")
    ap.add_argument("--size", type=float, default=2.0)
    ap.add_argument("--printer", default="objet-eden-250")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="tray.3mf")
    ap.add_argument("--keep", type=Path, default=None, help="Folder to keep the outputs in.")
    args = ap.parse_args()

    exe = Path(sys.executable).with_name("grainforge")
    cmd = [str(exe), "tray", "--method", args.method, "--count", str(args.count), "--size", str(args.size),
           "--printer", args.printer, "--workers", str(args.workers), "--out", args.out, "--overwrite"]
    if args.preset and args.method == "cri":
        cmd += ["--preset", args.preset]
    with tempfile.TemporaryDirectory() as tmp:
        where = args.keep or Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        load = os.getloadavg()
        wall, peak, res = run(cmd, where)
        print("command:", " ".join(["grainforge"] + cmd[1:]))
        print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
        if res.returncode != 0:
            print(res.stderr)
            raise SystemExit(f"tray failed with exit code {res.returncode}")
        out = where / args.out
        with open(out.with_suffix(".csv"), newline="") as fh:
            rows = list(csv.DictReader(fh))
        faces = sum(int(r["faces"]) for r in rows)
        for line in res.stderr.strip().splitlines():  # the resolution choice and any warning
            if line.startswith(("resolution matching", "WARNING")):
                print(line)
        print(f"grains: {len(rows)}  plates: {len({r['plate'] for r in rows})}  "
              f"subdivisions: {sorted({r['subdivisions'] for r in rows})}  triangles: {faces:,}")
        print(f"file: {out.stat().st_size / 1e6:.1f} MB")
        print(f"wall time: {wall:.1f} s   peak RSS (process tree): {peak / 2**20:.0f} MiB")
        print(f"throughput: {len(rows) / wall:.0f} grains/s")


if __name__ == "__main__":
    main()
