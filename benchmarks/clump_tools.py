"""Our clumps against two open clump tools: same grains, same measure (docs/benchmarks.md).

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 nice .venv/bin/python benchmarks/clump_tools.py

needs the other tools in a throwaway virtual environment (both GPL: run as subprocesses through
``benchmarks/clump_tools_runner.py``, never imported here nor by grainforge)::

    python3 -m venv /tmp/clumptools && /tmp/clumptools/bin/pip install multisphere==1.1.1 clump-python==0.3.3

Grains: ``--grains`` (3) of each of fso, cri, dpa, angular, rf (``grainforge.<method>(rng=seed)``,
default settings, seeds 1, 2, 3) and the first ``--grains`` twins of the Ottawa sand shipped in
``examples/sand-atlas`` (``grainforge fit … --method rf``, made once into ``--out`` and reused; the
twins are grains 0, 1, 2 of its recipe, as ``grainforge batch`` draws them). Each grain is written
as an STL that every tool reads; every clump is measured by
``grainforge.dem.clump.clump_accuracy(vertices, faces, centres, radii, resolution=100)`` on that
grain's mesh. Tools and settings:

* ``grainforge`` — ``clump(v, f, spheres=N, rng=0)``, defaults (working grid 40 cells per d_eq);
* ``grainforge r80`` — the same on a working grid of 80 cells per d_eq;
* ``multisphere`` 1.1.1 — ``multisphere_from_mesh(mesh, div=100, max_spheres=N)`` (its default grid:
  100 cells along the bounding box's shortest edge); it may stop before N spheres;
* ``CLUMP-EDT`` (clump-python 0.3.3) — ``GenerateClump_Euclidean_3D(stl, N, rMin=0, div=50,
  overlap=0.7)``;
* ``CLUMP-Favier`` — ``GenerateClump_Favier(stl, N)`` (spheres on the longest axis, radius the
  nearest vertex: chooseDistance 'min').

Part 1 (equal sphere count): N = 10, 20, 30, 50. Part 2 (equal accuracy): for each target IoU
(0.80, 0.85, 0.90) the fewest spheres the tool's knob sweep found reaching it (up to ``--cap``
150): grainforge — ``clump(..., spheres=cap, target_iou=T)`` (its own bisection over the nested
greedy prefixes, each measured by ``clump_accuracy``: its CPU time includes that search), or with
``--gf-search bisect`` bisection over ``spheres`` here (the same counts); multisphere — first its own end (``max_spheres``
= cap: it stops earlier when its distance field has no more peaks), then, for the targets that end
reaches, ``precision`` T, T + 0.04, T + 0.08 (``max_spheres`` = cap) until a run with fewer spheres
reaches T, any of its runs on the grain counting;
CLUMP-EDT — overlap 0.5 and 0.7, the spheres are placed one after the other so the k-sphere
clump is the first k spheres of the cap-sphere one: bisection over k, then one timed run at the
k found; CLUMP-Favier — N in 5, 10, 15, 20, 30, 50, 75, 100, 150 with chooseDistance 'min' and
'avg'. CPU s is the process CPU time of the one call that makes the reported clump (in the
tool's own process; reading the STL and voxelising included); search CPU s adds every run the
search made.

Writes ``benchmarks/results/clump_tools.csv`` (one row per grain, tool, N or target) and
``docs/img/clump_tools.png``; prints the two Markdown tables of docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import csv
import inspect
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RUNNER = ROOT / "benchmarks" / "clump_tools_runner.py"
OTTAWA = ROOT / "examples" / "sand-atlas" / "ottawa-7.3um.csv"
FAMILIES = ("fso", "cri", "dpa", "angular", "rf", "ottawa")
TOOLS = ("grainforge", "grainforge r80", "multisphere", "CLUMP-EDT", "CLUMP-Favier")
COUNTS = (10, 20, 30, 50)
TARGETS = (0.80, 0.85, 0.90)
EDT_DIV, EDT_OVERLAP, EDT_OVERLAPS = 50, 0.7, (0.5, 0.7)
FAVIER_N = (5, 10, 15, 20, 30, 50, 75, 100, 150)
FIELDS = ("family", "grain", "tool", "part", "requested", "setting", "spheres", "reached", "iou", "coverage", "spill",
          "volume_error", "inertia_error", "cpu_s", "search_cpu_s")


# --------------------------------------------------------------------------- grains
def ottawa_twins(out: Path, n: int):
    """The first ``n`` twins of the Ottawa sand's rf fit (the fit is made once, into ``out``)."""
    from grainforge.methods import generate
    from grainforge.population import draw_grain, load_recipe

    fit = out / "ottawa-fit"
    if not (fit / "recipe.toml").exists():
        exe = Path(sys.executable).with_name("grainforge")
        subprocess.run([str(exe), "fit", str(OTTAWA), "--voxel-size-um", "7.3", "--method", "rf", "--workers", "1",
                        "--out", str(fit), "--overwrite"], check=True, stdout=subprocess.DEVNULL)
    recipe = load_recipe(fit / "recipe.toml")
    out = []
    for i in range(n):
        seed, params, _ = draw_grain(recipe, i)
        out.append((f"twin {i}", generate(recipe.method, params, rng=seed)))
    return out


def grains(out: Path, n: int, families):
    import grainforge

    for fam in families:
        if fam == "ottawa":
            yield from (("ottawa", name, g) for name, g in ottawa_twins(out, n))
        else:
            for seed in range(1, n + 1):
                yield fam, f"seed {seed}", getattr(grainforge, fam)(rng=seed)


# --------------------------------------------------------------------------- tools
class Grain:
    """One grain: its mesh, its STL, and every clump measured on it (cached by key)."""

    def __init__(self, family, name, g, work: Path):
        import trimesh

        self.family, self.name = family, name
        self.v = np.asarray(g.vertices, dtype=np.float64)
        self.f = np.asarray(g.faces, dtype=np.int64)
        self.dir = work / f"{family}-{name.replace(' ', '')}"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.stl = self.dir / "grain.stl"
        trimesh.Trimesh(self.v, self.f, process=False).export(self.stl)

    def measure(self, centres, radii):
        from grainforge.dem.clump import clump_accuracy

        keep = np.asarray(radii, float).reshape(-1) > 0  # CLUMP-EDT can return zero radii once the image is carved
        return clump_accuracy(self.v, self.f, np.asarray(centres).reshape(-1, 3)[keep], np.asarray(radii)[keep],
                              resolution=100), int(keep.sum())

    def run(self, jobs):
        """Run jobs in the tools' venv; returns {job key: (centres, radii, cpu)}."""
        if not jobs:
            return {}
        todo = [dict(j, out=str(self.dir / f"{j['key']}.npz")) for j in jobs]
        spec = self.dir / "jobs.json"
        spec.write_text(json.dumps({"stl": str(self.stl), "jobs": todo}), encoding="utf-8")
        subprocess.run([ARGS.tools_python, str(RUNNER), str(spec)], check=True, stdout=subprocess.DEVNULL,
                       env=dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1"))
        res = {}
        for j in todo:
            z = np.load(j["out"])
            res[j["key"]] = (z["centres"], z["radii"], float(z["cpu_s"])) if "error" not in z else str(z["error"])
        return res


def row(grain, tool, part, requested, setting, acc=None, count=None, cpu=None, search=None, reached=True):
    r = dict(family=grain.family, grain=grain.name, tool=tool, part=part, requested=requested, setting=setting,
             spheres=count if reached else "", reached=reached, cpu_s=round(cpu, 4) if reached else "",
             search_cpu_s=round(search, 4) if search is not None else "")
    for k in ("iou", "coverage", "spill", "volume_error", "inertia_error"):
        r[k] = round(getattr(acc, k), 5) if acc is not None else ""
    return r


def target_rows(grain, tool, runs):
    """One row per accuracy target from a tool's sweep ``runs`` of (setting, accuracy, spheres, CPU): the fewest
    spheres (then the least CPU) that reach it, else the best run, marked not reached."""
    rows, total = [], sum(x[3] for x in runs)
    for t in TARGETS:
        ok = [x for x in runs if x[1].iou >= t]
        if ok:
            s, acc, count, cpu = min(ok, key=lambda x: (x[2], x[3]))
            rows.append(row(grain, tool, "target", t, s, acc, count, cpu, total))
        elif runs:
            best = max(runs, key=lambda x: x[1].iou)
            rows.append(row(grain, tool, "target", t, "best: " + best[0], best[1], None, None, total, False))
        else:
            rows.append(row(grain, tool, "target", t, "every run failed", None, None, None, total, False))
    return rows


def grainforge_rows(grain, tool, resolution):
    from grainforge.dem.clump import clump

    rows = []
    cache = {}

    def make(n):
        if n not in cache:
            t = time.process_time()
            c = clump(grain.v, grain.f, spheres=n, resolution=resolution, rng=0)
            cpu = time.process_time() - t
            acc, count = grain.measure(c.centres, c.radii)
            cache[n] = (acc, count, cpu)
        return cache[n]

    setting = f"resolution={resolution}"
    for n in COUNTS:
        acc, count, cpu = make(n)
        rows.append(row(grain, tool, "count", n, setting, acc, count, cpu, cpu))
    api = ARGS.gf_search == "api" or (ARGS.gf_search == "auto" and "target_iou" in inspect.signature(clump).parameters)
    for target in TARGETS:
        if api:
            t = time.process_time()
            c = clump(grain.v, grain.f, spheres=ARGS.cap, resolution=resolution, target_iou=target, rng=0)
            cpu = time.process_time() - t
            acc, count = grain.measure(c.centres, c.radii)
            rows.append(row(grain, tool, "target", target, setting + ", clump(target_iou=)", acc, count, cpu, cpu,
                            reached=acc.iou >= target))
            continue
        spent = 0.0
        lo, hi = 0, ARGS.cap  # IoU(lo) < target assumed; bisection for the first n with IoU(n) ≥ target
        acc_hi, _, cpu = make(hi)
        spent += cpu
        if acc_hi.iou < target:
            rows.append(row(grain, tool, "target", target, setting + ", bisection", acc_hi, None, None, spent, False))
            continue
        while hi - lo > 1:
            mid = (lo + hi) // 2
            acc, _, cpu = make(mid)
            spent += cpu
            if acc.iou >= target:
                hi = mid
            else:
                lo = mid
        acc, count, cpu = make(hi)
        rows.append(row(grain, tool, "target", target, setting + ", bisection", acc, count, cpu, spent))
    return rows


def multisphere_rows(grain):
    tool, rows, runs = "multisphere", [], []  # runs: (setting, acc, count, cpu)

    def add(res, key, setting):
        c, r, cpu = res[key]
        acc, count = grain.measure(c, r)
        runs.append((setting, acc, count, cpu))
        return acc, count, cpu

    # its own end: as many spheres as it places (up to the cap); a run asking for more spheres than
    # that makes the same spheres (the same loop, stopped by the same test), so it is not run again
    res = grain.run([dict(tool="multisphere", key="ms-cap", max_spheres=ARGS.cap)])
    end = add(res, "ms-cap", f"div=100, max_spheres={ARGS.cap}")
    res = grain.run([dict(tool="multisphere", key=f"ms-n{n}", max_spheres=n) for n in COUNTS if n < end[1]])
    for n in COUNTS:
        setting = f"div=100, max_spheres={n}"
        acc, count, cpu = add(res, f"ms-n{n}", setting) if n < end[1] else end
        rows.append(row(grain, tool, "count", n, setting, acc, count, cpu, cpu))
    # precision T, then T + 0.04, T + 0.08, for the targets its own end reaches and no run has yet
    for step in (0.0, 0.04, 0.08):
        more = [t for t in TARGETS if end[0].iou >= t and not any(a.iou >= t and n < end[1] for _, a, n, _ in runs)
                and t + step <= 1.0]
        if not more:
            break
        keys = {t: f"ms-p{t + step:.2f}" for t in more}
        res = grain.run([dict(tool="multisphere", key=keys[t], precision=round(t + step, 2), max_spheres=ARGS.cap)
                         for t in more])
        for t in more:
            add(res, keys[t], f"div=100, precision={t + step:.2f}")
    return rows + target_rows(grain, tool, runs)


def edt_rows(grain):
    tool, rows = "CLUMP-EDT", []
    jobs = [dict(tool="clump-edt", key=f"edt-o{EDT_OVERLAP}-n{n}", N=n, div=EDT_DIV, overlap=EDT_OVERLAP)
            for n in COUNTS]
    jobs += [dict(tool="clump-edt", key=f"edt-o{o}-cap", N=ARGS.cap, div=EDT_DIV, overlap=o) for o in EDT_OVERLAPS]
    res = grain.run(jobs)
    for n in COUNTS:
        c, r, cpu = res[f"edt-o{EDT_OVERLAP}-n{n}"]
        acc, count = grain.measure(c, r)
        rows.append(row(grain, tool, "count", n, f"div={EDT_DIV}, overlap={EDT_OVERLAP}", acc, count, cpu, cpu))
    search = sum(res[f"edt-o{o}-cap"][2] for o in EDT_OVERLAPS)
    found = {}  # target -> (k, overlap, acc)
    for o in EDT_OVERLAPS:
        c, r, _ = res[f"edt-o{o}-cap"]
        cache = {}

        def prefix(k, c=c, r=r, cache=cache):
            if k not in cache:
                cache[k] = grain.measure(c[:k], r[:k])[0]
            return cache[k]

        for t in TARGETS:
            lo, hi = 0, len(r)
            if prefix(hi).iou < t:
                continue
            while hi - lo > 1:
                mid = (lo + hi) // 2
                lo, hi = (lo, mid) if prefix(mid).iou >= t else (mid, hi)
            if t not in found or hi < found[t][0]:
                found[t] = (hi, o, prefix(hi))
    # the clumps found, made on their own and timed
    timed = {(k, o) for k, o, _ in found.values()}
    res2 = grain.run([dict(tool="clump-edt", key=f"edt-o{o}-k{k}", N=k, div=EDT_DIV, overlap=o) for k, o in timed])
    for t in TARGETS:
        if t not in found:
            best = max(EDT_OVERLAPS, key=lambda o: grain.measure(*res[f"edt-o{o}-cap"][:2])[0].iou)
            acc = grain.measure(*res[f"edt-o{best}-cap"][:2])[0]
            rows.append(row(grain, tool, "target", t, f"best: overlap={best}, N={ARGS.cap}", acc, None, None, search,
                            False))
            continue
        k, o, _ = found[t]
        c, r, cpu = res2[f"edt-o{o}-k{k}"]
        acc, count = grain.measure(c, r)  # the run on its own: the same spheres as the prefix
        search_t = search + sum(res2[f"edt-o{oo}-k{kk}"][2] for kk, oo in timed)
        rows.append(row(grain, tool, "target", t, f"div={EDT_DIV}, overlap={o}, N={k}", acc, count, cpu, search_t,
                        acc.iou >= t))
    return rows


def favier_rows(grain):
    tool, rows = "CLUMP-Favier", []
    settings = sorted({(n, "min") for n in COUNTS} | {(n, ch) for n in FAVIER_N for ch in ("min", "avg")})
    res = grain.run([dict(tool="clump-favier", key=f"fav-{ch}-{n}", N=n, choose=ch) for n, ch in settings])
    runs = []
    for n, ch in settings:
        if isinstance(res[f"fav-{ch}-{n}"], str):  # the tool failed on this grain (e.g. a span without vertices)
            if ch == "min" and n in COUNTS:
                rows.append(row(grain, tool, "count", n, "failed: " + res[f"fav-{ch}-{n}"], reached=False))
            continue
        c, r, cpu = res[f"fav-{ch}-{n}"]
        acc, count = grain.measure(c, r)
        runs.append((f"chooseDistance={ch}, N={n}", acc, count, cpu))
        if ch == "min" and n in COUNTS:
            rows.append(row(grain, tool, "count", n, "chooseDistance=min", acc, count, cpu, cpu))
    return rows + target_rows(grain, tool, runs)


# --------------------------------------------------------------------------- report
def tables(rows):
    """The two Markdown tables: IoU at equal sphere count; spheres and CPU at equal accuracy."""
    fams = [f for f in FAMILIES if any(r["family"] == f for r in rows)] + ["all"]

    def sel(fam, tool, part, req):
        return [r for r in rows if (fam == "all" or r["family"] == fam) and r["tool"] == tool and r["part"] == part
                and float(r["requested"]) == req and (part == "target" or r["iou"] != "")]

    out = ["| grains | tool | " + " | ".join(f"IoU at {n}" for n in COUNTS) + " | CPU s at 10 / 30 / 50 "
           "| coverage / spill % / inertia err. at 30 |", "|---|---|" + "---:|" * (len(COUNTS) + 2)]
    for fam in fams:
        for tool in TOOLS:
            cells, cpus = [], []
            for n in COUNTS:
                s = sel(fam, tool, "count", n)
                if not s:
                    cells.append("—")
                    continue
                iou = np.mean([r["iou"] for r in s])
                sph = np.mean([r["spheres"] for r in s])
                failed = sum(1 for r in rows if (fam == "all" or r["family"] == fam) and r["tool"] == tool
                             and r["part"] == "count" and float(r["requested"]) == n and r["iou"] == "")
                cells.append(f"{iou:.3f}" + (f" ({sph:.0f})" if sph < n - 0.5 else "")
                             + (f", {failed} failed" if failed else ""))
            for n in (10, 30, 50):
                s = sel(fam, tool, "count", n)
                cpus.append(f"{np.mean([r['cpu_s'] for r in s]):.2f}" if s else "—")
            s = sel(fam, tool, "count", 30)
            extra = (f"{np.mean([r['coverage'] for r in s]):.3f} / {100 * np.mean([r['spill'] for r in s]):.2f} / "
                     f"{np.mean([r['inertia_error'] for r in s]):.3f}") if s else "—"
            out.append(f"| {fam} | {tool} | " + " | ".join(cells) + f" | {' / '.join(cpus)} | {extra} |")
    out += ["", "| grains | tool | " + " | ".join(f"IoU {t:.2f}: spheres (CPU s)" for t in TARGETS)
            + " | search CPU s (all targets) |", "|---|---|" + "---:|" * (len(TARGETS) + 1)]
    for fam in fams:
        for tool in TOOLS:
            cells = []
            for t in TARGETS:
                s = sel(fam, tool, "target", t)
                ok = [r for r in s if r["reached"] in (True, "True")]
                if not s:
                    cells.append("—")
                elif not ok:
                    best = [r["iou"] for r in s if r["iou"] != ""]
                    cells.append(f"none of {len(s)}" + (f" (best IoU {max(best):.3f})" if best else ""))
                else:
                    c = f"{np.mean([r['spheres'] for r in ok]):.0f} ({np.mean([r['cpu_s'] for r in ok]):.2f})"
                    cells.append(c if len(ok) == len(s) else f"{c}, {len(ok)} of {len(s)}")
            s = [r for r in rows if (fam == "all" or r["family"] == fam) and r["tool"] == tool and r["part"] == "target"]
            grains_ = {(r["family"], r["grain"]) for r in s}
            search = (sum(max(float(r["search_cpu_s"]) for r in s if (r["family"], r["grain"]) == g) for g in grains_)
                      / max(len(grains_), 1))
            out.append(f"| {fam} | {tool} | " + " | ".join(cells) + f" | {search:.1f} |")
    # paired: on the grains both grainforge (default) and the other tool reach the target
    out += ["", "| target IoU | tool | grains both reach (of all) | its spheres / grainforge's (median) "
            "| grains where grainforge needs fewer / as many / more | its CPU / grainforge's (median) |",
            "|---:|---|---:|---:|---|---:|"]
    reached = {(r["family"], r["grain"], r["tool"], float(r["requested"])): r for r in rows
               if r["part"] == "target" and r["reached"] in (True, "True")}
    every = {(r["family"], r["grain"]) for r in rows}
    for t in TARGETS:
        for tool in TOOLS[1:]:
            pairs = [(reached[(f, g, "grainforge", t)], reached[(f, g, tool, t)]) for f, g in sorted(every)
                     if (f, g, "grainforge", t) in reached and (f, g, tool, t) in reached]
            if not pairs:
                out.append(f"| {t:.2f} | {tool} | 0 (of {len(every)}) | — | — | — |")
                continue
            ratio = np.median([float(o["spheres"]) / float(m["spheres"]) for m, o in pairs])
            fewer = sum(float(m["spheres"]) < float(o["spheres"]) for m, o in pairs)
            same = sum(float(m["spheres"]) == float(o["spheres"]) for m, o in pairs)
            cpu = np.median([float(o["cpu_s"]) / max(float(m["cpu_s"]), 1e-9) for m, o in pairs])
            out.append(f"| {t:.2f} | {tool} | {len(pairs)} (of {len(every)}) | {ratio:.2f} | "
                       f"{fewer} / {same} / {len(pairs) - fewer - same} | {cpu:.1f} |")
    return "\n".join(out)


def figure(rows, path: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fams = [f for f in FAMILIES if any(r["family"] == f for r in rows)]
    fig, axes = plt.subplots(2, 3, figsize=(12, 7.5), sharex=True, sharey=True)
    marks = dict(zip(TOOLS, ("o", "s", "^", "D", "v")))
    for ax, fam in zip(axes.ravel(), fams):
        for i, tool in enumerate(TOOLS):
            s = [r for r in rows if r["family"] == fam and r["tool"] == tool and r["part"] == "count" and r["iou"] != ""]
            if not s:
                continue
            xs = np.array([r["spheres"] for r in s], float)
            ys = np.array([r["iou"] for r in s], float)
            ax.scatter(xs, ys, s=10, alpha=0.35, color=f"C{i}", marker=marks[tool])
            means = [(np.mean([r["spheres"] for r in s if r["requested"] == n]),
                      np.mean([r["iou"] for r in s if r["requested"] == n])) for n in COUNTS]
            ax.plot(*zip(*means), "-", marker=marks[tool], color=f"C{i}", label=tool)
        ax.set_title(fam if fam != "ottawa" else "Ottawa twins (rf fit)", fontsize=10)
        ax.set_xscale("log")
        ax.set_xticks(COUNTS, [str(n) for n in COUNTS])
        ax.set_xticks([], minor=True)
        ax.tick_params(labelbottom=True)
        ax.grid(alpha=0.3)
        for t in TARGETS:
            ax.axhline(t, color="0.6", lw=0.6, ls=":")
    for ax in axes.ravel()[len(fams):]:
        ax.set_axis_off()
    fig.supxlabel("spheres (asked 10, 20, 30, 50; a tool may place fewer: each point is one grain's clump)", fontsize=10)
    fig.supylabel("IoU with the grain (clump_accuracy, d_eq/100 grid)", fontsize=10)
    axes[0, 0].legend(fontsize=8, loc="lower right")
    fig.suptitle("Clump accuracy against sphere count: lines = mean over the grains, points = each grain", fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def read_rows(path: Path):
    """The rows of a results CSV, numbers as numbers (counts as int, as they were written)."""

    def value(k, v):
        if v == "" or k not in ("requested", "iou", "coverage", "spill", "volume_error", "inertia_error", "cpu_s",
                                "search_cpu_s", "spheres"):
            return v
        x = float(v)
        return int(x) if k in ("requested", "spheres") and x.is_integer() else x

    with open(path, encoding="utf-8", newline="") as fh:
        return [{k: value(k, v) for k, v in r.items()} for r in csv.DictReader(fh)]


ARGS = None


def main():
    global ARGS
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grains", type=int, default=3, help="grains per family")
    ap.add_argument("--families", nargs="*", default=list(FAMILIES))
    ap.add_argument("--cap", type=int, default=150, help="most spheres any equal-accuracy search tries")
    ap.add_argument("--gf-search", choices=("auto", "api", "bisect"), default="auto",
                    help="grainforge's equal-accuracy search: clump(target_iou=) (auto: when clump has it) or bisection")
    ap.add_argument("--tools-python", default="/tmp/clumptools/bin/python")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "clump-tools")
    ap.add_argument("--csv", type=Path, default=ROOT / "benchmarks" / "results" / "clump_tools.csv")
    ap.add_argument("--figure", type=Path, default=ROOT / "docs" / "img" / "clump_tools.png")
    ap.add_argument("--report-only", action="store_true", help="tables and figure from --csv, no runs")
    ap.add_argument("--only", nargs="+", choices=TOOLS, metavar="TOOL",
                    help="run only these tools (quoted names, e.g. 'grainforge r80'); the other tools' rows are kept "
                         "from --csv (the same grains: their clumps do not depend on ours)")
    ARGS = ap.parse_args()
    if ARGS.report_only:
        rows = read_rows(ARGS.csv)
        print(tables(rows))
        figure(rows, ARGS.figure)
        return
    kept = []
    if ARGS.only:
        kept = [r for r in read_rows(ARGS.csv) if r["tool"] not in ARGS.only]
    ARGS.out.mkdir(parents=True, exist_ok=True)
    wall = time.perf_counter()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    rows, done = [], set()
    for fam, name, g in grains(ARGS.out, ARGS.grains, ARGS.families):
        t0 = time.perf_counter()
        grain = Grain(fam, name, g, ARGS.out / "grains")
        makers = {"grainforge": lambda: grainforge_rows(grain, "grainforge", 40),
                  "grainforge r80": lambda: grainforge_rows(grain, "grainforge r80", 80),
                  "multisphere": lambda: multisphere_rows(grain), "CLUMP-EDT": lambda: edt_rows(grain),
                  "CLUMP-Favier": lambda: favier_rows(grain)}
        new = []
        for tool in TOOLS:
            if not ARGS.only or tool in ARGS.only:
                new += makers[tool]()
            else:
                new += [r for r in kept if (r["family"], r["grain"], r["tool"]) == (fam, name, tool)]
        rows += new
        brief = "; ".join(f"{r['tool']}: {r['iou']:.3f}" for r in new
                          if r["part"] == "count" and r["requested"] == 30 and r["iou"] != "")
        print(f"{fam} {name}: {time.perf_counter() - t0:.0f} s wall; IoU at 30 — {brief}", flush=True)
        done.add((fam, name))
        ARGS.csv.parent.mkdir(parents=True, exist_ok=True)
        with open(ARGS.csv, "w", encoding="utf-8", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=FIELDS)
            w.writeheader()
            w.writerows(rows)
            # with --only, the kept rows of the grains still to come (an interrupted run loses none)
            w.writerows(r for r in kept if (r["family"], r["grain"]) not in done)
    print(f"\n{(time.perf_counter() - wall) / 60:.1f} min wall; load average {os.getloadavg()[0]:.2f}\n")
    print(tables(rows))
    figure(rows, ARGS.figure)


if __name__ == "__main__":
    main()
