"""Measured control of the angular generator: flatness, edge radius, descriptor range.

Every grain is generated, written to STL at its printed size, read back with
trimesh (vertices merged by position) and measured there.

    nice .venv/bin/python benchmarks/validate_angular.py [--grains 20] [--only flatness,radius,range]

Prints Markdown tables (docs/validation.md, "Angular grains").
"""

from __future__ import annotations

import argparse
import io
import sys
import time

import numpy as np
import trimesh

from grainforge.analysis.facets import edge_radius, facet_flatness
from grainforge.fabrication.scale import to_size
from grainforge.geometry.solid import volume_centroid
from grainforge.io import export_bytes
from grainforge.methods import generate
from grainforge.methods.angular import Params, build, core, core_edges

SIZE_MM = 2.0


def written(params: Params, seed: int, size: float = SIZE_MM):
    """(mesh read back from STL, scale, centroid offset in R0 units) of one grain at ``size`` mm."""
    g = to_size(generate("angular", params, seed), size)
    mesh = trimesh.load(io.BytesIO(export_bytes(g, "stl")), file_type="stl")
    v, f, _ = build(params, np.random.default_rng(seed))
    return mesh, g.info["scale"], volume_centroid(v, f), g


def flatness_table(n: int) -> None:
    print("\n### Facet flatness (share of area within 2° of a facet plane)\n")
    print("| rounding | roughness | grains | mean | min | max |")
    print("|---|---|---|---|---|---|")
    for rounding in (0.0, 0.2):
        for rough in (0.0, 0.005, 0.01, 0.02, 0.04, 0.08):
            p = Params(rounding=rounding, roughness=rough)
            vals = []
            for seed in range(n):
                mesh, _, _, _ = written(p, seed)
                c = core(p, np.random.default_rng(seed))
                vals.append(facet_flatness(mesh.vertices, mesh.faces, c.normals))
            vals = np.array(vals)
            print(f"| {rounding:g} | {rough:g} | {n} | {vals.mean():.3f} | {vals.min():.3f} | {vals.max():.3f} |",
                  flush=True)


def edge_cut(mesh, point, direction) -> float:
    """Distance from a sharp edge's true position to the mesh, in its cross-section (mesh units)."""
    segs = trimesh.intersections.mesh_plane(mesh, plane_normal=direction, plane_origin=point)
    a, b = segs[:, 0] - point, segs[:, 1] - point
    ab = b - a
    t = np.clip(-(a * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-30), 0, 1)
    return float(np.linalg.norm(a + t[:, None] * ab, axis=1).min())


def radius_table(n: int, subdivisions: int) -> None:
    print(f"\n### Edge radius of curvature (cross-sections of the STL, subdivisions {subdivisions})\n")
    print("| rounding | requested ρ (mm, mean) | measured (mm, mean) | measured / requested: mean | sd | edges | grains |")
    print("|---|---|---|---|---|---|---|")
    for rounding in (0.0, 0.1, 0.2, 0.4, 0.6, 0.8):
        p = Params(rounding=rounding, subdivisions=subdivisions)
        req, meas, ratio, cut, grains = [], [], [], [], 0
        for seed in range(n):
            mesh, scale, off, _ = written(p, seed)
            mesh.apply_translation(off * scale)  # back to the core's frame (scaled)
            c = core(p, np.random.default_rng(seed))
            rho = c.rho * scale
            grains += 1
            for mid, d, length, i, j in core_edges(c):
                turn = np.arccos(np.clip(c.normals[i] @ c.normals[j], -1, 1))
                if turn < np.deg2rad(20) or length < 1e-3:
                    continue  # nearly flat edges have too short an arc to fit
                if rounding == 0:
                    cut.append(edge_cut(mesh, mid * scale, d))
                    continue
                reach = 1.5 * c.rho * scale
                r = edge_radius(mesh, mid * scale, direction=d, n1=c.normals[i], n2=c.normals[j], reach=reach)
                if r is None:
                    continue
                req.append(rho)
                meas.append(r)
                ratio.append(r / rho if rho > 0 else np.nan)
        if rounding == 0:
            cut = np.array(cut) * 1000
            print(f"| 0 (sharp) | 0 | edge cut by the mesh: mean {cut.mean():.1f} µm, 95th pct "
                  f"{np.percentile(cut, 95):.1f} µm, max {cut.max():.1f} µm | — | — | {len(cut)} | {grains} |", flush=True)
            continue
        req, meas, ratio = map(np.array, (req, meas, ratio))
        print(f"| {rounding:g} | {req.mean():.4f} | {meas.mean():.4f} | {ratio.mean():.3f} | {ratio.std():.3f} "
              f"| {len(meas)} | {grains} |", flush=True)


#: settings of the range table, from near-spherical convex to angular-sand shapes
RANGE = [
    ("near-spherical: 40 facets, rounding 0.8", Params(facets=40, aspect=(1, 1, 1), rounding=0.8)),
    ("default (20 facets, 1.3:1.1:1, rounding 0.1)", Params()),
    ("sharp, rough: 16 facets, 1.8:1.3:1, rounding 0, roughness 0.02", Params(
        facets=16, aspect=(1.8, 1.3, 1.0), rounding=0.0, roughness=0.02)),
    ("Hostun-like: 16 facets, 2:1.4:1, 6 dents 0.5/0.5, roughness 0.01", Params(
        facets=16, aspect=(2.0, 1.4, 1.0), rounding=0.1, dents=6, dent_depth=0.5, dent_width=0.5,
        roughness=0.01, length_ratio=2.0)),
    ("angular corner: 12 facets, 2.4:1.6:1, 10 dents 0.65/0.5, roughness 0.01", Params(
        facets=12, aspect=(2.4, 1.6, 1.0), rounding=0.1, dents=10, dent_depth=0.65, dent_width=0.5,
        roughness=0.01, length_ratio=2.0)),
]


def range_table(n: int) -> None:
    from grainforge.analysis.descriptors import basic_descriptors
    from grainforge.fabrication.printability import check_mesh

    print(f"\n### Range reached (mesh sphericity and convexity; printability at {SIZE_MM:g} mm, objet-eden-250)\n")
    print("| setting | grains | sphericity mean (min–max) | convexity mean (min–max) "
          "| printable (OK or WARN) | grains with sph ≤ 0.70 and conv ≤ 0.78, printable |")
    print("|---|---|---|---|---|---|")
    for label, p in RANGE:
        sph, conv, ok, corner = [], [], 0, 0
        for seed in range(n):
            mesh, _, _, g = written(p, seed)
            d = basic_descriptors(mesh)
            chk = check_mesh(mesh.vertices, mesh.faces, "objet-eden-250")
            sph.append(d["sphericity"])
            conv.append(d["convexity"])
            ok += chk.ok
            corner += chk.ok and d["sphericity"] <= 0.70 and d["convexity"] <= 0.78
        sph, conv = np.array(sph), np.array(conv)
        print(f"| {label} | {n} | {sph.mean():.3f} ({sph.min():.3f}–{sph.max():.3f}) | {conv.mean():.3f} "
              f"({conv.min():.3f}–{conv.max():.3f}) | {ok}/{n} | {corner}/{n} |", flush=True)


def atlas_table(n: int, voxels_across: float = 60.0) -> None:
    """The same settings measured as a μCT study would (Sand-Atlas definitions, analysis.atlas)."""
    from grainforge.analysis.atlas import atlas_descriptors

    print(f"\n### Range reached, Atlas-style voxel descriptors ({voxels_across:g} voxels across d_eq)\n")
    print("| setting | grains | true sphericity mean (min–max) | convexity mean (min–max) "
          "| grains with sph ≤ 0.70 and conv ≤ 0.78 |")
    print("|---|---|---|---|---|")
    for label, p in RANGE:
        sph, conv = [], []
        for seed in range(n):
            mesh, _, _, _ = written(p, seed)
            d = atlas_descriptors(mesh, voxels_across=voxels_across)
            sph.append(d["sphericity"])
            conv.append(d["convexity"])
        sph, conv = np.array(sph), np.array(conv)
        both = int(np.sum((sph <= 0.70) & (conv <= 0.78)))
        print(f"| {label} | {n} | {sph.mean():.3f} ({sph.min():.3f}–{sph.max():.3f}) | {conv.mean():.3f} "
              f"({conv.min():.3f}–{conv.max():.3f}) | {both}/{n} |", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grains", type=int, default=20)
    ap.add_argument("--subdivisions", type=int, default=6)
    ap.add_argument("--only", default="flatness,radius,range,atlas")
    a = ap.parse_args(argv)
    t0 = time.time()
    parts = a.only.split(",")
    if "flatness" in parts:
        flatness_table(a.grains)
    if "radius" in parts:
        radius_table(a.grains, a.subdivisions)
    if "range" in parts:
        range_table(a.grains)
    if "atlas" in parts:
        atlas_table(a.grains)
    print(f"\n({time.time() - t0:.0f} s)", file=sys.stderr)


if __name__ == "__main__":
    main()
