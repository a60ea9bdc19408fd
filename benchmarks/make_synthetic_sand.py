"""Make ``tests/data/synthetic-angular-sand.csv``: an angular "sand" of rf grains with known settings (docs/fit.md).

150 rf grains whose per-grain settings (irregularity D3, roughness D8 and the
Zingg ratios of the aspect) are drawn from known truncated normals, each
measured the Atlas way at about 30 voxels across (13.3 µm voxels, d_eq about
400 µm) into a Sand Atlas CSV, with the drawn settings in
``tests/data/synthetic-angular-sand-settings.csv`` (same row order).  The
settings make Hostun-like angular grains: true sphericity about 0.72 ± 0.06,
convexity about 0.80 ± 0.06, flatness about 0.70.  Usage::

    .venv/bin/python benchmarks/make_synthetic_sand.py     # rewrites both files (deterministic)
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
VOXEL_UM = 13.3
#: the known settings: name -> (mean, sd, low, high) of a truncated normal
KNOWN = {"irregularity": (0.12, 0.035, 0.04, 0.22), "roughness": (0.028, 0.005, 0.015, 0.039),
         "elongation": (0.72, 0.08, 0.45, 0.95), "flatness": (0.70, 0.08, 0.45, 0.95)}
GRAINS = 150
SEED = 41


def main() -> None:
    import numpy as np
    from scipy.stats import truncnorm

    from grainforge.fit import DESCRIPTORS, FITS, _measure, grain_seed
    from grainforge.methods import get

    rng = np.random.default_rng(SEED)
    spec = FITS["rf"]
    rows, truth = [], []
    for i in range(GRAINS):
        v = {k: float(truncnorm.rvs((lo - m) / s, (hi - m) / s, loc=m, scale=s, random_state=rng))
             for k, (m, s, lo, hi) in KNOWN.items()}
        d_eq = float(400.0 * math.exp(0.1 * rng.standard_normal()))
        params = get("rf").Params(**{**spec.fixed, **spec.params(v)})
        d = _measure("rf", params, grain_seed(SEED, i), d_eq / VOXEL_UM, "atlas")
        rows.append([i + 1, math.pi / 6 * d_eq**3, d_eq, *d, VOXEL_UM])
        truth.append([i + 1, *(v[k] for k in KNOWN)])
    header = ["Particle ID", "Volume (µm³)", "Equivalent Diameter (µm)", "True Sphericity (-)", "Convexity (-)",
              "Flatness (-)", "Elongation (-)", "Voxel Size (µm)"]
    assert header[3:7] == [f"{'True Sphericity' if k == 'sphericity' else k.title()} (-)" for k in DESCRIPTORS]
    for name, head, body in (("synthetic-angular-sand.csv", header, rows),
                             ("synthetic-angular-sand-settings.csv", ["Particle ID", *KNOWN], truth)):
        with open(DATA / name, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(head)
            w.writerows([[f"{x:.6g}" if isinstance(x, float) else x for x in r] for r in body])
    table = np.array([r[3:7] for r in rows])
    print("measured mean ± sd:", ", ".join(f"{k} {table[:, j].mean():.3f} ± {table[:, j].std():.3f}"
                                          for j, k in enumerate(DESCRIPTORS)))


if __name__ == "__main__":
    main()
