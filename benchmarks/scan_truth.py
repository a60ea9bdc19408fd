"""``grainforge scan`` against known grains: a packed volume of generated grains, clean and as a scanner sees it.

Grains (CRI grains of several seeds and rotated ellipsoids) are voxelised as ``atlas_descriptors`` voxelises them
(``voxel_image`` at one voxel size, ``--across`` voxels across a grain of d_eq 2), and packed: each starts in its
cell of a cubic grid and slides along −x, −y, −z until it touches what is already there, so most grains touch
several others.  The truth is each grain's ``atlas_descriptors`` (its mesh, the same voxel size, the same
orientation).  Then:

1. **labelled** — the clean labelled volume, measured by ``measure_labels``: the descriptors must equal the truth.
2. **binary, segmented** — the labels' union, segmented by ``segment`` (defaults).
3. **scanned, segmented** — the union with noise added (normal, ``--noise`` of the grain–void contrast), blurred
   as a scanner's point-spread and partial volumes blur it (a Gaussian of ``--blur`` voxels), thresholded at half
   the contrast, then segmented.

For 2 and 3 it prints the label recovery (found / merged / split / missed / spurious, ``compare_labels``;
spurious counts labels of 66 voxels or more, the smaller being counted apart by ``scan``) and,
over the found grains that do not touch the image's faces, each descriptor's mean error (bias), mean absolute
error and largest absolute error against the truth.  Usage:

    .venv/bin/python benchmarks/scan_truth.py [--grains 27] [--across 30] [--blur 1.0] [--noise 0.15] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

DESCRIPTORS = ("equivalent_diameter", "sphericity", "convexity", "flatness", "elongation", "opening_fraction")


def _meshes(n: int, seed: int):
    import trimesh

    import grainforge
    from grainforge.geometry.rotations import random_rotation

    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        if i % 3 == 2:
            m = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
            m.apply_scale(rng.uniform(0.7, 1.25, 3))
            v, f = np.asarray(m.vertices), np.asarray(m.faces)
        else:
            g = grainforge.cri(rng=seed * 1000 + i)
            v, f = np.asarray(g.vertices), np.asarray(g.faces)
        v = v @ random_rotation(rng).T
        out.append(trimesh.Trimesh(v, f, process=False))
    return out


def _tight(mask):
    idx = np.argwhere(mask)
    lo, hi = idx.min(0), idx.max(0) + 1
    return mask[tuple(slice(a, b) for a, b in zip(lo, hi))]


def _fits(vol, mask, pos):
    if min(pos) < 0 or any(p + s > n for p, s, n in zip(pos, mask.shape, vol.shape)):
        return False
    return not (vol[tuple(slice(p, p + s) for p, s in zip(pos, mask.shape))][mask] > 0).any()


def pack(masks, margin: int = 3):
    """Labelled volume of ``masks`` (tight), packed by sliding each down −x, −y, −z until it touches."""
    n = int(np.ceil(len(masks) ** (1 / 3)))
    cell = max(max(m.shape) for m in masks) + 2
    size = n * cell + 2 * margin
    vol = np.zeros((size, size, size), np.uint16)
    for k, mask in enumerate(masks, start=1):
        i, j, l = np.unravel_index(k - 1, (n, n, n))
        pos = [margin + i * cell, margin + j * cell, margin + l * cell]
        moved = True
        while moved:
            moved = False
            for axis in (2, 1, 0):
                while True:
                    nxt = list(pos)
                    nxt[axis] -= 1
                    if nxt[axis] < margin or not _fits(vol, mask, nxt):
                        break
                    pos, moved = nxt, True
        vol[tuple(slice(p, p + s) for p, s in zip(pos, mask.shape))][mask] = k
    # crop the empty far side (keep the margin)
    idx = np.argwhere(vol)
    hi = idx.max(0) + 1 + margin
    return vol[: hi[0], : hi[1], : hi[2]]


def errors(rows, truth, match):
    """Per descriptor: (bias, mean |error|, max |error|, n) over matched, measured grains."""
    out = {}
    for name in DESCRIPTORS:
        e = [rows[c][name] - truth[t][name] for t, c in match.items() if c in rows and rows[c]["status"] == "measured"]
        e = np.asarray(e, dtype=np.float64)
        if name == "equivalent_diameter":
            e = e / np.mean([truth[t][name] for t in match])  # relative
        out[name] = (float(e.mean()), float(np.abs(e).mean()), float(np.abs(e).max()), len(e)) if len(e) else None
    return out


def best_match(truth_labels, found_labels):
    """True label -> the segmented label holding most of it, where that label is mostly this grain."""
    t = truth_labels.ravel().astype(np.int64)
    f = found_labels.ravel().astype(np.int64)
    both = (t > 0) & (f > 0)
    pairs, k = np.unique(np.stack([t[both], f[both]]), axis=1, return_counts=True)
    ts, fs = np.bincount(t), np.bincount(f)
    match = {}
    for (a, c), n in zip(pairs.T, k):
        if n > 0.5 * ts[a] and n > 0.5 * fs[c]:
            match[int(a)] = int(c)
    return match


def report(name, rows, truth, match, recovery=None):
    if recovery is not None:
        print(f"{name}: recovery " + ", ".join(f"{k} {v}" for k, v in recovery.items()))
    e = errors(rows, truth, match)
    print(f"| {name} | descriptor | bias | mean abs error | max abs error | grains |")
    print("|---|---|---|---|---|---|")
    for d, v in e.items():
        if v is not None:
            label = "d_eq (relative)" if d == "equivalent_diameter" else d
            print(f"| {name} | {label} | {v[0]:+.4f} | {v[1]:.4f} | {v[2]:.4f} | {v[3]} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--grains", type=int, default=27)
    ap.add_argument("--across", type=float, default=30.0, help="voxels across a grain of d_eq 2")
    ap.add_argument("--blur", type=float, default=1.0, help="the scanner's blur, Gaussian sigma in voxels")
    ap.add_argument("--noise", type=float, default=0.15, help="noise sd, in units of the grain-void contrast")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    from scipy import ndimage

    from grainforge.analysis.atlas import atlas_descriptors, voxel_image
    from grainforge.analysis.scan import MIN_VOXELS, compare_labels, label_boxes, measure_labels, segment
    from grainforge.io.volume import Volume

    t0 = time.perf_counter()
    h = 2.0 / args.across
    meshes = _meshes(args.grains, args.seed)
    masks = [_tight(voxel_image(m, voxel_size=h)[0]) for m in meshes]
    truth = {k: atlas_descriptors(m, voxel_size=h) for k, m in enumerate(meshes, start=1)}
    vol = pack(masks)
    touching = 0
    for k in range(1, len(masks) + 1):
        ring = ndimage.binary_dilation(vol == k) & (vol > 0) & (vol != k)
        touching += bool(ring.any())
    print(f"load average {os.getloadavg()[0]:.2f}; {len(masks)} grains ({touching} touching another), image "
          f"{'x'.join(map(str, vol.shape))}, {args.across:g} voxels across d_eq 2, blur {args.blur:g}, noise "
          f"{args.noise:g}; made in {time.perf_counter() - t0:.0f} s")

    def measure(labels):
        v = Volume.from_array(labels)
        return {r["label"]: r for r in measure_labels(v, label_boxes(v), voxel_size=h, workers=1)}

    interior = {b.label for b in label_boxes(Volume.from_array(vol)) if not b.touches(vol.shape)}
    rows = measure(vol)
    report("labelled", rows, truth, {k: k for k in interior})
    binary = vol > 0
    labels, info = segment(binary)
    rec = compare_labels(vol, labels, min_voxels=MIN_VOXELS)
    report("binary, segmented", measure(labels), truth,
           {t: c for t, c in best_match(vol, labels).items() if t in interior}, rec)
    rng = np.random.default_rng(args.seed + 1)
    grey = binary.astype(np.float32) + rng.normal(0.0, args.noise, binary.shape).astype(np.float32)
    scanned = ndimage.gaussian_filter(grey, args.blur) > 0.5
    changed = float((scanned != binary).sum() / binary.sum())
    labels, info = segment(scanned)
    rec = compare_labels(vol, labels, min_voxels=MIN_VOXELS)
    print(f"scanned image: {changed:.1%} of the grain voxels changed by blur, noise and threshold")
    report("scanned, segmented", measure(labels), truth,
           {t: c for t, c in best_match(vol, labels).items() if t in interior}, rec)
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
