"""DPA growth with and without the contact rules (clearance 1e-3, notch ≥ 30°; docs/methods/dpa.md).

Run: ``nice .venv/bin/python benchmarks/validate_dpa_contacts.py [--seeds 10] [--primaries 200]``.
Prints, per non-cube primitive and ε, how often a chosen placement was rejected as intruding or by
the contact rules, and mean ± s.d. of D_A (Eq. 5) and porosity with the rules and without them
(same seeds).  Asserts nothing; recorded in docs/methods/dpa.md, "Contacts".
"""

from __future__ import annotations

import argparse
import os

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--primaries", type=int, default=200)
    args = ap.parse_args()
    from grainforge.methods.dpa import aggregation as D

    print(f"load average: {os.getloadavg()}; N = {args.primaries}, seeds 0..{args.seeds - 1}")
    print(f"{'primitive':21s} {'eps':>5s} {'intruding %':>11s} {'contact rule %':>14s} "
          f"{'D_A rules':>14s} {'D_A before':>14s} {'porosity rules':>15s} {'porosity before':>15s}")
    for name in ("octahedron", "tetrahedron", "dodecahedron", "icosahedron", "truncated-octahedron"):
        for eps in (0.3, 3.0, 30.0):
            rows = {True: [], False: []}
            tried = np.zeros(3)
            for seed in range(args.seeds):
                for rules in (True, False):
                    kw = {} if rules else {"clearance": -1.0, "min_notch": -1.0}
                    agg = D.aggregate(name, args.primaries, exponent=eps, rng=np.random.default_rng(seed), **kw)
                    m = agg.measures()
                    rows[rules].append((m["D_A"], m["porosity"]))
                    if rules:
                        tried += agg.tried
            a, b = np.array(rows[True]), np.array(rows[False])
            pct = 100.0 * tried / tried.sum()
            print(f"{name:21s} {eps:5g} {pct[1]:11.1f} {pct[2]:14.1f} "
                  f"{a[:, 0].mean():7.3f}±{a[:, 0].std():.3f} {b[:, 0].mean():7.3f}±{b[:, 0].std():.3f} "
                  f"{a[:, 1].mean():8.3f}±{a[:, 1].std():.3f} {b[:, 1].mean():8.3f}±{b[:, 1].std():.3f}", flush=True)
    print(f"load average: {os.getloadavg()}")


if __name__ == "__main__":
    main()
