"""The demo's DPA section, written in full and checked as readers see it: every file
must read back as a valid solid and pass ``grainforge check``.

Run: ``nice .venv/bin/python benchmarks/validate_dpa_demo.py [--out DIR]`` (≈ 5 min under load).
Writes ``grainforge.viz.demo.dpa_sweeps`` (300 primaries: cubes, smoothed cubes, octahedra; ε 0.1–100;
3 seeds), then reads every STL back with trimesh (merging vertices by position) and with admesh,
and runs ``grainforge check`` on all of them.  Prints the counts; asserts nothing.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    import trimesh

    from grainforge.geometry.solid import solid_problems
    from grainforge.viz.demo import dpa_sweeps

    out = args.out or Path(tempfile.mkdtemp(prefix="dpa-demo-"))
    t = time.time()
    dpa_sweeps(out, quick=False)
    stls = sorted(str(p) for p in out.rglob("*.stl"))
    print(f"{len(stls)} STL files written to {out} in {time.time() - t:.0f} s")
    bad = 0
    for p in stls:
        m = trimesh.load(p)
        ok = (m.is_watertight and m.is_winding_consistent and m.body_count == 1 and m.volume > 0
              and not solid_problems(m.vertices, m.faces))
        a = subprocess.run(["admesh", p], capture_output=True).stdout.decode(errors="replace")  # admesh echoes the header unterminated
        vals = [int(re.search(rf"{k}\s*:\s*(\d+)", a).group(1)) for k in (
            "Number of parts", "Degenerate facets", "Facets reversed", "Edges fixed", "Facets removed", "Backwards edges")]
        if not ok or vals[0] != 1 or any(vals[1:]):
            bad += 1
            print("invalid:", p, vals)
    print(f"invalid by trimesh or admesh: {bad}")
    r = subprocess.run([str(Path(sys.executable).with_name("grainforge")), "check", *stls], capture_output=True, text=True)
    fails = sum(" FAIL " in line for line in r.stdout.splitlines())
    print(f"grainforge check: exit {r.returncode}, {fails} FAIL")


if __name__ == "__main__":
    main()
