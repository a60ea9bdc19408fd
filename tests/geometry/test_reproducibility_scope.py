"""What "same parameters + seed ⇒ byte-identical files" covers, tested on every code path here.

The promise holds for one NumPy/OpenBLAS build on one CPU feature level: for
any worker count, block size and BLAS thread count.  A machine runs several
code paths of the same build: NumPy picks SIMD kernels by CPU feature
(``NPY_DISABLE_CPU_FEATURES`` turns the widest ones off, as on an older CPU)
and OpenBLAS picks its kernels by CPU (``OPENBLAS_CORETYPE`` forces one).  Each
path is run in a subprocess here and must be deterministic and independent of
the block size on its own; across paths, float64 transcendental functions round
differently in the last bit (NumPy's AVX-512 kernels are not its AVX2 ones), so
the grains agree to rounding, not bit for bit.  docs/validation.md
("Reproducibility") gives the figures.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

pytestmark = pytest.mark.slow

_SCRIPT = r"""
import hashlib, json, os, tempfile
import numpy as np
from grainforge.geometry.geodesic import icosphere
from grainforge.methods import METHODS, get, generate, fso
from grainforge.io import write_mesh
from grainforge.dem.clump import clump

STL = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
out = {}
u, _ = icosphere(3)
field = fso.draw_field(fso.Params(), np.random.default_rng(5))
out["fso_chunks"] = sorted({hashlib.sha256(fso.wm_sum(u, field, chunk=c).tobytes()).hexdigest()
                            for c in (None, 1, 2, 7, 100, len(u))})
with tempfile.TemporaryDirectory() as d:
    for name in METHODS:
        p = get(name).Params()
        if name == "fso":
            p = p.__class__(subdivisions=4)
        g = generate(name, p, 3)
        f = os.path.join(d, name + ".stl")
        write_mesh(g, f)
        rec = np.fromfile(f, dtype=STL, offset=84)
        out[name] = {"sha": hashlib.sha256(open(f, "rb").read()).hexdigest(),
                     "v": rec["v"].astype(float).ravel().tolist(), "n": rec["n"].astype(float).ravel().tolist()}
        if name in ("fso", "angular"):
            c = clump(g.vertices, g.faces, spheres=10, resolution=30, measure_resolution=40)
            out[name]["clump"] = np.concatenate([c.centres.ravel(), c.radii]).tolist()
print(json.dumps(out))
"""


def _features():
    from numpy._core._multiarray_umath import __cpu_features__ as feats

    return feats


def _paths():
    """(name, extra environment) of the code paths this machine can run."""
    paths = [("default", {})]
    paths.append(("openblas-haswell", {"OPENBLAS_CORETYPE": "Haswell"}))
    feats = _features()
    wide = [f for f in ("AVX512_SPR", "AVX512_ICL", "AVX512_SKX", "X86_V4") if feats.get(f)]
    if wide:
        paths.append(("numpy-no-avx512", {"NPY_DISABLE_CPU_FEATURES": ",".join(wide)}))
    return paths


def _run(env_extra):
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")}
    env.update(env_extra)
    res = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def runs():
    # the default path twice (run-to-run determinism), every other path once
    return {name: (_run(extra), _run(extra) if name == "default" else None) for name, extra in _paths()}


def test_each_path_is_deterministic_and_block_size_free(runs):
    for name, (a, _) in runs.items():
        assert len(a["fso_chunks"]) == 1, (name, "wm_sum depends on the block size")
    first, second = runs["default"]
    assert first == second, "two runs of the same path differ"


def test_paths_agree_to_rounding(runs):
    base = runs["default"][0]
    for name, (other, _) in runs.items():
        for method in ("fso", "cri", "dpa", "angular", "rf"):
            a, b = base[method], other[method]
            v0, v1 = np.asarray(a["v"]), np.asarray(b["v"])
            assert v0.shape == v1.shape, (name, method)
            # float32 file coordinates: at most one unit in the last place apart
            assert np.abs(v0 - v1).max() <= 2.0**-23 * np.abs(v0).max(), (name, method)
            assert np.abs(np.asarray(a["n"]) - np.asarray(b["n"])).max() <= 1e-6, (name, method)
        for method in ("fso", "angular"):
            # the greedy's choices are discrete: a last-bit change could flip a
            # tie; none does on these grains (same spheres to 1e-9 of the size)
            c0, c1 = np.asarray(base[method]["clump"]), np.asarray(other[method]["clump"])
            assert c0.shape == c1.shape, (name, method)
            assert np.abs(c0 - c1).max() <= 1e-9 * np.abs(c0).max(), (name, method)
