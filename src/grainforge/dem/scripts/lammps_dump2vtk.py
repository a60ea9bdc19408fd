"""Convert LAMMPS text dumps post/grains.*.dump (id mol x y z vx vy vz radius) to legacy VTK."""
import glob
import os

for path in sorted(glob.glob(os.path.join("post", "grains.*.dump"))):
    lines = open(path).read().splitlines()
    start = next(i for i, l in enumerate(lines) if l.startswith("ITEM: ATOMS")) + 1
    rows = [l.split() for l in lines[start:] if l.strip()]
    n = len(rows)
    out = ["# vtk DataFile Version 3.0", "grainforge LAMMPS " + os.path.basename(path), "ASCII",
           "DATASET POLYDATA", "POINTS %d double" % n]
    out += [" ".join(r[2:5]) for r in rows]
    out += ["VERTICES %d %d" % (n, 2 * n)] + ["1 %d" % i for i in range(n)]
    out += ["POINT_DATA %d" % n, "SCALARS radius double 1", "LOOKUP_TABLE default"] + [r[8] for r in rows]
    out += ["SCALARS mol int 1", "LOOKUP_TABLE default"] + [r[1] for r in rows]
    out += ["VECTORS velocity double"] + [" ".join(r[5:8]) for r in rows]
    with open(path[:-5] + ".vtk", "w") as fh:
        fh.write("\n".join(out) + "\n")
