"""Runs other clump tools on one STL for ``benchmarks/clump_tools.py`` (never imported by grainforge).

    /tmp/clumptools/bin/python benchmarks/clump_tools_runner.py JOBS.json

Executed only by the interpreter of a throwaway virtual environment holding the
tools (both GPL, never a dependency of grainforge)::

    python3 -m venv /tmp/clumptools && /tmp/clumptools/bin/pip install multisphere clump-python

``JOBS.json`` is ``{"stl": PATH, "jobs": [{"tool": ..., "out": PATH.npz, ...settings}]}``; for each
job the tool is called once on the STL and ``out`` receives ``centres`` (N, 3), ``radii`` (N,) in
the STL's frame and units, and ``cpu_s``, the process CPU time of that one call (reading the STL
and voxelising it included, as each tool does both inside its call); a call that raises leaves
``error`` (the exception) and no spheres instead. Tools:

* ``multisphere`` (Buchele, Müller & Pöschel): ``multisphere_from_mesh(mesh, div=, precision=,
  max_spheres=)``; its grid has ``div`` cells along the shortest edge of the bounding box.
* ``clump-edt`` (CLUMP, Angelidakis et al., Euclidean distance transform):
  ``GenerateClump_Euclidean_3D(stl, N, rMin=0, div, overlap)``; it reports centres relative to
  the centre of its padded voxel image, which is not the mesh's frame: the runner maps them back
  through the image's grid (the same ``trimesh`` voxelisation the tool makes, repeated outside
  the timed call).
* ``clump-favier`` (CLUMP, Favier et al.'s method): ``GenerateClump_Favier(stl, N,
  chooseDistance)``; its centres are in the mesh's frame.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import time

import numpy as np


def run_multisphere(stl, job):
    import multisphere as mss

    mesh = mss.load_mesh(stl)
    kw = {"div": int(job.get("div", 100))}
    if job.get("precision") is not None:
        kw["precision"] = float(job["precision"])
    if job.get("max_spheres") is not None:
        kw["max_spheres"] = int(job["max_spheres"])
    t = time.process_time()
    pack = mss.multisphere_from_mesh(mesh, **kw)
    cpu = time.process_time() - t
    return np.asarray(pack.centers, float).reshape(-1, 3), np.asarray(pack.radii, float).reshape(-1), cpu


def _edt_frame(stl, div):
    """Offset from CLUMP-EDT's reported centres to the mesh frame (the tool's own voxelisation)."""
    import trimesh

    mesh = trimesh.load_mesh(stl)
    p = np.asarray(mesh.vertices)
    lo, hi = p.min(axis=0), p.max(axis=0)
    ave = (lo + hi) / 2
    pitch = float(np.min(hi - lo)) / div
    centred = trimesh.Trimesh(p - ave, mesh.faces, process=False)
    vox = centred.voxelized(pitch=pitch, method="subdivide").fill()
    origin = (np.asarray(vox.transform) @ np.array([0.0, 0.0, 0.0, 1.0]))[:3]
    shape = np.array(vox.matrix.shape) + 4  # the tool pads its image with 2 cells each side
    # the tool reports (i - shape/2 + 1) * pitch for image index i; i sits at origin + (i - 2) * pitch
    # in the centred frame, i.e. at ave + origin + (i - 2) * pitch in the mesh's
    return ave + origin + (shape / 2 - 3) * pitch


def run_clump_edt(stl, job):
    from CLUMP import GenerateClump_Euclidean_3D

    div = int(job.get("div", 50))
    t = time.process_time()
    _, c = GenerateClump_Euclidean_3D(stl, int(job["N"]), 0.0, div, float(job.get("overlap", 0.5)))
    cpu = time.process_time() - t
    centres = np.asarray(c.positions, float).reshape(-1, 3) + _edt_frame(stl, div)
    return centres, np.asarray(c.radii, float).reshape(-1), cpu


def run_clump_favier(stl, job):
    from CLUMP import GenerateClump_Favier

    t = time.process_time()
    _, c = GenerateClump_Favier(stl, int(job["N"]), chooseDistance=job.get("choose", "min"))
    cpu = time.process_time() - t
    return np.asarray(c.positions, float).reshape(-1, 3), np.asarray(c.radii, float).reshape(-1), cpu


TOOLS = {"multisphere": run_multisphere, "clump-edt": run_clump_edt, "clump-favier": run_clump_favier}


def main():
    spec = json.loads(open(sys.argv[1], encoding="utf-8").read())
    for job in spec["jobs"]:
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # the tools print progress
                centres, radii, cpu = TOOLS[job["tool"]](spec["stl"], job)
        except Exception as exc:  # a tool that fails on a grain is a result: recorded, not fatal
            err = f"{type(exc).__name__}: {exc}"
            np.savez(job["out"], centres=np.zeros((0, 3)), radii=np.zeros(0), cpu_s=np.nan, error=err)
            print(json.dumps({"out": job["out"], "error": err}), flush=True)
            continue
        np.savez(job["out"], centres=centres, radii=radii, cpu_s=cpu)
        print(json.dumps({"out": job["out"], "spheres": len(radii), "cpu_s": round(cpu, 3)}), flush=True)


if __name__ == "__main__":
    main()
