"""Make a small synthetic μCT scan to try ``grainforge scan`` on: a labelled 3D TIFF of packed CRI grains.

    python examples/scan/make_scan.py --out out/scan      # labels.tif (and binary.tif), 10 µm voxels

64 CRI grains, each with its own irregularity, roughness and aspect (so that a fit has spread to match), in a
random orientation, are voxelised as ``grainforge.analysis.atlas.voxel_image`` voxelises a grain (16 to 32
voxels across their equivalent diameter, log-uniform; 10 µm voxels: grains of 160 to 320 µm) and packed: each starts in its
cell of a 4 × 4 × 4 grid and slides along −x, −y, −z until it touches the grains already there.  The image is
written as a multi-page ImageJ TIFF with its voxel size in the metadata (``labels.tif``, uint16, one label per
grain) and as its binary union (``binary.tif``, uint8), the two kinds of image a lab holds.  It is synthetic,
made by grainforge itself: no real scan is in this repository (docs/guide/scan.md walks through it).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

VOXEL_UM = 10.0
ACROSS = (16.0, 32.0)
GRAINS = 64


def grains(n: int, seed: int = 0):
    """``n`` CRI grains (vertices, faces) of equivalent diameter about 2, in random orientations."""
    import grainforge
    from grainforge.geometry.rotations import random_rotation

    rng = np.random.default_rng(seed)
    for i in range(n):
        aspect = (1.0, rng.uniform(0.55, 0.95), rng.uniform(0.4, 0.8))
        g = grainforge.cri(descriptors=(0.0, rng.uniform(0.02, 0.15), rng.uniform(0.002, 0.012)),
                           aspect=(aspect[0], aspect[1], min(aspect[1], aspect[2])), subdivisions=4, rng=seed + i)
        yield np.asarray(g.vertices) @ random_rotation(rng).T, np.asarray(g.faces)


def pack(masks, margin: int = 3) -> np.ndarray:
    """A labelled volume of the (tight) ``masks``, each slid along −x, −y, −z until it touches."""

    def fits(vol, mask, pos):
        if min(pos) < 0 or any(p + s > n for p, s, n in zip(pos, mask.shape, vol.shape)):
            return False
        return not (vol[tuple(slice(p, p + s) for p, s in zip(pos, mask.shape))][mask] > 0).any()

    n = int(np.ceil(len(masks) ** (1 / 3)))
    cell = max(max(m.shape) for m in masks) + 2
    vol = np.zeros((n * cell + 2 * margin,) * 3, np.uint16)
    for k, mask in enumerate(masks, start=1):
        pos = [margin + c * cell for c in np.unravel_index(k - 1, (n, n, n))]
        moved = True
        while moved:
            moved = False
            for axis in (2, 1, 0):
                while pos[axis] > margin:
                    nxt = list(pos)
                    nxt[axis] -= 1
                    if not fits(vol, mask, nxt):
                        break
                    pos, moved = nxt, True
        vol[tuple(slice(p, p + s) for p, s in zip(pos, mask.shape))][mask] = k
    hi = np.argwhere(vol).max(0) + 1 + margin
    return vol[: hi[0], : hi[1], : hi[2]]


def main(out: Path) -> None:
    import tifffile

    from grainforge.analysis.atlas import voxel_image

    masks = []
    across = np.exp(np.random.default_rng(1).uniform(*np.log(ACROSS), GRAINS))
    for (v, f), n in zip(grains(GRAINS), across):
        mask = voxel_image(v, f, voxels_across=n)[0]
        idx = np.argwhere(mask)
        masks.append(mask[tuple(slice(a, b) for a, b in zip(idx.min(0), idx.max(0) + 1))])
    labels = pack(masks)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"resolution": (1 / VOXEL_UM, 1 / VOXEL_UM), "metadata": {"spacing": VOXEL_UM, "unit": "um", "axes": "ZYX"}}
    tifffile.imwrite(out / "labels.tif", labels, imagej=True, **meta)
    tifffile.imwrite(out / "binary.tif", (labels > 0).astype(np.uint8), imagej=True, **meta)
    print(f"{out / 'labels.tif'}: {'x'.join(map(str, labels.shape))} voxels of {VOXEL_UM:g} µm, {len(masks)} grains")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/scan"), help="folder of labels.tif and binary.tif")
    main(ap.parse_args().out)
