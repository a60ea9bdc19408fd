"""The paper's Figures 1–6, regenerated with grainforge's own generators.

Hanaor et al., *3D printable geomaterials* (Géotechnique 2016):

1. FSO grains, L from 0.1 R to 10 R at D = 2.4.
2. FSO grains, D from 2.0 to 2.8 at L = 7 R.
3. Grain contours from three sources: (a) a fractal profile, (b) Fourier
   descriptors, (c) a grain image.  The paper's (c) is an optical micrograph
   of a sand grain, which grainforge does not ship; panel (c) here is traced
   from a synthetic image (a rendered FSO grain) through the same image →
   contour path (:meth:`grainforge.outline.contours.Contour.from_image`) a user's
   micrograph would take.
4. CRI grains from three FD-defined contours: (a) three different FD sets,
   (b) and (c) one FD set for all three contours.
5. DPA aggregates of cubes over the exponent ε (top: sharp; bottom: smoothed
   corners, as the paper's Fig. 5 shows).
6. DPA aggregates of octahedra over ε.

Beyond the paper (shape control measured on the grain):

7. FSO aspects: the ellipsoidal precursor (``aspect``), seamless surface.
8. Paper vs seamless FSO surface, each seen from a pole and from the equator
   (the paper form's pinned poles and its mirror seam at the equator).
9. CRI before/after: the 2016 reconstruction (linear stretch, parallel
   ridges) against the default (spectral consistency, ridge twist).

Each figure is one PNG with fixed seeds, so ``grainforge figures`` is
reproducible.  A figure whose generator is not available in this build is
skipped with a message.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["FIGURES", "make_figures", "figure1", "figure2", "figure3", "figure4", "figure5", "figure6", "figure7",
           "figure8", "figure9"]

#: seed used for every panel (one grain per parameter value, same random field)
SEED = 7
#: the L/R values of Fig. 1 and the D values of Fig. 2
FIG1_LENGTHS = (0.1, 0.5, 1.0, 2.0, 3.5, 5.0, 7.0, 10.0)
FIG2_DIMENSIONS = (2.0, 2.2, 2.4, 2.6, 2.8)
#: FD sets (D2, D3, D8) of Fig. 4(a) — xy, xz, yz — and of Figs. 4(b, c)
FIG4_SETS = ((0.15, 0.10, 0.03), (0.08, 0.06, 0.02), (0.22, 0.08, 0.04))
FIG4_SAME = (0.15, 0.10, 0.03)
#: exponents ε of Figs. 5 and 6
DPA_EXPONENTS = (0.2, 1.0, 3.0, 10.0)
DPA_PRIMARIES = 100
#: equivalent diameter (mm) every 3D grain of the figures is scaled to, as printed by default
#: (``grainforge tray`` makes generated grains 10 mm); each panel has a scale bar in mm
PRINTED_SIZE = 10.0
SIZE_NOTE = f"; each grain scaled to d_eq = {PRINTED_SIZE:g} mm"


def _printed(grain):
    """``grain`` scaled to the figures' printed size, d_eq = :data:`PRINTED_SIZE` mm."""
    from ..fabrication.scale import to_size

    return to_size(grain, PRINTED_SIZE)


class Unavailable(Exception):
    """A figure's generator is not part of this build."""


def _method(name: str):
    from ..methods import METHODS

    if name not in METHODS:
        raise Unavailable(f"the {name.upper()} generator is not available in this build")


def figure1(out: Path, subdivisions: int = 5) -> Path:
    """FSO, D = 2.4, L/R from 0.1 to 10 (paper Fig. 1).

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    from ..methods.fso import fso
    from .render import contact_sheet

    grains = [_printed(fso(fractal_dimension=2.4, length_ratio=L, subdivisions=subdivisions, rng=SEED))
              for L in FIG1_LENGTHS]
    labels = [f"({chr(97 + i)}) L = {L:g} R" for i, L in enumerate(FIG1_LENGTHS)]
    return contact_sheet(grains, labels, out, columns=4, unit="mm",
                         title="Fig. 1  FSO grains: stochastic length L from 0.1 R to 10 R, D = 2.4" + SIZE_NOTE)


def figure2(out: Path, subdivisions: int = 5) -> Path:
    """FSO, L = 7 R, D from 2.0 to 2.8 (paper Fig. 2).

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    from ..methods.fso import fso
    from .render import contact_sheet

    grains = [_printed(fso(fractal_dimension=D, length_ratio=7.0, subdivisions=subdivisions, rng=SEED))
              for D in FIG2_DIMENSIONS]
    labels = [f"({chr(97 + i)}) D = {D:.1f}" for i, D in enumerate(FIG2_DIMENSIONS)]
    return contact_sheet(grains, labels, out, columns=5, unit="mm",
                         title="Fig. 2  FSO grains: fractal dimension D from 2.0 to 2.8, L = 7 R" + SIZE_NOTE)


def _synthetic_micrograph(size: int = 320, subdivisions: int = 5) -> np.ndarray:
    """A grey image of a rendered FSO grain on a dark background (stand-in for a micrograph)."""
    from ..methods.fso import fso
    from .render import render_image

    g = fso(fractal_dimension=2.3, length_ratio=4.0, amplitude=0.12, subdivisions=subdivisions, rng=SEED)
    img = render_image(g, size=size, elev=90.0, azim=-90.0, color=(0.85, 0.80, 0.70), background=(0.08, 0.08, 0.10))
    return img.mean(axis=2)


def _traced_micrograph(subdivisions: int = 5):
    """The synthetic micrograph of Fig. 3(c) and the contour traced from it."""
    from ..outline.contours import Contour

    image = _synthetic_micrograph(subdivisions=subdivisions)
    # background 0.09, darkest shaded grain pixel ~0.17: Otsu would split the grain's own light and shadow
    # (it traced only the lit half of the grain)
    return image, Contour.from_image(image, threshold=0.13, foreground="bright")


def figure3(out: Path, subdivisions: int = 5) -> Path:
    """Contours from a fractal profile, Fourier descriptors and an image (paper Fig. 3).

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    _method("cri")
    from ..outline.contours import Contour

    frac = Contour.from_fractal(fractal_dimension=2.4, length_ratio=2.0, amplitude=0.06, rng=SEED)
    four = Contour.from_descriptors(FIG4_SAME, rng=SEED)
    image, traced = _traced_micrograph(subdivisions)
    fig, axes = plt.subplots(1, 3, figsize=(9.6, 3.6), dpi=130)
    for ax, c, lab in ((axes[0], frac, "(a) fractal profile, D = 2.4, L = 2 R"),
                       (axes[1], four, "(b) Fourier descriptors (0.15, 0.10, 0.03)")):
        p = c.points()
        p = np.vstack([p, p[:1]])
        ax.fill(p[:, 0], p[:, 1], color=(0.80, 0.70, 0.53), alpha=0.5)
        ax.plot(p[:, 0], p[:, 1], color="k", lw=1.0)
        ax.plot([0], [0], "+", color="k")
        ax.set_aspect("equal")
        ax.set_title(lab, fontsize=8)
        ax.set_axis_off()
    ax = axes[2]
    ax.imshow(image, cmap="gray", origin="upper")
    p = traced.points(physical=True)
    p = np.vstack([p, p[:1]])
    # image contours have y up with y = −row
    ax.plot(p[:, 0], -p[:, 1], color=(1.0, 0.45, 0.1), lw=1.2)
    ax.set_title("(c) traced from an image (synthetic stand-in\nfor the paper's micrograph)", fontsize=8)
    ax.set_axis_off()
    fig.suptitle("Fig. 3  Grain contours from three sources", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, out)


def figure4(out: Path, subdivisions: int = 5) -> Path:
    """CRI grains from FD-defined contours (paper Fig. 4).

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    _method("cri")
    from ..methods.cri import cri
    from .render import contact_sheet

    a = cri(descriptors=FIG4_SETS[0], descriptors_xz=FIG4_SETS[1], descriptors_yz=FIG4_SETS[2],
            subdivisions=subdivisions, rng=SEED)
    b = cri(descriptors=FIG4_SAME, subdivisions=subdivisions, rng=SEED)
    c = cri(descriptors=FIG4_SAME, subdivisions=subdivisions, rng=SEED + 1)
    fmt = lambda d: "(" + ", ".join(f"{x:g}" for x in d) + ")"  # noqa: E731
    labels = [
        "(a) three FD sets:\n" + " / ".join(fmt(d) for d in FIG4_SETS),
        f"(b) one FD set:\n{fmt(FIG4_SAME)}",
        f"(c) one FD set:\n{fmt(FIG4_SAME)}, another seed",
    ]
    return contact_sheet([_printed(g) for g in (a, b, c)], labels, out, columns=3, panel_size=3.0, unit="mm",
                         title="Fig. 4  CRI grains from three Fourier-descriptor contours" + SIZE_NOTE)


def _dpa_sheet(out: Path, primitive: str, rows: list[tuple[int, str]], title: str) -> Path:
    _method("dpa")
    from ..methods.dpa import dpa
    from .render import contact_sheet

    grains, labels = [], []
    k = 0
    for smooth, note in rows:
        for eps in DPA_EXPONENTS:
            g = dpa(primitive=primitive, exponent=eps, primaries=DPA_PRIMARIES, smooth=smooth, rng=SEED)
            DA = g.info.get("D_A")
            grains.append(_printed(g))
            labels.append(f"({chr(97 + k)}) ε = {eps:g}{note}" + (f", D_A = {DA:.2f}" if DA is not None else ""))
            k += 1
    return contact_sheet(grains, labels, out, columns=len(DPA_EXPONENTS), title=title + SIZE_NOTE, unit="mm",
                         color=(0.72, 0.70, 0.66), common_scale=True)  # one scale: extents compare


def figure5(out: Path, subdivisions: int = 5) -> Path:
    """DPA of cubes over ε, sharp and smoothed (paper Fig. 5)."

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    return _dpa_sheet(out, "cube", [(0, ""), (1, ", smoothed")],
                      f"Fig. 5  DPA aggregates of {DPA_PRIMARIES} cubes: exponent ε (top sharp, bottom smoothed)")


def figure6(out: Path, subdivisions: int = 5) -> Path:
    """DPA of octahedra over ε (paper Fig. 6)."

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    return _dpa_sheet(out, "octahedron", [(0, "")],
                      f"Fig. 6  DPA aggregates of {DPA_PRIMARIES} octahedra: exponent ε")


#: aspects of Fig. 7
FIG7_ASPECTS = ((1.0, 1.0, 1.0), (1.0, 0.8, 0.6), (1.0, 0.7, 0.5), (1.0, 0.5, 0.3))


def _posed(grain, elev: float, azim: float):
    """The grain turned so that the contact sheet's default camera sees it from (elev, azim)."""
    import trimesh

    from .render import view_rotation

    M = view_rotation().T @ view_rotation(elev, azim)
    return trimesh.Trimesh(np.asarray(grain.vertices) @ M.T, grain.faces, process=False)


def figure7(out: Path, subdivisions: int = 5) -> Path:
    """FSO on ellipsoidal precursors (``aspect``), seamless surface, D = 2.4, L = 7 R.

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    from ..methods.fso import fso
    from .render import contact_sheet

    grains, labels = [], []
    for i, asp in enumerate(FIG7_ASPECTS):
        g = fso(aspect=asp, surface="seamless", subdivisions=subdivisions, rng=SEED)
        grains.append(_posed(_printed(g), 25.0, -60.0))
        labels.append(f"({chr(97 + i)}) A:B:C = {':'.join(f'{a:g}' for a in asp)}")
    return contact_sheet(grains, labels, out, columns=4, unit="mm",
                         title="Fig. 7  FSO aspect: overlay on an ellipsoidal precursor (seamless surface, "
                               "D = 2.4, L = 7 R, amplitude 0.1)" + SIZE_NOTE)


def figure8(out: Path, subdivisions: int = 5) -> Path:
    """Paper vs seamless FSO, pole view and equator view (L = 2 R shows more small-scale relief).

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    from ..methods.fso import fso
    from .render import contact_sheet

    grains, labels = [], []
    for surface in ("paper", "seamless"):
        g = _printed(fso(surface=surface, length_ratio=2.0, amplitude=0.12, subdivisions=subdivisions, rng=SEED))
        for view, (elev, azim) in (("pole (+z) view", (90.0, -90.0)), ("equator view", (0.0, -60.0))):
            grains.append(_posed(g, elev, azim))
            labels.append(f"({chr(97 + len(labels))}) {surface}: {view}")
    return contact_sheet(grains, labels, out, columns=4, unit="mm",
                         title="Fig. 8  FSO surface forms (D = 2.4, L = 2 R, amplitude 0.12, same seed): the paper's "
                               "Eqs. 2-3 pin both poles at R0 and mirror the relief about the equator; the seamless "
                               "form has no special latitude or pole" + SIZE_NOTE)


def figure9(out: Path, subdivisions: int = 5) -> Path:
    """CRI before (2016 reconstruction) and after (spectral consistency + ridge twist).

    Parameters
    ----------
    out : Path
        The PNG file.
    subdivisions : int, default 5
        Icosphere level of the grains drawn.

    Returns
    -------
    Path
        ``out``.
    """
    _method("cri")
    from ..methods.cri import cri
    from .render import contact_sheet

    grains, labels = [], []
    for name, kw in (("before: stretch, no twist", {"consistency": "stretch", "ridge_twist": 0.0}),
                     ("after: spectral, twist 30°", {})):
        for preset in ("rough-sphere", "rough-angular"):
            for seed in (SEED, SEED + 1):
                grains.append(_printed(cri(preset=preset, subdivisions=subdivisions, rng=seed, **kw)))
                labels.append(f"({chr(97 + len(labels))}) {preset}\n{name}")
    return contact_sheet(grains, labels, out, columns=4, unit="mm",
                         title="Fig. 9  CRI before (top: the 2016 reconstruction's linear stretch and sweep, "
                               "parallel ridges) and after (bottom: contours keep their modes, roughness turned off "
                               "the sweep direction)" + SIZE_NOTE)


#: number -> (file name, function(out_path, subdivisions) -> path)
FIGURES: dict[int, tuple[str, Callable[[Path, int], Path]]] = {
    1: ("figure1-fso-length.png", figure1),
    2: ("figure2-fso-dimension.png", figure2),
    3: ("figure3-contours.png", figure3),
    4: ("figure4-cri.png", figure4),
    5: ("figure5-dpa-cubes.png", figure5),
    6: ("figure6-dpa-octahedra.png", figure6),
    7: ("figure7-fso-aspect.png", figure7),
    8: ("figure8-fso-seamless.png", figure8),
    9: ("figure9-cri-before-after.png", figure9),
}


def make_figures(out: str | Path, numbers=tuple(FIGURES), *, subdivisions: int = 5,
                 echo: Callable[[str], None] | None = None) -> tuple[list[Path], list[tuple[int, str]]]:
    """Write the requested figures into ``out``.

    Parameters
    ----------
    out : str or Path
        Output folder.
    numbers : iterable of int, default all
        Figure numbers (keys of :data:`FIGURES`).
    subdivisions : int, default 5
        Icosphere level of the grains drawn.
    echo : callable, optional
        Receives one line per figure written.

    Returns
    -------
    written : list of Path
    skipped : list of (number, reason)
        Figures whose generator is not available.

    Raises
    ------
    ValueError
        For a number that is not a figure.
    """
    out = Path(out)
    written, skipped = [], []
    for n in numbers:
        if n not in FIGURES:
            raise InputError(f"figure numbers are 1–{max(FIGURES)}, got {n!r}")
        name, fn = FIGURES[n]
        try:
            written.append(fn(out / name, subdivisions))
        except Unavailable as exc:
            skipped.append((n, str(exc)))
            continue
        if echo is not None:
            echo(f"wrote {out / name}")
    return written, skipped
