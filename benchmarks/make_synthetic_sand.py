"""Make the synthetic sands of ``tests/data``: rf grains with known settings, measured into Sand Atlas CSVs.

``angular`` (default): ``synthetic-angular-sand.csv``, 150 grains whose
per-grain settings (irregularity D3, roughness D8 and the Zingg ratios of the
aspect) are drawn from known truncated normals (:data:`KNOWN`), each
measured the Atlas way at about 30 voxels across (13.3 µm voxels, d_eq about
400 µm), the drawn settings in ``synthetic-angular-sand-settings.csv`` (same
row order): Hostun-like angular grains (true sphericity about 0.72,
convexity about 0.80, flatness about 0.70; the script prints the measured
means and sds).

``fine``: ``synthetic-1um-sand.csv``, 100 Ottawa-like grains (:data:`FINE`)
of d_eq about 200 µm at 1 µm voxels, each measured at its full resolution
(140 to 290 voxels across): a table at a resolution the fit measures capped.

Deterministic; usage::

    nice .venv/bin/python benchmarks/make_synthetic_sand.py [angular|fine]
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
VOXEL_UM = 13.3
#: the known settings: name -> (mean, sd, low, high) of a truncated normal
KNOWN = {"irregularity": (0.10, 0.05, 0.02, 0.22), "roughness": (0.031, 0.006, 0.015, 0.039),
         "elongation": (0.64, 0.1, 0.4, 0.95), "flatness": (0.70, 0.1, 0.4, 0.95)}
GRAINS = 150
SEED = 41
#: the fine sand's settings, voxel size (µm), median d_eq (µm) and grains
FINE = {"irregularity": (0.04, 0.015, 0.0, 0.1), "roughness": (0.012, 0.004, 0.0, 0.03),
        "elongation": (0.77, 0.1, 0.45, 0.98), "flatness": (0.77, 0.1, 0.45, 0.98)}
FINE_VOXEL_UM, FINE_D_UM, FINE_GRAINS = 1.0, 200.0, 100


def main() -> None:
    import sys

    if sys.argv[1:] == ["fine"]:
        make("synthetic-1um-sand.csv", FINE, FINE_GRAINS, FINE_VOXEL_UM, FINE_D_UM, settings=None)
    else:
        make("synthetic-angular-sand.csv", KNOWN, GRAINS, VOXEL_UM, 400.0,
             settings="synthetic-angular-sand-settings.csv")


def make(name: str, known: dict, grains: int, voxel_um: float, d_um: float, settings: str | None) -> None:
    import numpy as np
    from scipy.stats import truncnorm

    from grainforge.fit import DESCRIPTORS, FITS, _measure, grain_seed
    from grainforge.methods import get

    rng = np.random.default_rng(SEED)
    spec = FITS["rf"]
    rows, truth = [], []
    for i in range(grains):
        v = {k: float(truncnorm.rvs((lo - m) / s, (hi - m) / s, loc=m, scale=s, random_state=rng))
             for k, (m, s, lo, hi) in known.items()}
        d_eq = float(d_um * math.exp(0.1 * rng.standard_normal()))
        params = get("rf").Params(**{**spec.fixed, **spec.params(v)})
        d = _measure("rf", params, grain_seed(SEED, i), d_eq / voxel_um, "atlas")
        rows.append([i + 1, math.pi / 6 * d_eq**3, d_eq, *d, voxel_um])
        truth.append([i + 1, *(v[k] for k in known)])
        print(f"grain {i + 1}/{grains}", end="\r", flush=True)
    header = ["Particle ID", "Volume (µm³)", "Equivalent Diameter (µm)", "True Sphericity (-)", "Convexity (-)",
              "Flatness (-)", "Elongation (-)", "Voxel Size (µm)"]
    assert header[3:7] == [f"{'True Sphericity' if k == 'sphericity' else k.title()} (-)" for k in DESCRIPTORS]
    files = [(name, header, rows)] + ([(settings, ["Particle ID", *known], truth)] if settings else [])
    for file, head, body in files:
        with open(DATA / file, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(head)
            w.writerows([[f"{x:.6g}" if isinstance(x, float) else x for x in r] for r in body])
    table = np.array([r[3:7] for r in rows])
    print("measured mean ± sd:", ", ".join(f"{k} {table[:, j].mean():.3f} ± {table[:, j].std():.3f}"
                                          for j, k in enumerate(DESCRIPTORS)))


if __name__ == "__main__":
    main()
