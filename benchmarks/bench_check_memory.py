"""Benchmark: peak memory of ``grainforge check`` for every generator, grain size and printer profile.

For each generator (fso, cri, dpa, angular, rf) and size (default 0.5, 2 and
20 mm, i.e. from below the printers' reliable sizes to large), one grain is
generated with the generator's defaults (and, for the geodesic generators, also
at ``--subdivisions 6``, the finest level resolution matching chooses); then

    /usr/bin/time -f %M grainforge check FILE --printer P

runs for every built-in printer profile and the peak resident memory it
reports (kB, the check process) is printed with the wall time and the
status.  Last, the case that ran out of memory: one check of a folder of 20 CRI
grains of 2 mm on generic-fdm.  A run may be capped with ``--limit-gb`` (an
address-space limit, so that an old, unbounded version fails with a
MemoryError instead of exhausting the machine).  Prints figures; asserts
nothing.

Usage: python benchmarks/bench_check_memory.py [--sizes 0.5,2,20] [--methods fso,cri,...]
       [--printers objet-eden-250,generic-fdm,generic-sla] [--levels 5,6] [--folder 20] [--limit-gb 8]
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GEODESIC = {"fso", "cri", "angular", "rf"}  # generators with --subdivisions


def _limit(gb: float | None):
    if gb is None:
        return None

    def apply():
        n = int(gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (n, n))

    return apply


def generate(exe: Path, method: str, size: float, level: int | None, out: Path, count: int = 1) -> list[Path]:
    cmd = [str(exe), "generate", method, "--count", str(count), "--size", str(size), "--out", str(out)]
    if level is not None:
        cmd += ["--subdivisions", str(level)]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return sorted(out.glob("*.stl"))


def check(exe: Path, target: Path, printer: str, limit_gb: float | None) -> tuple[int, float, str]:
    """Peak RSS (kB) from /usr/bin/time, wall seconds, and the status word(s) or the error line."""
    cmd = ["/usr/bin/time", "-f", "%M", str(exe), "check", str(target), "--printer", printer, "--csv"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, preexec_fn=_limit(limit_gb), check=False)
    wall = time.perf_counter() - t0
    err = proc.stderr.strip().splitlines()
    peak = int(err[-1]) if err and err[-1].isdigit() else -1
    if proc.returncode in (0, 1):
        rows = [ln.split(",") for ln in proc.stdout.strip().splitlines()[1:]]
        status = {r[2] for r in rows}
        what = "/".join(sorted(status)) + (f" ({len(rows)} parts)" if len(rows) > 1 else "")
    else:
        what = next((ln for ln in err if ln.startswith("Error")), f"exit {proc.returncode}")
    return peak, wall, what


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", default="fso,cri,dpa,angular,rf")
    ap.add_argument("--sizes", default="0.5,2,20")
    ap.add_argument("--printers", default="objet-eden-250,generic-fdm,generic-sla")
    ap.add_argument("--levels", default="5,6", help="Subdivision levels of the geodesic generators (5: default).")
    ap.add_argument("--folder", type=int, default=20, help="Grains in the folder case (0: skip it).")
    ap.add_argument("--limit-gb", type=float, default=None, help="Address-space limit of each check run.")
    args = ap.parse_args()

    exe = Path(sys.executable).with_name("grainforge")
    printers = args.printers.split(",")
    print(f"{'method':8} {'size_mm':>7} {'level':>5} {'faces':>6}  {'printer':15} {'peak_MB':>8} {'wall_s':>7}  status")
    worst = 0
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for method in args.methods.split(","):
            levels = [int(x) for x in args.levels.split(",")] if method in GEODESIC else [None]
            for size in (float(s) for s in args.sizes.split(",")):
                for level in levels:
                    out = tmp / f"{method}-{size:g}-{level}"
                    (path,) = generate(exe, method, size, None if level == 5 else level, out)
                    faces = (path.stat().st_size - 84) // 50  # binary STL
                    for printer in printers:
                        peak, wall, what = check(exe, path, printer, args.limit_gb)
                        worst = max(worst, peak)
                        print(f"{method:8} {size:7g} {level if level is not None else '-':>5} {faces:6d}  "
                              f"{printer:15} {peak / 1024:8.0f} {wall:7.1f}  {what}", flush=True)
        if args.folder:
            folder = tmp / "folder"
            generate(exe, "cri", 2.0, None, folder, count=args.folder)
            for printer in printers:
                peak, wall, what = check(exe, folder, printer, args.limit_gb)
                worst = max(worst, peak)
                print(f"{'cri x' + str(args.folder):8} {2.0:7g} {5:>5} {20480:6d}  {printer:15} {peak / 1024:8.0f} "
                      f"{wall:7.1f}  {what}", flush=True)
    print(f"largest peak: {worst / 1024:.0f} MB")


if __name__ == "__main__":
    main()
