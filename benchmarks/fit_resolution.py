"""Generated grains' Atlas descriptors have converged with resolution at the fit's cap (docs/fit.md).

``grainforge fit`` measures generated grains at most ``--max-voxels-across``
voxels across, however fine the sand's scan; by default each method's own cap
(``grainforge.fit.MethodFit.max_across``).  For each fitted generator this
measures a few grains (settings drawn from the fit's design box, seeds fixed)
at the cap and at full resolution (default 300 voxels across), in the same
orientation, and prints per generator the largest |cap − full| of each
descriptor, as a Markdown table.  The cap holds when every entry is ≤ 0.005.
A method without a cap (fso) is measured at ``--probe`` (default 250) to show
that it has none.  Usage::

    nice .venv/bin/python benchmarks/fit_resolution.py [--grains 4] [--cap N] [--full 300] [--methods rf,fso]
"""

from __future__ import annotations

import argparse
import time

from _timing import one_core

one_core()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--grains", type=int, default=4)
    ap.add_argument("--cap", type=float, default=None, help="default: each method's own cap")
    ap.add_argument("--probe", type=float, default=250.0, help="cap tried for a method that has none")
    ap.add_argument("--full", type=float, default=300.0)
    ap.add_argument("--methods", default="rf,cri,fso,angular")
    args = ap.parse_args()
    import numpy as np

    from grainforge.fit import DESCRIPTORS, FITS, grain_seed
    from grainforge.fit.made_grains import _measure
    from grainforge.fit.twins import design_points
    from grainforge.methods import get

    print(f"| method | cap | grains | {' | '.join(f'max abs Δ {k}' for k in DESCRIPTORS)} | "
          f"s per grain at {args.full:g} |")
    print("|---|---|---|" + "---|" * (len(DESCRIPTORS) + 1))
    for m in args.methods.split(","):
        spec = FITS[m]
        cap = args.cap or spec.max_across or args.probe
        label = f"{cap:g}" if args.cap or spec.max_across else f"none (tried {cap:g})"
        # settings from the middle 60 % of the design box (the box's corners include grains no sand has)
        u = 0.2 + 0.6 * design_points(args.grains, len(spec.all_settings), rng=5)
        worst = np.zeros(4)
        t_full = []
        for i in range(args.grains):
            params = get(m).Params(**{**spec.fixed, **spec.grain_params(u[i])})
            seed = grain_seed(99, i)
            at_cap = np.array(_measure(m, params, seed, cap, "atlas"))
            t = time.perf_counter()
            full = np.array(_measure(m, params, seed, args.full, "atlas"))
            t_full.append(time.perf_counter() - t)
            worst = np.maximum(worst, np.abs(at_cap - full))
            print(f"  {m} grain {i}: cap {np.round(at_cap, 4).tolist()} full {np.round(full, 4).tolist()}", flush=True)
        print(f"| {m} | {label} | {args.grains} | " + " | ".join(f"{w:.4f}" for w in worst)
              + f" | {np.median(t_full):.1f} |", flush=True)


if __name__ == "__main__":
    main()
