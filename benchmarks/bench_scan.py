"""Time and peak memory of ``grainforge scan`` on a labelled volume (target: 1,000³ uint16, ~5,000 grains, ≤ 2 GB,
≤ 10 min on 2 cores).

The volume: rotated ellipsoids (semi-axes drawn in 0.30–0.46 of the cell, so neighbours often touch) on a
jittered cubic grid of ``--grains`` cells, labels 1 … n as uint16, written slab by slab into a ``.npy`` (the
generator holds one layer of cells).  At 1,000³ and 5,000 grains a cell is 58.5 voxels and a grain about 45
voxels across.  ``grainforge scan`` then runs as its own process (``--workers``, default 2) and this script
reports its wall clock, CPU time and peak resident memory (the process tree sampled every 0.2 s, and each
process's own kernel-kept peak, ``VmHWM``), and the rate.

Usage (the full size needs ~2 GB of disk for the image):

    .venv/bin/python benchmarks/bench_scan.py --size 1000 --grains 5000
    .venv/bin/python benchmarks/bench_scan.py --size 400            # grains scaled to keep ~45 voxels across
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def make_volume(path: Path, size: int, grains: int, seed: int = 0) -> int:
    """Write the labelled volume; return the number of labels."""
    rng = np.random.default_rng(seed)
    n = max(1, round(grains ** (1 / 3)))
    cell = size / n
    out = np.lib.format.open_memmap(path, mode="w+", dtype=np.uint16, shape=(size, size, size))
    label = 0
    for i in range(n):
        z0, z1 = int(round(i * cell)), int(round((i + 1) * cell))
        layer = np.zeros((z1 - z0, size, size), np.uint16)
        for j in range(n):
            for k in range(n):
                y0, x0 = int(round(j * cell)), int(round(k * cell))
                y1, x1 = int(round((j + 1) * cell)), int(round((k + 1) * cell))
                axes = rng.uniform(0.30, 0.46, 3) * cell
                centre = (np.array([(z1 - z0) / 2, (y1 - y0) / 2, (x1 - x0) / 2])
                          + rng.uniform(-0.04, 0.04, 3) * cell)
                q = rng.normal(size=4)
                q /= np.linalg.norm(q)
                w, x, y, z = q
                R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                              [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                              [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
                g = np.stack(np.meshgrid(np.arange(z1 - z0), np.arange(y1 - y0), np.arange(x1 - x0),
                                         indexing="ij"), -1) + 0.5 - centre
                local = g @ R
                inside = ((local / axes) ** 2).sum(-1) <= 1.0
                label += 1
                layer[:, y0:y1, x0:x1][inside] = label
        out[z0:z1] = layer
    out.flush()
    del out
    return label


def _tree_rss(root: int, cpu: dict, hwm: dict) -> int:
    """Resident bytes of ``root`` and every process below it (Linux /proc); each one's CPU seconds into ``cpu``
    and its own peak resident bytes (``VmHWM``, kept by the kernel: no sampling misses it) into ``hwm``."""
    parent, rss, used = {}, {}, {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            parent[int(d)] = int(fields[1])
            rss[int(d)] = int(fields[21]) * os.sysconf("SC_PAGE_SIZE")
            used[int(d)] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        except (OSError, IndexError, ValueError):
            continue
    tree, todo = {root}, [root]
    while todo:
        p = todo.pop()
        for c, pp in parent.items():
            if pp == p and c not in tree:
                tree.add(c)
                todo.append(c)
    for p in tree:
        if p in used:
            cpu[p] = max(cpu.get(p, 0.0), used[p])
        try:
            with open(f"/proc/{p}/status") as fh:
                peak = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmHWM:"))
            hwm[p] = max(hwm.get(p, 0), peak)
        except (OSError, StopIteration, ValueError):
            pass
    return sum(rss.get(p, 0) for p in tree)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=400, help="edge of the cubic image, voxels")
    ap.add_argument("--grains", type=int, default=None,
                    help="grains (default: 5,000 × (size/1000)³, so they stay ~45 voxels across)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", type=Path, default=None, help="keep the image and table in this folder")
    args = ap.parse_args()
    grains = args.grains or max(1, round(5000 * (args.size / 1000) ** 3))
    work = Path(tempfile.mkdtemp(prefix="bench-scan-")) if args.keep is None else args.keep
    work.mkdir(parents=True, exist_ok=True)
    image = work / f"labels-{args.size}.npy"
    t = time.perf_counter()
    labels = make_volume(image, args.size, grains)
    made = time.perf_counter() - t
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; image {args.size}³ uint16 "
          f"({image.stat().st_size / 1e9:.2f} GB), {labels} labels, made in {made:.0f} s", flush=True)
    exe = Path(sys.executable).with_name("grainforge")
    table = work / "sand.csv"
    cmd = [str(exe), "scan", str(image), "--voxel-size-um", "7.3", "--atlas-csv", str(table), "--overwrite",
           "--workers", str(args.workers)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    peak_tree, cpu_seen, hwm = 0, {}, {}
    while proc.poll() is None:
        peak_tree = max(peak_tree, _tree_rss(proc.pid, cpu_seen, hwm))
        time.sleep(0.2)
    err = proc.stderr.read()
    wall = time.perf_counter() - t
    done = subprocess.CompletedProcess(cmd, proc.returncode, None, err)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit(f"scan failed ({done.returncode}): {done.stderr.strip()}")
    # the command's own CPU from its rusage, its workers' as last sampled (they are not its waited children)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    cpu += sum(v for p, v in cpu_seen.items() if p != proc.pid)
    # each process's own peak (VmHWM).  Not ru_maxrss: the child's count starts from this script's resident
    # pages at the fork, and this script has just written the 2-GB image through a memory map (the kernel keeps
    # that high-water mark across exec), so ru_maxrss reports this script's memory, not the scan's
    peak = max(hwm.values(), default=0) / 1e6
    peak_sum = sum(hwm.values()) / 1e6  # an upper bound on the tree's peak (every process at its own peak at once)
    measured = sum(1 for _ in table.open(encoding="utf-8")) - 1
    print(done.stderr.strip().splitlines()[-2] if len(done.stderr.strip().splitlines()) > 1 else done.stderr.strip())
    print("| image | labels | measured | workers | wall s | CPU s | grains/s (wall) | peak RSS MB, all processes: "
          "sampled (sum of each one's peak) | largest process's peak MB |")
    print("|---|---|---|---|---|---|---|---|---|")
    print(f"| {args.size}³ uint16 | {labels} | {measured} | {args.workers} | {wall:.0f} | {cpu:.0f} | "
          f"{measured / wall:.2f} | {peak_tree / 1e6:.0f} ({peak_sum:.0f}) | {peak:.0f} |")
    full = 5000 / (measured / wall) if measured else math.nan
    print(f"at this rate 5,000 grains take about {full / 60:.1f} min of wall clock")


if __name__ == "__main__":
    main()
