"""Reference true sphericities from spam (the Sand Atlas's library), for ``tests/test_atlas_convention.py``.

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
"""

from __future__ import annotations

import argparse
import pathlib

import numpy as np

OUT = pathlib.Path(__file__).resolve().parent.parent / "tests" / "data" / "spam-sphericity.npz"
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


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--masks", action="store_true", help="voxelise the grains (grainforge's environment)")
    ap.add_argument("--measure", action="store_true", help="measure them with spam (spam's environment)")
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


if __name__ == "__main__":
    main()
