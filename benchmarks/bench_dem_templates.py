"""What one DEM template costs, measured beside the up-front model that ``grainforge dem`` quotes.

    .venv/bin/python benchmarks/bench_dem_templates.py [--levelset]

Two 2 mm grains of 20,480 faces (angular and CRI, seed 0) are made into
templates (:func:`grainforge.dem.template.prepare`) at several ``--spheres`` /
``--refine-iterations`` settings (and, with ``--levelset``, level-set
spacings, minutes each). For each: the CPU seconds (``time.process_time``, one
core), the spheres placed, and :func:`grainforge.runtime.estimate.dem_template_seconds`.
The model is an upper bound for the refinement (it counts every iteration; the
L-BFGS-B search often converges sooner) and is meant to tell hours from days,
not to predict within 10 %.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

CLUMP_SETTINGS = [(10, 0), (30, 0), (100, 0), (1000, 0), (30, 30), (10, 300), (30, 300), (100, 300), (100, 1000)]
SPACINGS = [0.05, 0.03, 0.02]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levelset", action="store_true", help="also time level sets (minutes)")
    args = ap.parse_args()

    from click.testing import CliRunner

    from grainforge.cli.main import cli
    from grainforge.dem.inputs import read_grain
    from grainforge.dem.template import prepare
    from grainforge.runtime.estimate import dem_template_seconds

    with tempfile.TemporaryDirectory() as tmp:
        grains = {}
        for method in ("angular", "cri"):
            folder = os.path.join(tmp, method)
            res = CliRunner().invoke(cli, ["generate", method, "--size", "2", "--seed", "0", "--out", folder])
            assert res.exit_code == 0, res.output
            grains[method] = read_grain(os.path.join(folder, f"{method}-0000.stl"))
        print(f"{'grain':8} {'faces':>6} {'shape':8} {'spheres':>7} {'refine':>6} {'spacing':>7} "
              f"{'placed':>6} {'CPU s':>8} {'model s':>8}")
        for name, (v, f) in grains.items():
            for spheres, refine in CLUMP_SETTINGS:
                t0 = time.process_time()
                t = prepare(v, f, name=name, spheres=spheres, refine_iterations=refine)
                cpu = time.process_time() - t0
                model = dem_template_seconds("clump", spheres=spheres, refine_iterations=refine)
                print(f"{name:8} {len(f):6d} {'clump':8} {spheres:7d} {refine:6d} {'':>7} {t.clump.count:6d} "
                      f"{cpu:8.3f} {model:8.3f}", flush=True)
            if args.levelset:
                for spacing in SPACINGS:
                    t0 = time.process_time()
                    t = prepare(v, f, name=name, shape="levelset", levelset_spacing=spacing)
                    cpu = time.process_time() - t0
                    model = dem_template_seconds("levelset", spacing=spacing)
                    print(f"{name:8} {len(f):6d} {'levelset':8} {'':>7} {'':>6} {spacing:7.3f} "
                          f"{t.levelset.distance.size:6d} {cpu:8.3f} {model:8.3f}", flush=True)


if __name__ == "__main__":
    main()
