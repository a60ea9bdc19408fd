"""Figure for docs/dem.md: clump coverage and spill against sphere count, one grain per method.

    .venv/bin/python benchmarks/dem_clump_figure.py  [--out docs/img/dem-clump-tradeoff.png]

Quality measured by grainforge.dem.clump.clump_quality on a grid of d_eq/100
(cell centres counted). Pictures: the grain, and its 30-sphere clump (spheres
drawn as icospheres), same view and scale.
"""

from __future__ import annotations

import argparse

import numpy as np


def clump_mesh(centres, radii):
    import trimesh

    parts = []
    for c, r in zip(centres, radii):
        s = trimesh.creation.icosphere(3, radius=r)
        s.apply_translation(c)
        parts.append(s)
    return trimesh.util.concatenate(parts)


def main():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import trimesh

    import grainforge
    from grainforge.dem.clump import clump
    from grainforge.io import save_figure
    from grainforge.viz.render import render_image

    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="docs/img/dem-clump-tradeoff.png")
    args = ap.parse_args()
    counts = [5, 10, 20, 30, 50, 100]
    grains = [("fso", grainforge.fso(rng=1)), ("cri", grainforge.cri(rng=2)), ("dpa", grainforge.dpa(rng=3))]
    fig, axes = plt.subplots(3, 3, figsize=(10, 9.5), gridspec_kw={"width_ratios": [1, 1, 1.5]})
    for row, (name, g) in enumerate(grains):
        v = g.vertices - g.vertices.mean(axis=0)
        cov, spill = [], []
        for n in counts:
            c = clump(v, g.faces, spheres=n, rng=0)
            cov.append(c.coverage)
            spill.append(c.spill)
            if n == 30:
                c30 = c
            print(f"{name} N={n:3d} spheres={c.count:3d} coverage={c.coverage:.3f} spill={c.spill:.4f}")
        mesh = trimesh.Trimesh(v, g.faces, process=False)
        cm = clump_mesh(c30.centres, c30.radii)
        # same frame for both pictures: add the other's bounding box as two far-apart tiny triangles
        lo = np.minimum(mesh.bounds[0], cm.bounds[0])
        hi = np.maximum(mesh.bounds[1], cm.bounds[1])
        for ax, m, title in ((axes[row, 0], mesh, f"{name} grain"),
                             (axes[row, 1], cm, f"clump, {c30.count} spheres")):
            pad = trimesh.Trimesh([lo, lo + 1e-6, lo + [0, 1e-6, 0], hi, hi - 1e-6, hi - [0, 1e-6, 0]],
                                  [[0, 1, 2], [3, 4, 5]], process=False)
            ax.imshow(render_image(trimesh.util.concatenate([m, pad]), size=360))
            ax.set_axis_off()
            ax.set_title(title, fontsize=10)
        ax = axes[row, 2]
        ax.plot(counts, cov, "o-", color="C0", label="coverage")
        ax.set_xscale("log")
        ax.set_ylim(0, 1.0)
        ax.set_ylabel("coverage", color="C0")
        ax.set_xlabel("spheres N")
        ax2 = ax.twinx()
        ax2.plot(counts, np.array(spill) * 100, "s--", color="C3", label="spill")
        ax2.set_ylim(0, max(5.0, max(spill) * 110))
        ax2.set_ylabel("spill %", color="C3")
        ax.set_xticks(counts, [str(c) for c in counts])
        ax.grid(alpha=0.3)
        ax.set_title(f"{name}: quality on a d_eq/100 grid", fontsize=10)
    fig.tight_layout()
    save_figure(fig, args.out, dpi=110)
    print("wrote", args.out)


if __name__ == "__main__":
    main()
