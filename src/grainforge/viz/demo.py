"""The main job behind ``make demo``: galleries like the paper's figures.

The demo is a list of sections; each section writes grains (with manifests)
and contact sheets under the output folder and returns what it wrote.  The
generators' sections are added as they land.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..rng import RNGLike

__all__ = ["SECTIONS", "run_demo", "fso_sweeps", "dpa_sweeps", "cri_gallery", "angular_gallery", "print_tray", "rf_gallery",
           "sample_micrograph", "write_fourier_csv", "grain_image", "example_images", "EXAMPLE_IMAGES"]


def _sweep_panels(out: Path, method: str, make_params, values, label, seeds) -> tuple[list, list[str]]:
    """Write one run per value into ``out/<label>=<value>``; the meshes and labels of a sheet, row by seed."""
    from ..io import read_mesh
    from ..io.inputs import MANIFEST, read_manifest
    from ..population.generate import write_run

    panels = {}  # (seed index, value index) -> (mesh, label): one row per seed, one column per value
    for j, value in enumerate(values):
        folder = out / f"{label}={value:g}"
        write_run(method, make_params(value), seeds=seeds, out=folder, overwrite=True)
        rows = read_manifest(folder / MANIFEST)
        for i, r in enumerate(rows):
            panels[i, j] = (read_mesh(folder / r["file"]), f"{label}={value:g}  seed {r['seed']}")
    order = sorted(panels)
    return [panels[k][0] for k in order], [panels[k][1] for k in order]


def _sweep_sheet(out: Path, meshes, labels, columns, title, radius=None) -> list[Path]:
    from .render import contact_sheet

    sheet = out.with_suffix(".png")
    contact_sheet(meshes, labels, sheet, columns=columns, title=title + " (files at d_eq = 10 mm)", unit="mm",
                  radius=radius)
    return [out, sheet]


def _sweep(out: Path, method: str, make_params, values, label, seeds, title) -> list[Path]:
    meshes, labels = _sweep_panels(out, method, make_params, values, label, seeds)
    return _sweep_sheet(out, meshes, labels, len(values), title)


def fso_sweeps(out: Path, quick: bool = False) -> list[Path]:
    """The paper's Figures 1 and 2: FSO grains over L/R0 at D = 2.4 and over D at L = 7R0.

    Parameters
    ----------
    out : Path
        The demo's output folder.
    quick : bool, default False
        Fewer seeds and coarser meshes (the quick demo).

    Returns
    -------
    list of Path
        The run folders and their contact sheets.
    """
    from ..methods.fso import Params
    from .figures import FIG1_LENGTHS, FIG2_DIMENSIONS

    seeds = [0, 1] if quick else [0, 1, 2]
    s = 4 if quick else 5
    written = _sweep(
        out / "fso-length-ratio", "fso", lambda L: Params(length_ratio=L, subdivisions=s),
        FIG1_LENGTHS, "L", seeds,
        "FSO, D = 2.4: stochastic length L/R0 from 0.1 to 10 (paper Fig. 1)",
    )
    written += _sweep(
        out / "fso-fractal-dimension", "fso", lambda D: Params(fractal_dimension=D, subdivisions=s),
        FIG2_DIMENSIONS, "D", seeds,
        "FSO, L = 7 R0: fractal dimension D from 2.0 to 2.8 (paper Fig. 2)",
    )
    return written


def cri_gallery(out: Path, quick: bool = False) -> list[Path]:
    """The paper's Figures 3 and 4: contours from three sources, and CRI grains from them.

    There are no real micrographs in this repository: the "micrograph" is a
    synthetic grain image (a Fourier contour drawn, blurred and speckled with
    scikit-image) that is written to PNG and read back like a real one.

    Parameters
    ----------
    out : Path
        The demo's output folder.
    quick : bool, default False
        Fewer seeds and coarser meshes (the quick demo).

    Returns
    -------
    list of Path
        The folder of runs and images, the contour figure and the contact sheets.
    """
    import numpy as np

    from ..io import read_mesh, save_figure
    from ..io.inputs import MANIFEST, read_manifest
    from ..methods.cri import Params
    from ..outline.contours import Contour
    from ..population.generate import write_run
    from .render import contact_sheet

    seeds = [0, 1] if quick else [0, 1, 2]
    s = 3 if quick else 5
    folder = out / "cri"
    folder.mkdir(parents=True, exist_ok=True)
    # synthetic micrographs: three drawn grains, blurred, with sensor noise
    images = [str(grain_image(folder / f"synthetic-micrograph-{i}.png", rng=i)) for i in range(3)]
    # Figure 3: one contour from each source
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sources = [
        ("fractal profile (2D Eq. 1)", Contour.from_fractal(rng=1)),
        ("Fourier descriptors 0.15, 0.10, 0.03", Contour.from_descriptors("rough-angular", rng=1)),
        ("synthetic micrograph (extracted)", Contour.from_image(images[0])),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(9, 3.3), dpi=110)
    for ax, (label, c) in zip(axes, sources):
        p = np.vstack([c.points(), c.points()[:1]])
        ax.fill(p[:, 0], p[:, 1], color=(0.78, 0.68, 0.52), lw=1.0, ec="k")
        d = c.descriptors()
        ax.set_title(f"{label}\nD2={d[2]:.3f} D3={d[3]:.3f} D8={d[8]:.3f}", fontsize=8)
        ax.set_aspect("equal")
        ax.set_axis_off()
    fig.suptitle("CRI input contours from three sources (paper Fig. 3)", fontsize=10)
    fig.subplots_adjust(top=0.78, bottom=0.02, left=0.02, right=0.98)
    written = [save_figure(fig, out / "cri-contours.png")]
    # Figure 4: grains from both presets and the three sources
    runs = [
        ("rough-sphere", Params(preset="rough-sphere", subdivisions=s)),
        ("rough-angular", Params(preset="rough-angular", subdivisions=s)),
        ("fractal", Params(contour="fractal", subdivisions=s)),
        ("micrographs", Params(images=",".join(images), subdivisions=s)),
    ]
    meshes, labels = [], []
    for name, params in runs:
        run_seeds = seeds[:1] if name == "micrographs" else seeds  # images: no randomness
        write_run("cri", params, seeds=run_seeds, out=folder / name, overwrite=True)
        rows = read_manifest(folder / name / MANIFEST)
        for r in rows:
            meshes.append(read_mesh(folder / name / r["file"]))
            labels.append(f"{name}  seed {r['seed']}")
    sheet = contact_sheet(meshes, labels, out / "cri-grains.png", columns=len(seeds),
                          title="CRI grains by contour source (paper Figs. 4, 8; files at d_eq = 10 mm)", unit="mm")
    written += [folder, sheet, cri_sections_figure(out / "cri-sections.png", s)]
    return written


def cri_sections_figure(path: Path, subdivisions: int = 5) -> Path:
    """Verification figure: a CRI grain's principal sections against its contours (:func:`cri_sections`)."""
    from ..io import save_figure

    return save_figure(cri_sections(subdivisions), path)


def cri_sections(subdivisions: int = 5):
    """The Figure of :func:`cri_sections_figure`: the three panels share one scale (equal axes, same
    limits), coordinates in units of the mean contour radius r0, legend below the panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    import trimesh

    from ..methods.cri import GRID, PLANES, Params, build, construct
    from ..outline.contours import Contour

    p = Params(preset="rough-angular", subdivisions=subdivisions)
    v, f, _ = build(p, 0)
    con = construct(p, 0)
    mesh = trimesh.Trimesh(v, f, process=False)
    normals = {"xy": (0, 0, 1), "xz": (0, 1, 0), "yz": (1, 0, 0)}
    axes2 = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}
    t = 2 * np.pi * np.arange(GRID + 1) / GRID
    fig, axes = plt.subplots(1, 3, figsize=(10, 4.2), dpi=100, sharex=True, sharey=True)
    reach = 0.0
    for k, (ax, plane) in enumerate(zip(axes, PLANES)):
        before = con.sections[k] / con.factors[k]
        r_in = np.r_[before, before[0]]
        r_sec = np.r_[con.sections[k], con.sections[k][0]]
        ax.plot(r_in * np.cos(t), r_in * np.sin(t), color="0.6", lw=1, label="contour before correction")
        ax.plot(r_sec * np.cos(t), r_sec * np.sin(t), color="C0", lw=1.5, label="contour stretched + corrected")
        cut = np.asarray(mesh.section(plane_origin=(0, 0, 0), plane_normal=normals[plane]).vertices)
        i, j = axes2[plane]
        ax.plot(cut[:, i], cut[:, j], ".", color="C3", ms=2, label="section of the mesh")
        sec = Contour(con.sections[k])
        ang = np.arctan2(cut[:, j], cut[:, i])
        err = np.abs(np.hypot(cut[:, i], cut[:, j]) - sec(ang) * sec.scale).max() / con.sections[k].mean()
        ax.set_title(f"{plane} section: max error {100 * err:.2f} % of r0", fontsize=9)
        ax.set_xlabel(f"{plane[0]} / r0")
        ax.set_ylabel(f"{plane[1]} / r0")
        ax.set_aspect("equal")
        ax.grid(True, color="0.92", lw=0.5)
        ax.tick_params(labelsize=7, labelleft=True)
        reach = max(reach, float(np.abs(r_in).max()), float(np.abs(r_sec).max()), float(np.abs(cut).max()))
    lim = 1.06 * reach
    for ax in axes:
        ax.set_xlim(-lim, lim)
        ax.set_ylim(-lim, lim)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)
    fig.suptitle(f"CRI rough-angular, seed 0, subdivisions {subdivisions}: principal sections "
                 "(r0: mean contour radius)", fontsize=10)
    fig.tight_layout(rect=(0, 0.08, 1, 0.95))
    return fig


def _analysis_plots(out: Path, quick: bool = False) -> list[Path]:
    from .plots import demo_plots  # lazily: matplotlib

    return demo_plots(out, quick)


def dpa_sweeps(out: Path, quick: bool = False) -> list[Path]:
    """The paper's Figures 5 and 6: DPA aggregates of cubes (sharp and smoothed) and octahedra over ε.

    All three sheets are drawn at one scale (one scale-bar length), that of the largest aggregate.

    Parameters
    ----------
    out : Path
        The demo's output folder.
    quick : bool, default False
        Fewer seeds and coarser meshes (the quick demo).

    Returns
    -------
    list of Path
        The run folders and their contact sheets.
    """
    from ..methods.dpa import Params
    from .render import view_radius

    seeds = [0, 1] if quick else [0, 1, 2]
    n = 100 if quick else 300
    values = [0.1, 1, 3, 10, 30, 100]
    sweeps = [
        (out / "dpa-cubes", lambda e: Params(primitive="cube", exponent=e, primaries=n), values, seeds,
         f"DPA, {n} cubes: exponent ε from 0.1 (compact) to 100 (branching) (paper Fig. 5)"),
        (out / "dpa-cubes-smoothed", lambda e: Params(primitive="cube", exponent=e, primaries=n, smooth=2),
         values[::2] if quick else values, seeds[:1] if quick else seeds,
         f"DPA, {n} cubes with rounded corners (smooth = 2) (paper Fig. 5, right)"),
        (out / "dpa-octahedra", lambda e: Params(primitive="octahedron", exponent=e, primaries=n), values, seeds,
         f"DPA, {n} octahedra: exponent ε from 0.1 to 100 (paper Fig. 6)"),
    ]
    panels = [_sweep_panels(folder, "dpa", make, vals, "eps", s) for folder, make, vals, s, _ in sweeps]
    # one scale for the whole DPA gallery: every grain has d_eq = 10 mm, so extents compare (compact vs branching)
    radius = max(view_radius(m) for meshes, _ in panels for m in meshes)
    written: list[Path] = []
    for (folder, _, vals, _, title), (meshes, labels) in zip(sweeps, panels):
        written += _sweep_sheet(folder, meshes, labels, len(vals), title, radius=radius)
    return written


#: the angular gallery: columns from sharp to rounded, rows from smooth to rough
ANGULAR_ROUNDING = (0.0, 0.1, 0.25, 0.5, 0.8)
ANGULAR_ROUGHNESS = (0.0, 0.01, 0.03)


def angular_gallery(out: Path, quick: bool = False) -> list[Path]:
    """Angular (crushed-rock) grains: sharp to rounded (columns) and smooth to rough (rows), one seed.

    A last row shows dented grains (lower convexity), also sharp to rounded.

    Parameters
    ----------
    out : Path
        The demo's output folder.
    quick : bool, default False
        Fewer seeds and coarser meshes (the quick demo).

    Returns
    -------
    list of Path
        The folder of runs and the contact sheet.
    """
    from ..io import read_mesh
    from ..io.inputs import MANIFEST, read_manifest
    from ..methods.angular import Params
    from ..population.generate import write_run
    from .render import contact_sheet

    s = 4 if quick else 5
    folder = out / "angular"
    meshes, labels = [], []
    rows = [(f"roughness {q:g}", dict(roughness=q)) for q in ANGULAR_ROUGHNESS]
    rows.append(("6 dents, roughness 0.01", dict(roughness=0.01, dents=6, dent_depth=0.35)))
    for name, extra in rows:
        for rounding in ANGULAR_ROUNDING:
            params = Params(facets=18, aspect=(1.6, 1.25, 1.0), rounding=rounding, subdivisions=s, **extra)
            sub = folder / f"{name.replace(' ', '-').replace(',', '')}-rounding={rounding:g}"
            write_run("angular", params, seeds=[3], out=sub, overwrite=True)
            meshes.append(read_mesh(sub / read_manifest(sub / MANIFEST)[0]["file"]))
            labels.append(f"rounding {rounding:g}, {name}")
    sheet = contact_sheet(meshes, labels, out / "angular-gallery.png", columns=len(ANGULAR_ROUNDING),
                          title="Angular grains (18 facets, aspect 1.6:1.25:1, seed 3): sharp to rounded "
                                "(left to right), smooth to rough (top to bottom), dented (last row)")
    return [folder, sheet]


POPULATION_RECIPE = """\
# demo: a rough-angular CRI sand graded like ASTM C778 graded sand (by mass, sieve sizes)
method = "cri"
count = {count}
seed = 778
[params]
preset = "rough-angular"
aspect = {{ distribution = "choice", values = [[1.25, 1.1, 1.0], [1.45, 1.2, 1.0], [1.7, 1.3, 1.0]], weights = [2, 2, 1] }}
subdivisions = 3
[size]
definition = "sieve"
sieves_mm = [0.10, 0.15, 0.30, 0.425, 0.60, 1.18]
percent_passing = [0, 2, 25, 70, 98, 100]
"""


def population_demo(out: Path, quick: bool = False) -> list[Path]:
    """A small population (docs/populations.md): grains, manifest, summary JSON and report PNG."""
    from ..population import parse_recipe, run_batch

    folder = out / "population-cri-sand"
    recipe = parse_recipe(POPULATION_RECIPE.format(count=16 if quick else 60), source="cri-sand-demo.toml")
    run_batch(recipe, folder, overwrite=True)
    return [folder, folder / "population.png"]




def sample_micrograph(path: Path, *, rows: int = 5, columns: int = 6, rng: RNGLike = 1) -> Path:
    """A synthetic micrograph of a sand sample: ``rows × columns`` separate grains, blurred and speckled.

    There are no real micrographs in this repository; the grains are Fourier
    contours whose descriptors vary from grain to grain as a natural sand's
    do (D2 ~ U(0.04, 0.25), D3 ~ U(0.02, 0.10), D8 ~ U(0.008, 0.03), decay
    exponents ~ U(−2.2, −1.2)), drawn at radius 55 px on a 160 px grid,
    blurred (σ = 1.5 px) and given sensor noise (σ = 10 grey levels), so that
    ``grainforge fourier`` reads them as it would a real image.

    Parameters
    ----------
    path : Path
        The PNG file to write.
    rows, columns : int, default 5, 6
        Grains down and across.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator, default 1
        Normalised by :func:`grainforge.rng.as_generator`: the descriptors, contours and noise are drawn from it.

    Returns
    -------
    Path
        ``path``.
    """
    import io as _io

    import numpy as np
    from PIL import Image
    from skimage.filters import gaussian

    from ..io import atomic_write
    from ..outline.contours import Contour
    from ..outline.imaging import draw_contours
    from ..rng import as_generator

    rng = as_generator(rng)
    items = []
    for i in range(rows * columns):
        d = (rng.uniform(0.04, 0.25), rng.uniform(0.02, 0.10), rng.uniform(0.008, 0.03))
        decay = tuple(rng.uniform(-2.2, -1.2, 2))
        c = Contour.from_descriptors(d, decay=decay, rng=rng)
        items.append((c, (100 + 160 * (i % columns), 100 + 160 * (i // columns)), 55.0))
    img = draw_contours((40 + 160 * rows, 40 + 160 * columns), items, background=35, fill=205).astype(float)
    img = gaussian(img, sigma=1.5, preserve_range=True)
    img += rng.normal(0.0, 10.0, img.shape)
    buf = _io.BytesIO()
    Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(buf, format="png")
    return atomic_write(path, buf.getvalue())


def grain_image(path: Path, *, rng: RNGLike, size: int = 512) -> Path:
    """A synthetic micrograph of one grain: a rough-angular Fourier contour drawn, blurred and speckled.

    The contour (``Contour.from_descriptors("rough-angular", rng=...)``)
    is drawn with radius 170/512 of the ``size`` × ``size`` picture, blurred
    (σ = 2/512 of it) and given sensor noise (σ = 12 grey levels):
    what ``generate cri --images`` and ``Contour.from_image`` read as a real grain image.

    Parameters
    ----------
    path : Path
        The PNG file to write.
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        An int ``s`` draws the contour from ``100 + s`` and the noise from ``200 + s`` (the streams of
        ``examples/images/``); any other value is normalised by :func:`grainforge.rng.as_generator` and the
        contour then the noise are drawn from it.
    size : int, default 512
        Picture width and height, pixels.

    Returns
    -------
    Path
        ``path``.
    """
    import io as _io

    import numpy as np
    from PIL import Image
    from skimage.filters import gaussian

    from ..io import atomic_write
    from ..outline.contours import Contour
    from ..outline.imaging import draw_contours
    from ..rng import as_generator

    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        as_generator(rng)  # refuses a negative seed
        contour_rng, noise_rng = 100 + int(rng), 200 + int(rng)  # the streams of examples/images/
    else:
        contour_rng = noise_rng = as_generator(rng)
    c = Contour.from_descriptors("rough-angular", rng=contour_rng)
    img = draw_contours((size, size), [(c, (size // 2, size // 2), 170.0 * size / 512)], background=40,
                        fill=200).astype(float)
    img = gaussian(img, sigma=2.0 * size / 512, preserve_range=True)
    img += as_generator(noise_rng).normal(0.0, 12.0, img.shape)
    buf = _io.BytesIO()
    Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(buf, format="png")
    return atomic_write(path, buf.getvalue())


#: the example images the README's commands read (examples/images/), made by :func:`example_images`
EXAMPLE_IMAGES = ("micrograph.png", "grain-a.png", "grain-b.png", "grain-c.png")


def example_images(folder: Path) -> list[Path]:
    """Write the small example images of ``examples/images/`` into ``folder``.

    ``micrograph.png``: a sample of 2 × 3 grains (:func:`sample_micrograph`) for
    ``grainforge fourier``; ``grain-a/b/c.png``: three single-grain images
    (:func:`grain_image`, 256 px) for ``generate cri --images``.

    Parameters
    ----------
    folder : Path
        Created if missing.

    Returns
    -------
    list of Path
        The four images.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = [sample_micrograph(folder / EXAMPLE_IMAGES[0], rows=2, columns=3)]
    written += [grain_image(folder / name, rng=i, size=256) for i, name in enumerate(EXAMPLE_IMAGES[1:])]
    return written


def write_fourier_csv(images, path: Path) -> Path:
    """The D2..D16 table ``grainforge fourier IMAGE... --csv path`` writes (same scan, 128 rays).

    Only the ``image``, ``grain`` and ``D2``..``D16`` columns, which is what
    the ``spectrum`` inputs of rf and CRI read.

    Parameters
    ----------
    images : iterable of path
        Grain images.
    path : Path
        The CSV file.

    Returns
    -------
    Path
        ``path``.
    """
    from ..io import write_csv
    from ..outline.contours import scan_image

    rows = []
    for image in images:
        scan = scan_image(str(image), n_angles=128)
        for i, c in enumerate(scan.contours):
            D = c.descriptors(16)
            rows.append({"image": str(image), "grain": i, **{f"D{n}": float(D[n]) for n in range(2, 17)}})
    return write_csv(path, rows, ["image", "grain"] + [f"D{n}" for n in range(2, 17)])


def rf_gallery(out: Path, quick: bool = False) -> list[Path]:
    """rf grains from a measured spectrum: a sample micrograph → its D2..D16 table → one rf grain per seed."

    Parameters
    ----------
    out : Path
        The demo's output folder.
    quick : bool, default False
        Fewer seeds and coarser meshes (the quick demo).

    Returns
    -------
    list of Path
        The folder (micrograph, table, runs) and the contact sheet.
    """
    from ..io import read_mesh
    from ..io.inputs import MANIFEST, read_manifest
    from ..methods.rf import Params
    from ..population.generate import write_run
    from .render import contact_sheet

    folder = out / "rf"
    folder.mkdir(parents=True, exist_ok=True)
    image = sample_micrograph(folder / "sample-micrograph.png")
    table = write_fourier_csv([image], folder / "fd.csv")
    seeds = list(range(6 if quick else 12))
    p = Params(spectrum=str(table), subdivisions=4 if quick else 5)
    write_run("rf", p, seeds=seeds, out=folder / "from-spectrum", overwrite=True)
    rows = read_manifest(folder / "from-spectrum" / MANIFEST)
    meshes = [read_mesh(folder / "from-spectrum" / r["file"]) for r in rows]
    labels = [f"seed {r['seed']}: grain #{r['spectrum_row']}" for r in rows]
    sheet = contact_sheet(meshes, labels, out / "rf-grains.png", columns=6, dpi=90, panel_size=2.2, unit="mm",
                          title="rf grains, each from one measured grain's D2..D16 (sample micrograph; "
                                "files at d_eq = 10 mm)")
    return [folder, sheet]


def print_tray(out: Path, quick: bool = False) -> list[Path]:
    """A PolyJet tray of 2 mm CRI grains (resolution matched), and the check of its first grains.

    Parameters
    ----------
    out : Path
        The demo's output folder.
    quick : bool, default False
        Fewer seeds and coarser meshes (the quick demo).

    Returns
    -------
    list of Path
        The print files, previews, the tray's CSV and the check's CSV.
    """
    from ..fabrication.printability import check_mesh
    from ..fabrication.tray import GeneratorSource, build_tray
    from ..io import write_csv
    from ..io.threemf import read_3mf
    from ..methods.cri import Params

    n = 40 if quick else 400
    res = build_tray(GeneratorSource("cri", Params(preset="rough-angular"), tuple(range(n)), 2.0),
                     "objet-eden-250", out / "tray.3mf", overwrite=True)
    rows = [check_mesh(p.vertices, p.faces, "objet-eden-250", name=p.name).row() for p in read_3mf(res.files[0])[:5]]
    checked = write_csv(out / "check.csv", rows)
    return [*res.files, *res.previews, res.csv, checked]


#: (name, function(out_folder, quick) -> written paths), run in this order
SECTIONS: list[tuple[str, Callable[[Path, bool], list[Path]]]] = [
    ("FSO sweeps (Figs. 1-2)", fso_sweeps),
    ("CRI contours and grains (Figs. 3-4)", cri_gallery),
    ("DPA exponent sweeps (Figs. 5-6)", dpa_sweeps),
    ("Angular grains: sharp to rounded, smooth to rough", angular_gallery),
    ("Population: CRI sand graded like ASTM C778", population_demo),
    ("Shape analysis: Zingg, sphericity-convexity, size and FD plots of the runs above", _analysis_plots),
    ("Print tray: 2 mm rough-angular CRI grains on the paper's PolyJet, checked", print_tray),
    ("rf grains from the spectra of a sample micrograph", rf_gallery),
]


def run_demo(out: str | Path, quick: bool = False, echo: Callable[[str], None] = print) -> list[Path]:
    """Run every demo section into ``out``; return the paths written.

    Parameters
    ----------
    out : str or Path
        Output folder (created).
    quick : bool, default False
        The quick demo.
    echo : callable, default print
        Receives one progress line per section.

    Returns
    -------
    list of Path
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for name, section in SECTIONS:
        echo(f"[demo] {name} ...")
        written += section(out, quick)
    return written
