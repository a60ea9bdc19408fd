"""The main job behind ``make demo``: galleries like the paper's figures.

The demo is a list of sections; each section writes grains (with manifests)
and contact sheets under the output folder and returns what it wrote.  The
generators' sections are added as they land.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

__all__ = ["SECTIONS", "run_demo", "fso_sweeps"]


def _sweep(out: Path, method: str, make_params, values, label, seeds, title) -> list[Path]:
    from .io import read_mesh
    from .render import contact_sheet
    from .run import write_run

    panels = {}  # (seed index, value index) -> (mesh, label): one row per seed, one column per value
    for j, value in enumerate(values):
        folder = out / f"{label}={value:g}"
        rows = write_run(method, make_params(value), seeds, folder, overwrite=True)
        for i, r in enumerate(rows):
            panels[i, j] = (read_mesh(folder / r["file"]), f"{label}={value:g}  seed {r['seed']}")
    order = sorted(panels)
    sheet = out.with_suffix(".png")
    contact_sheet([panels[k][0] for k in order], [panels[k][1] for k in order], sheet,
                  columns=len(values), title=title)
    return [out, sheet]


def fso_sweeps(out: Path, quick: bool = False) -> list[Path]:
    """The paper's Figures 1 and 2: FSO grains over L/R0 at D = 2.4 and over D at L = 7R0."""
    from .methods.fso import Params

    seeds = [0, 1] if quick else [0, 1, 2]
    s = 4 if quick else 5
    written = _sweep(
        out / "fso-length-ratio", "fso", lambda L: Params(length_ratio=L, subdivisions=s),
        [0.1, 0.5, 1, 2, 3.5, 5, 7, 10], "L", seeds,
        "FSO, D = 2.4: stochastic length L/R0 from 0.1 to 10 (paper Fig. 1)",
    )
    written += _sweep(
        out / "fso-fractal-dimension", "fso", lambda D: Params(fractal_dimension=D, subdivisions=s),
        [2.0, 2.2, 2.4, 2.6, 2.8], "D", seeds,
        "FSO, L = 7 R0: fractal dimension D from 2.0 to 2.8 (paper Fig. 2)",
    )
    return written


#: (name, function(out_folder, quick) -> written paths)
SECTIONS: list[tuple[str, Callable[[Path, bool], list[Path]]]] = [
    ("FSO sweeps (Figs. 1-2)", fso_sweeps),
]


def run_demo(out: str | Path, quick: bool = False, echo: Callable[[str], None] = print) -> list[Path]:
    """Run every demo section into ``out``; return the paths written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for name, section in SECTIONS:
        echo(f"[demo] {name} ...")
        written += section(out, quick)
    return written
