"""Make the synthetic sands of ``tests/data``: generated grains with known settings, measured into Sand Atlas CSVs.

``angular`` (default): ``synthetic-angular-sand.csv``, 300 grains of the
``angular`` generator (the fit's ``angular`` method: 7 facets, 6 dents, a fine
texture, the aspect by inertia) whose per-grain settings (edge rounding, dent depth and the Zingg
ratios of the aspect) are drawn from known truncated normals
(:data:`KNOWN_ANGULAR`), each measured the Atlas way at about 30 voxels across
(13.3 µm voxels, d_eq about 400 µm), the drawn settings in
``synthetic-angular-sand-settings.csv`` (same row order): a crushed,
Hostun-like sand (the script prints the measured means and sds).  The same
rows with a sixth column, each grain's opening fraction (``Opening Fraction
(-)``, :data:`grainforge.fit.OPENING_COLUMN`, measured on the same voxel
image), are ``synthetic-angular-sand-opening.csv``: the table a study that
also measured that on its images would have.

``rf``: ``synthetic-rf-sand.csv``, 150 rf grains (:data:`KNOWN_RF`: irregularity
D3, roughness D8, the aspect; the roughness decay at the generator's default)
made and measured the same way, settings in ``synthetic-rf-sand-settings.csv``.

``fine``: ``synthetic-1um-sand.csv``, 100 Ottawa-like rf grains (:data:`FINE`)
of d_eq about 200 µm at 1 µm voxels, each measured at its full resolution
(140 to 290 voxels across): a table at a resolution the fit measures capped.

Deterministic (for any ``--workers``); usage::

    nice .venv/bin/python benchmarks/make_synthetic_sand.py [angular|rf|fine] [--grains N] [--out DIR]
        [--workers 2]

With ``--grains`` larger than the default, the sand's first rows are the
default sand's (the draws are made row by row); ``fit_recovery.py``'s
docstring twins such a sand of 20,000 angular grains.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
VOXEL_UM = 13.3
#: the known settings: name -> (mean, sd, low, high) of a truncated normal
KNOWN_ANGULAR = {"rounding": (0.2, 0.08, 0.02, 0.45), "dent_depth": (0.6, 0.06, 0.42, 0.7),
                 "elongation": (0.7, 0.08, 0.45, 0.9), "flatness": (0.68, 0.08, 0.45, 0.9)}
ANGULAR_GRAINS = 300
KNOWN_RF = {"irregularity": (0.10, 0.05, 0.02, 0.22), "roughness": (0.031, 0.006, 0.015, 0.039),
            "elongation": (0.64, 0.1, 0.4, 0.95), "flatness": (0.70, 0.1, 0.4, 0.95)}
GRAINS = 150
SEED = 41
#: the fine sand's settings, voxel size (µm), median d_eq (µm) and grains
FINE = {"irregularity": (0.04, 0.015, 0.0, 0.1), "roughness": (0.012, 0.004, 0.0, 0.03),
        "elongation": (0.77, 0.1, 0.45, 0.98), "flatness": (0.77, 0.1, 0.45, 0.98)}
FINE_VOXEL_UM, FINE_D_UM, FINE_GRAINS = 1.0, 200.0, 100
#: rf's roughness decay in the rf sands: the generator's default (the fit's rf method varies it per grain)
RF_DECAY = -5.0 / 3.0


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("which", nargs="?", default="angular", choices=["angular", "rf", "fine"])
    ap.add_argument("--grains", type=int, default=None,
                    help="grains of the sand [default: 300 angular, 150 rf, 100 fine]; the first rows of a larger "
                         "sand are the default sand's rows")
    ap.add_argument("--out", type=Path, default=DATA, help="folder of the CSVs [default: tests/data]")
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    kw = {"out": args.out, "workers": args.workers}
    if args.which == "fine":
        make("rf", "synthetic-1um-sand.csv", FINE, args.grains or FINE_GRAINS, FINE_VOXEL_UM, FINE_D_UM, settings=None,
             **kw)
    elif args.which == "rf":
        make("rf", "synthetic-rf-sand.csv", KNOWN_RF, args.grains or GRAINS, VOXEL_UM, 400.0,
             settings="synthetic-rf-sand-settings.csv", **kw)
    else:
        make("angular", "synthetic-angular-sand.csv", KNOWN_ANGULAR, args.grains or ANGULAR_GRAINS, VOXEL_UM, 400.0,
             settings="synthetic-angular-sand-settings.csv", opening="synthetic-angular-sand-opening.csv", **kw)


def make(method: str, name: str, known: dict, grains: int, voxel_um: float, d_um: float,
         settings: str | None, out: Path = DATA, workers: int = 1, opening: str | None = None) -> None:
    import numpy as np
    from scipy.stats import truncnorm

    from grainforge.fit import DESCRIPTORS, FITS, MeasurePool, grain_seed, write_sand

    rng = np.random.default_rng(SEED)
    spec = FITS[method]
    drawn = []
    for _ in range(grains):  # row by row, so that a larger sand begins with the smaller one's rows
        v = {k: float(truncnorm.rvs((lo - m) / s, (hi - m) / s, loc=m, scale=s, random_state=rng))
             for k, (m, s, lo, hi) in known.items()}
        drawn.append((v, float(d_um * math.exp(0.1 * rng.standard_normal()))))
    jobs = [(spec.params({**v, "roughness_decay": RF_DECAY} if method == "rf" else v), grain_seed(SEED, i),
             d_eq / voxel_um) for i, (v, d_eq) in enumerate(drawn)]

    def progress(it, total):
        for n, x in enumerate(it, 1):
            if n % 50 == 0 or n == total:
                print(f"grain {n}/{total}", end="\r", flush=True)
            yield x

    with MeasurePool(workers) as pool:  # each grain measured the Atlas way (spam's cube)
        table = pool.run(method, spec.fixed, jobs, progress=progress, opening=opening is not None)
    print()
    if not np.all(np.isfinite(table)):
        raise SystemExit(f"the generator refused {int(np.sum(~np.all(np.isfinite(table), axis=1)))} grains")
    truth = [[i + 1, *(v[k] for k in known)] for i, (v, _) in enumerate(drawn)]
    d_eq = [d for _, d in drawn]
    values = {k: table[:, j] for j, k in enumerate(DESCRIPTORS)}
    out.mkdir(parents=True, exist_ok=True)
    write_sand(out / name, d_eq, values, voxel_size=voxel_um)
    if opening:
        write_sand(out / opening, d_eq, values, voxel_size=voxel_um, opening=table[:, 4])
    if settings:
        with open(out / settings, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["Particle ID", *known])
            w.writerows([[f"{x:.6g}" if isinstance(x, float) else x for x in r] for r in truth])
    print("measured mean ± sd:", ", ".join(f"{k} {table[:, j].mean():.3f} ± {table[:, j].std():.3f}"
                                          for j, k in enumerate(DESCRIPTORS)))


if __name__ == "__main__":
    main()
