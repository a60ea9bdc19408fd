"""Benchmark: the paper's print job as one command.

    grainforge tray --method cri --preset rough-angular --count 8000 --size 2 \
        --printer objet-eden-250 --out tray.3mf

Runs the command in a subprocess and reports wall time, the time its plan was
said (before any grain is made: resolution matching's pilot grains), and the
peak resident memory of the whole process tree (the command plus its worker
processes), sampled every 50 ms, then checks the files: number of objects, the
mesh resolution chosen, triangles and bytes of each print file.  Prints
figures; asserts nothing about time.

Usage: python benchmarks/bench_tray.py [--count N] [--method cri] [--workers 2] [--plates N|auto]
       [--max-triangles T] [--keep DIR]

The paper's specimen at the printer's tolerance: ``--plates auto`` (33 files for
8,000 grains); a fraction of it: ``--count 488 --plates auto`` (2 files).
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import threading
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


def _rss_tree(pid: int, cpu: dict[int, float] | None = None) -> int:
    """Resident set size (bytes) of ``pid`` and all its descendants; ``cpu`` gets each one's CPU seconds so far
    (user + system, from /proc/PID/stat)."""
    total, stack = 0, [pid]
    page = os.sysconf("SC_PAGE_SIZE")
    tick = os.sysconf("SC_CLK_TCK")
    while stack:
        p = stack.pop()
        try:
            with open(f"/proc/{p}/statm") as fh:
                total += int(fh.read().split()[1]) * page
            if cpu is not None:
                with open(f"/proc/{p}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
                cpu[p] = max(cpu.get(p, 0.0), (int(fields[11]) + int(fields[12])) / tick)  # utime, stime
        except (OSError, IndexError, ValueError):
            continue
        stack += _children(p)
    return total


def run(cmd: list[str], cwd: Path) -> tuple[float, int, subprocess.CompletedProcess, list[tuple[float, str]],
                                             list[tuple[float, float]]]:
    """Wall time, peak RSS of the tree, the finished process, each stderr line with its time (s from start), and
    the CPU seconds of the tree over time (sampled every 50 ms: what a process spent after its last sample is
    missed)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines: list[tuple[float, str]] = []

    def read():
        for line in proc.stderr:
            lines.append((time.perf_counter() - t0, line.rstrip("\n")))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    peak, cpu, timeline = 0, {}, []
    while proc.poll() is None:
        peak = max(peak, _rss_tree(proc.pid, cpu))
        timeline.append((time.perf_counter() - t0, sum(cpu.values())))
        time.sleep(0.05)
    reader.join()
    wall = time.perf_counter() - t0
    err = "\n".join(text for _, text in lines)
    return wall, peak, subprocess.CompletedProcess(cmd, proc.returncode, "", err), lines, timeline


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=8000)
    ap.add_argument("--method", default="cri")
    ap.add_argument("--preset", default="rough-angular")
    ap.add_argument("--size", type=float, default=2.0)
    ap.add_argument("--printer", default="objet-eden-250")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="tray.3mf")
    ap.add_argument("--plates", default="1", help="Print files: N or auto (tray --plates).")
    ap.add_argument("--max-triangles", type=int, default=None, help="Triangle budget of a print file.")
    ap.add_argument("--keep", type=Path, default=None, help="Folder to keep the outputs in.")
    args = ap.parse_args()

    exe = Path(sys.executable).with_name("grainforge")
    cmd = [str(exe), "tray", "--method", args.method, "--count", str(args.count), "--size", str(args.size),
           "--printer", args.printer, "--workers", str(args.workers), "--out", args.out, "--overwrite",
           "--plates", args.plates]
    if args.max_triangles is not None:
        cmd += ["--max-triangles", str(args.max_triangles)]
    if args.preset and args.method == "cri":
        cmd += ["--preset", args.preset]
    with tempfile.TemporaryDirectory() as tmp:
        where = args.keep or Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        load = os.getloadavg()
        wall, peak, res, lines, timeline = run(cmd, where)
        print("command:", " ".join(["grainforge"] + cmd[1:]))
        print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
        if res.returncode != 0:
            print(res.stderr)
            raise SystemExit(f"tray failed with exit code {res.returncode}")
        out = where / args.out
        with open(out.with_suffix(".csv"), newline="") as fh:
            rows = list(csv.DictReader(fh))
        faces = sum(int(r["faces"]) for r in rows)
        plan = [(t, text) for t, text in lines if text.startswith(("resolution matching", "plan:"))]
        for t, text in plan + [(t, text) for t, text in lines if text.startswith("WARNING")]:
            print(f"[{t:6.1f} s] {text}")
        print(f"plan said by: {plan[-1][0]:.1f} s" if plan else "no plan said")
        plates = sorted({int(r["plate"]) for r in rows})
        files = [out] if len(plates) == 1 else [out.with_name(f"{out.stem}-plate{k}{out.suffix}") for k in plates]
        per_file = [sum(int(r["faces"]) for r in rows if int(r["plate"]) == k) for k in plates]
        sizes = [f.stat().st_size for f in files]
        print(f"grains: {len(rows)}  plates: {len(plates)}  "
              f"subdivisions: {sorted({r['subdivisions'] for r in rows})}  triangles: {faces:,}")
        print(f"files: {len(files)}, {sum(sizes) / 1e6:.1f} MB in all, largest {max(sizes) / 1e6:.1f} MB; "
              f"most triangles in a file: {max(per_file):,}")
        print(f"wall time: {wall:.1f} s   peak RSS (process tree): {peak / 2**20:.0f} MiB")
        print(f"throughput: {len(rows) / wall:.1f} grains/s")
        cpu = timeline[-1][1]
        before = max((c for t, c in timeline if plan and t <= plan[-1][0]), default=0.0)
        grain = (cpu - before) / len(rows)
        print(f"CPU time of the process tree: {cpu:.0f} s, {before:.0f} s of it before the plan was said, then "
              f"{grain:.2f} s a grain; on {args.workers} idle cores about {before + grain * len(rows) / args.workers:.0f}"
              f" s ({before:.0f} s + {grain:.2f} s x grains / {args.workers})")


if __name__ == "__main__":
    main()
