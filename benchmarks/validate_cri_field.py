"""CRI with random-field roughness (``--roughness field``) against the swept roughness.

For each descriptor set: the separable share f(θ) + g(ψ) of the small-scale relief
(``relief.separable_share``, the ridge measure of docs/validation.md; 8 grains, both roughness
kinds, same seeds) and the D2, D3, D8 of the sections through the volume centroid perpendicular to
the principal inertia axes (grains written to STL and read back; 20 grains), as
``benchmarks/validate_cri.py`` measures them.

Run: ``nice .venv/bin/python benchmarks/validate_cri_field.py > out/validate_cri_field.md`` (~6 min idle).
"""

from __future__ import annotations

import time

import numpy as np
from validate_cri import read_back, ridge_share, section_descriptors

SETS = ((0.0, 0.0, 0.02), (0.15, 0.10, 0.03), (0.3, 0.1, 0.05))


def main():
    from grainforge import cri

    t = time.time()
    print("## CRI roughness: swept vs field (benchmarks/validate_cri_field.py)\n")
    print("| requested (D2, D3, D8) | roughness | separable share, 8 grains (mean ± sd) | sections: mean D2, D3, D8 "
          "(20 grains) | error % | s.e. % | CPU s/grain |")
    print("|---|---|---|---|---|---|---|")
    for d in SETS:
        for rough in ("swept", "field"):
            c0 = time.process_time()
            share, S = [], []
            for seed in range(20):
                g = cri(descriptors=d, rng=seed, roughness=rough)
                if seed < 8:
                    share.append(ridge_share(g.vertices, g.faces))
                S.append(section_descriptors(read_back(g)))
            cpu = (time.process_time() - c0) / 20
            S = np.array(S).mean(axis=1)  # (grains, 3): per grain, mean over the three planes
            m = S.mean(axis=0)
            se = S.std(axis=0, ddof=1) / np.sqrt(len(S))
            want = np.asarray(d)
            ok = want > 0
            err = ", ".join(f"{100 * (m[k] / want[k] - 1):+.1f}" if ok[k] else "—" for k in range(3))
            sem = ", ".join(f"{100 * se[k] / want[k]:.1f}" if ok[k] else "—" for k in range(3))
            print(f"| {d} | {rough} | {np.mean(share):.2f} ± {np.std(share):.2f} | "
                  f"{', '.join(f'{x:.4f}' for x in m)} | {err} | {sem} | {cpu:.2f} |")
    print(f"\n({time.time() - t:.0f} s; load average {', '.join(f'{x:.1f}' for x in __import__('os').getloadavg())})")


if __name__ == "__main__":
    main()
