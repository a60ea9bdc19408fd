"""Convert LAMMPS vertex dumps post/vertices.*.dump (compute body/local: id x y z per hull vertex,
in the order of data.bodies, um) to legacy-VTK polygon meshes in metres, using the hull faces in
grains.json."""
import glob
import json
import os

deck = json.load(open("grains.json"))
scale = 1.0 / deck["micro"]["length"]  # the dumps are in um; the VTK files in m
faces = {p["id"]: deck["grains"][p["grain"]]["faces"] for p in deck["placements"]}
for path in sorted(glob.glob(os.path.join("post", "vertices.*.dump"))):
    lines = open(path).read().splitlines()
    start = next(i for i, l in enumerate(lines) if l.startswith("ITEM: ENTRIES")) + 1
    rows = [l.split() for l in lines[start:] if l.strip()]
    bodies = {}
    for r in rows:
        bodies.setdefault(int(r[0]), []).append(" ".join(repr(float(x) * scale) for x in r[1:4]))
    points, polys, ids = [], [], []
    for bid in sorted(bodies):
        base = len(points)
        points += bodies[bid]
        for f in faces[bid]:
            polys.append("3 %d %d %d" % (base + f[0], base + f[1], base + f[2]))
            ids.append(str(bid))
    out = ["# vtk DataFile Version 3.0", "grainforge LAMMPS bodies " + os.path.basename(path), "ASCII",
           "DATASET POLYDATA", "POINTS %d double" % len(points)]
    out += points
    out += ["POLYGONS %d %d" % (len(polys), 4 * len(polys))] + polys
    out += ["CELL_DATA %d" % len(polys), "SCALARS body int 1", "LOOKUP_TABLE default"] + ids
    with open(path[:-5] + ".vtk", "w") as fh:
        fh.write("\n".join(out) + "\n")
