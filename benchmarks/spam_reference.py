"""Reference true sphericities from spam (the Sand Atlas's library), for ``tests/analysis/test_atlas_convention.py``.

Voxelises grains at 2 mm with 0.029 mm voxels (voxel centres inside the mesh,
``grainforge.analysis.atlas.voxelise``), measures each with
``spam.label.trueSphericity`` and stores the masks (bit-packed) and spam's
values in ``tests/data/spam-sphericity.npz``.  Four grains: three whose
extent above their centre of mass exceeds the extent below (spam clips them)
and one it does not clip.

Needs spam (``pip install spam==0.9.1``, about 1 GB with its dependencies),
best in a separate environment: run this script's ``--measure`` step there::

    .venv/bin/python benchmarks/spam_reference.py --masks            # writes the masks
    /path/to/spam-env/bin/python benchmarks/spam_reference.py --measure

``--scan`` (in spam's environment, after ``--masks``) puts the four grains side by side in one labelled
volume, touching, labels 1–4, and stores it with spam's true sphericity of each label measured on that
volume in ``tests/data/spam-scan.npz``, for ``tests/fit/test_scan.py`` (``grainforge scan`` against spam on the
same labelled image).
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np

OUT = pathlib.Path(__file__).resolve().parent.parent / "tests" / "data" / "spam-sphericity.npz"
SCAN_OUT = OUT.with_name("spam-scan.npz")
GRAINS = (("cri", 3), ("cri", 5), ("angular", 5), ("rf", 0))
VOXEL_MM = 0.029


def masks():
    from grainforge.analysis.atlas import voxelise
    from grainforge.fabrication import to_size
    from grainforge.methods import generate, get

    out = {}
    for name, seed in GRAINS:
        g = to_size(generate(name, get(name).Params(), seed), 2.0)
        mask, _ = voxelise(np.asarray(g.vertices), np.asarray(g.faces), VOXEL_MM)
        out[f"{name}-{seed}"] = mask
    return out


def side_by_side(masks: list[np.ndarray], margin: int = 12) -> np.ndarray:
    """The masks in one uint8 labelled volume (labels 1, 2, ... in order), along x, each box touching the next
    (neighbouring grains meet where both reach their box's face), ``margin`` voxels of void around them all."""
    shape = (max(m.shape[0] for m in masks) + 2 * margin, max(m.shape[1] for m in masks) + 2 * margin,
             sum(m.shape[2] for m in masks) + 2 * margin)
    vol = np.zeros(shape, dtype=np.uint8)
    x = margin
    for k, m in enumerate(masks, start=1):
        vol[margin:margin + m.shape[0], margin:margin + m.shape[1], x:x + m.shape[2]][m] = k
        x += m.shape[2]
    return vol


def scan_reference() -> None:
    """The labelled volume of the four grains and spam's true sphericity of each label (spam's environment)."""
    import spam.label

    data = dict(np.load(OUT))
    names = sorted({k.split("/")[0] for k in data})
    masks = []
    for k in names:
        shape = tuple(data[k + "/shape"])
        masks.append(np.unpackbits(data[k + "/bits"])[: np.prod(shape)].reshape(shape).astype(bool))
    vol = side_by_side(masks)
    spheric = np.asarray(spam.label.trueSphericity(vol.astype(np.uint32)), dtype=np.float64)[1: len(masks) + 1]
    np.savez_compressed(SCAN_OUT, labels=vol, names=np.array(names), spam_sphericity=spheric)
    for name, value in zip(names, spheric):
        print(f"label {name}: spam true sphericity {value:.6f}")
    print(f"wrote {SCAN_OUT} ({vol.shape}, {len(names)} labels)")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--masks", action="store_true", help="voxelise the grains (grainforge's environment)")
    ap.add_argument("--measure", action="store_true", help="measure them with spam (spam's environment)")
    ap.add_argument("--scan", action="store_true",
                    help="the four grains in one labelled volume, measured by spam (spam's environment)")
    a = ap.parse_args()
    if a.masks:
        m = masks()
        data = {}
        for k, v in m.items():
            data[k + "/shape"] = np.array(v.shape)
            data[k + "/bits"] = np.packbits(v.ravel())
        np.savez_compressed(OUT, **data)
        print(f"wrote {len(m)} masks to {OUT}")
    if a.measure:
        import spam.label

        data = dict(np.load(OUT))
        names = sorted({k.split("/")[0] for k in data})
        for k in names:
            shape = tuple(data[k + "/shape"])
            mask = np.unpackbits(data[k + "/bits"])[: np.prod(shape)].reshape(shape).astype(bool)
            lab = np.zeros(tuple(s + 20 for s in shape), dtype=np.uint32)
            lab[10:-10, 10:-10, 10:-10] = mask
            data[k + "/spam"] = np.array(float(spam.label.trueSphericity(lab)[1]))
            print(f"{k}: spam true sphericity {float(data[k + '/spam']):.6f}")
        np.savez_compressed(OUT, **data)
    if a.scan:
        scan_reference()


if __name__ == "__main__":
    main()
