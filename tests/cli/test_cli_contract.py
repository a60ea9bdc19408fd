"""The CLI contract, case by case: every bad input, huge request and interrupt.

Every row of :data:`CASES` runs ``grainforge ARGS...`` in a fresh folder and
asserts the contract.  Most rows run *in-process* (click's ``CliRunner``,
through the same ``cli.main`` that turns errors into one line and an exit
code, as the console script does): no interpreter start per row.  The rows
marked ``process=True`` run as a real subprocess (in its own session, with a
6 GiB address-space limit): the huge requests, where the limit is what makes
a request that tries to allocate too much fail fast instead of swapping the
machine, and which also prove the exit codes of the real executable.  Every
row asserts:

- the exit code (2 for bad input; 0 or 1 where the row documents it);
- exactly one line on stderr (or ``lines`` lines where documented), matching ``err``;
- no ``Traceback``;
- no file or folder appears or disappears in the case folder or the shared
  inputs, except the ``creates`` the row documents;
- no process is left afterwards (of the command's session for a subprocess;
  no child of the test process for an in-process row).

Adding a row for a new command
------------------------------
Append a :class:`Case` to :data:`CASES` (or build several with a helper
like :func:`unreadable_mesh_cases`)::

    Case("fit-readonly", ["fit", "{in}/grain.stl", "--out", "ro/fit.csv"], err="cannot write into"),

``{in}`` is the folder of shared inputs made once by :func:`inputs` (a small
grain, a folder of grains with a manifest, corrupt meshes, images, recipes,
printer files; add what your command needs there).  The command runs in the
case folder, which holds ``ro/`` (a folder nobody can write into),
``afile`` (a plain file, for "not a folder" cases), ``exists.png``,
``exists.csv``, ``exists.3mf`` and ``done/`` (existing outputs, for the overwrite rule).  A command that
writes should get at least the rows: read-only folder, under ``afile``, empty
path, existing output without ``--overwrite``.  Interrupt cases (real
signals) are the ``test_sigterm_*``, ``test_sigkill_*`` and ``test_ctrl_c_*`` functions at the end.

Run: ``.venv/bin/python -m pytest tests/cli/test_cli_contract.py -q``.  The in-process rows are in the fast
lane; the subprocess rows, sequences and signals are marked slow.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from _processes import child_processes, kill_sessions, session_processes

#: the CLI as a user runs it (the package this interpreter imports)
CLI = [sys.executable, "-c", "from grainforge.cli.main import main; main()"]
#: address-space limit of every command (bytes): a runaway allocation fails fast
MEMORY_LIMIT = 6 * 1024**3


@dataclass
class Case:
    """One CLI invocation and what it must do.

    Attributes
    ----------
    id : str
        Test id.
    args : list of str
        Arguments after ``grainforge``; ``{in}`` is the shared inputs folder.
    code : int
        Expected exit code (2: refused).
    err : str
        Regular expression the stderr must contain (searched).
    lines : int
        Lines expected on stderr (one for a refusal).
    creates : tuple of str
        Paths (relative to the case folder) the command is documented to create.
    check : callable, optional
        ``check(case_folder)`` for more assertions on a documented success.
    timeout : float
        Seconds before the command counts as hanging (subprocess rows).
    readonly : bool
        The row needs ``ro/`` unwritable (skipped where that cannot be arranged).
    process : bool
        Run as a real, memory-limited subprocess (a huge request) instead of in-process.
    """

    id: str
    args: list[str]
    code: int = 2
    err: str = ""
    lines: int = 1
    creates: tuple[str, ...] = ()
    check: object = None
    timeout: float = 60.0
    readonly: bool = False
    process: bool = False


def _jpeg(d: Path) -> None:
    assert (d / "r.jpg").read_bytes()[:3] == b"\xff\xd8\xff"


def unreadable_mesh_cases() -> list[Case]:
    """Every mesh-reading command × every kind of unreadable mesh: one line naming what is wrong with the file."""
    files = {
        "truncated": ("trunc.stl", r"truncated binary STL"),
        "random-bytes": ("rand.stl", r"not an STL file \(neither ASCII STL nor a binary STL"),
        "facet-count-ffffffff": ("ffff.stl", r"header announces 4294967295 facets"),
        "png-renamed": ("png.stl", r"not an STL file \(it is a PNG image\)"),
        "empty-zip-3mf": ("empty.3mf", r"not a 3MF file"),
        "nan-coordinates": ("nan.stl", r"non-finite"),
        "empty-file": ("empty.stl", r"empty file"),
    }
    commands = {
        "render": lambda f: ["render", f, "-o", "r.png"],
        "analyse": lambda f: ["analyse", f],
        "check": lambda f: ["check", f],
        "tray": lambda f: ["tray", f, "--out", "t.3mf", "--workers", "1"],
    }
    return [Case(f"{c}-{k}", make("{in}/" + name), err=re.escape(name) + ": .*" + msg)
            for c, make in commands.items() for k, (name, msg) in files.items()]


def writing_cases() -> list[Case]:
    """Every command that writes: read-only folder, below a file, empty path, existing output."""
    small_cal = ["calibrate", "dpa", "--primaries", "3", "--exponents", "1,2", "--repeats", "1", "--workers", "1"]
    commands = {  # name: (args without the output, output option, output kind, existing output)
        "generate": (["generate", "fso", "--subdivisions", "2"], "--out", "dir", "done"),
        "render": (["render", "{in}/grain.stl"], "-o", "png", "exists.png"),
        "fourier": (["fourier", "{in}/grain.png"], "--csv", "csv", "exists.csv"),
        "calibrate": (small_cal, "--out", "dir", "done"),
        "analyse": (["analyse", "{in}/grain.stl", "--no-fractal", "--no-fourier"], "--csv", "csv", "exists.csv"),
        "plot": (["plot", "zingg", "{in}/grains/manifest.csv"], "-o", "png", "exists.png"),
        "figures": (["figures", "--only", "2"], "--out", "dir", "done"),
        "tray": (["tray", "--method", "fso", "--count", "2", "--size", "5", "--workers", "1"], "--out", "3mf",
                 "exists.3mf"),
        "batch": (["batch", "{in}/good.toml", "--workers", "1"], "--out", "dir", "done"),
        "dem": (["dem", "{in}/grains", "--workers", "1"], "--out", "dir", None),
        "fit": (["fit", "{in}/text.csv", "--workers", "1"], "--out", "dir", None),
        "demo": (["demo", "--quick"], "--out", "dir", None),
        "generate-angular": (["generate", "angular"], "--out", "dir", None),
        "generate-rf": (["generate", "rf"], "--out", "dir", None),
    }
    name = {"dir": "out", "png": "o.png", "csv": "o.csv", "3mf": "t.3mf"}
    cases = []
    for cmd, (args, opt, kind, existing) in commands.items():
        target = name[kind]
        cases += [
            Case(f"{cmd}-readonly-folder", args + [opt, f"ro/{target}"], err=r"cannot write into .*ro",
                 readonly=True),
            Case(f"{cmd}-below-a-file", args + [opt, f"afile/{target}"], err=r"afile is a file, not a folder"),
            Case(f"{cmd}-empty-path", args + [opt, ""], err=r"path is empty"),
        ]
        if existing:
            cases.append(Case(f"{cmd}-existing-output", args + [opt, existing], err=r"exists.*; use (--resume or )?--overwrite"))
        if kind == "dir":
            cases.append(Case(f"{cmd}-out-is-a-file", args + [opt, "afile"], err=r"afile'? is a file"))
    return cases


CASES: list[Case] = [
    *writing_cases(),
    *unreadable_mesh_cases(),
    # §1: an unreadable printer file
    Case("check-printer-is-a-folder", ["check", "{in}/grain.stl", "--printer", "{in}/folder.toml"],
         err=r"folder\.toml"),
    Case("check-printer-garbage", ["check", "{in}/grain.stl", "--printer", "{in}/garbage.toml"],
         err=r"garbage\.toml"),
    # §1: generate --out below an existing file
    Case("generate-out-below-stl", ["generate", "fso", "--out", "{in}/grain.stl/sub"], err=r"is a file, not a folder"),
    # §1: MemoryError / huge values
    Case("render-columns-1e9", ["render", "{in}/grain.stl", "-o", "r.png", "--columns", "1000000000"],
         code=0, err=r"wrote r\.png", creates=("r.png",), process=True),
    Case("calibrate-exponents-1e9", ["calibrate", "dpa", "--exponents", "1:1000000000:1", "--out", "cal"],
         err=r"--exponents.*1000", process=True),
    Case("tray-count-1e9", ["tray", "--method", "fso", "--count", "1000000000", "--size", "0.5", "--out", "t.3mf"],
         err=r"would (take|need) .*--count", process=True),
    Case("batch-size-mm-1e300", ["batch", "{in}/huge_size.toml", "--out", "b"], err=r"size\.mm: must be in", process=True),
    Case("batch-median-1e300", ["batch", "{in}/huge_median.toml", "--out", "b"], err=r"median_mm", process=True),
    # §2: exit 0 on bad input
    Case("render-nan", ["render", "{in}/nan.stl", "-o", "r.png"], err=r"non-finite"),
    *[Case(f"plot-{kind}-text-columns", ["plot", kind, "{in}/text.csv", "-o", "p.png"], err=r"holds no numbers")
      for kind in ("zingg", "sphericity-convexity", "size-distribution")],
    Case("analyse-primary-volume-inf", ["analyse", "{in}/grain.stl", "--primary-volume", "inf"],
         err=r"--primary-volume.*finite"),
    *[Case(f"fourier-threshold-{v}", ["fourier", "{in}/grain.png", "--threshold", v], err=r"--threshold.*finite")
      for v in ("nan", "inf", "-inf")],
    # §3: huge requests refused up front with the estimate and the option that reduces it
    Case("generate-fso-count-1e9", ["generate", "fso", "--count", "1000000000", "--out", "g"],
         err=r"would take .*--count", process=True),
    Case("generate-cri-count-1e9", ["generate", "cri", "--count", "1000000000", "--out", "g"],
         err=r"would take .*--count", process=True),
    Case("batch-count-2**63-1", ["batch", "{in}/huge_count.toml", "--out", "b"], err=r"would take .*count", process=True),
    Case("fourier-rays-1e8", ["fourier", "{in}/grain.png", "--rays", "100000000"], err=r"GiB.*--rays|--rays.*GiB", process=True),
    Case("calibrate-repeats-1e9", ["calibrate", "dpa", "--primaries", "100000", "--repeats", "1000000000",
                                   "--out", "cal"], err=r"would take .*--repeats", process=True),
    Case("fso-subdivisions-8-400-terms", ["generate", "fso", "--subdivisions", "8", "--ridges", "400",
                                          "--frequencies", "400", "--gamma", "1.05", "--count", "1000", "--out", "g"],
         err=r"would take .*--(subdivisions|count)", process=True),
    Case("tray-max-triangles-1e12", ["tray", "--method", "fso", "--count", "100000", "--max-triangles",
                                     "1000000000000", "--max-subdivisions", "7", "--out", "t.3mf"],
         err=r"would take .*--count", timeout=240, process=True),  # resolution matching's pilot grains come first
    # §4: a batch whose parameter draws reach invalid values is refused before any work
    Case("batch-amplitude-support", ["batch", "{in}/bad_amplitude.toml", "--out", "b", "--workers", "1"],
         err=r"amplitude"),
    # §5: one overwrite rule; real JPEG
    Case("render-jpeg", ["render", "{in}/grain.stl", "-o", "r.jpg"], code=0, err=r"wrote r\.jpg",
         creates=("r.jpg",), check=_jpeg),
    Case("render-gif-refused", ["render", "{in}/grain.stl", "-o", "r.gif"], err=r"must end in \.png"),
    # §6: folders as inputs; fourier goes on past a bad image
    Case("analyse-folder", ["analyse", "{in}/grains", "--no-fractal", "--no-fourier", "--workers", "2"], code=0,
         lines=0),
    Case("check-folder", ["check", "{in}/grains", "--printer", "generic-sla"], code=0, err=r"2 part\(s\)"),
    Case("fourier-skips-white", ["fourier", "{in}/grain.png", "{in}/white.png", "{in}/grain.png"], code=1, lines=3,
         err=r"skipped .*white\.png(.|\n)*skipped 1 of 3 image\(s\): .*white\.png"),
    # §7: 3D images (scan, and analyse of an image, which is the scan): one line, nothing written
    *[Case(f"{cmd}-{name}", [cmd, f"{{in}}/{name}.npy", "--voxel-size-um", "10", "--atlas-csv", "s.csv"], err=err)
      for cmd in ("scan", "analyse")
      for name, err in (("flat", r"not a 3D image"), ("float", r"float32 image cannot hold labels"),
                        ("void", r"no grain: every voxel is 0"), ("one-label", r"every voxel is label 1"))],
    # a scan cut short (a copy that stopped): one line naming the file, not tifffile's log lines and mmap's error
    *[Case(f"{cmd}-truncated-{kind}", [cmd, f"{{in}}/{arg}", "--voxel-size-um", "10", "--atlas-csv", "s.csv"],
           err=re.escape(named) + r": truncated (TIFF image|\.npy array): .* but the file has \d+ bytes")
      for cmd in ("scan", "analyse")
      for kind, arg, named in (("tiff", "trunc.tif", "trunc.tif"), ("tiff-header", "trunc-head.tif", "trunc-head.tif"),
                               ("npy", "trunc.npy", "trunc.npy"), ("slice", "trunc-slices", "trunc-slices/s2.tif"))],
    Case("scan-truncated-compressed-tiff", ["scan", "{in}/trunc-zip.tif", "--voxel-size-um", "10"],
         err=r"trunc-zip\.tif: truncated or damaged TIFF image \(\d+ bytes; tifffile: .*\); copy the file again"),
    Case("scan-raw-size", ["scan", "{in}/labels.raw", "--raw-shape", "12", "12", "13", "--raw-dtype", "uint16",
                           "--voxel-size-um", "10", "--atlas-csv", "s.csv"], err=r"needs \d+ bytes: check --raw-shape"),
    *[Case(f"scan-voxel-size-{v}", ["scan", "{in}/labels.npy", "--voxel-size-um", v, "--atlas-csv", "s.csv"],
           err=r"--voxel-size-um") for v in ("0", "-1", "nan", "inf")],
    Case("scan-no-voxel-size", ["scan", "{in}/labels.npy", "--atlas-csv", "s.csv"], err=r"give --voxel-size-um"),
    # one voxel size, in µm or mm, for meshes and images alike (--voxel-size-um and --voxel-size-mm everywhere)
    *[Case(f"{cmd}-voxel-size-both", [cmd, f"{{in}}/{name}", "--voxel-size-um", "10", "--voxel-size-mm", "0.01"],
           err=r"give --voxel-size-um or --voxel-size-mm, not both")
      for cmd, name in (("analyse", "grain.stl"), ("analyse", "labels.npy"), ("scan", "labels.npy"))],
    *[Case(f"analyse-mesh-{flag}-too-coarse", ["analyse", "{in}/grain.stl", flag, v],
           err=re.escape(flag) + r": .*grain\.stl: .* voxels across .*; measure at a voxel size of at most [0-9.]+ mm")
      for flag, v in (("--voxel-size-um", "100000"), ("--voxel-size-mm", "100"))],
    Case("scan-voxel-size-mm-1e308", ["scan", "{in}/labels.npy", "--voxel-size-mm", "1e308"],
         err=r"'--voxel-size-mm': 1e\+308 mm is inf µm, not a usable voxel size"),
    Case("scan-missing", ["scan", "{in}/nothere.npy", "--voxel-size-um", "10", "--atlas-csv", "s.csv"],
         err=r"no such file"),
    Case("scan-unwritable", ["scan", "{in}/labels.npy", "--voxel-size-um", "10", "--atlas-csv", "ro/s.csv"],
         err=r"--atlas-csv: cannot write", readonly=True),
    # --segment on an image already labelled: refused (its labels would be lost) unless --ignore-labels
    *[Case(f"{cmd}-segment-labelled", [cmd, "{in}/labels.npy", "--segment", "--voxel-size-um", "10", "--atlas-csv",
                                       "s.csv"],
           err=r"labels\.npy: already labelled \(2 labels, 1–2\): --segment takes a binary image .*drop --segment "
               r".* --ignore-labels") for cmd in ("scan", "analyse")],
    Case("scan-ignore-labels-without-segment", ["scan", "{in}/labels.npy", "--ignore-labels", "--voxel-size-um", "10"],
         err=r"--ignore-labels needs --segment"),
    Case("scan-segment-ignore-labels", ["scan", "{in}/labels.npy", "--segment", "--ignore-labels", "--voxel-size-um",
                                        "10", "--atlas-csv", "s.csv"], code=0, lines=3,
         err=r"segmented: 2 grain\(s\)(.|\n)*2 grain\(s\) measured of 2 label\(s\)", creates=("s.csv",)),
    Case("scan-segment-binary-255", ["scan", "{in}/binary-255.npy", "--segment", "--voxel-size-um", "10"], code=0,
         lines=2, err=r"segmented: 2 grain\(s\)(.|\n)*2 grain\(s\) measured of 2 label\(s\)"),
    Case("scan-labels", ["scan", "{in}/labels.npy", "--voxel-size-um", "10", "--atlas-csv", "s.csv"], code=0,
         lines=2, err=r"2 grain\(s\) measured of 2 label\(s\)\n.*wrote 2 grain\(s\) to s\.csv", creates=("s.csv",)),
    # simulate calibrate triaxial: the target, the triaxial settings (simulate triaxial's checks), other tests'
    # options; all before any engine starts
    *[Case(f"calibrate-triaxial-{name}", ["simulate", "calibrate", "triaxial", "{in}/grains", "--out", "cal",
                                          *args], err=err)
      for name, args, err in (
          ("target-0", ["--target-angle", "0"], r"--target-angle: target angle 0° is outside 5–80°"),
          ("target-90", ["--target-angle", "90"], r"--target-angle: target angle 90° is outside 5–80°"),
          ("target-nan", ["--target-angle", "nan"], r"--target-angle.*finite"),
          ("confining-0", ["--target-angle", "30", "--confining-kpa", "0"], r"'--confining-kpa': must be in"),
          ("axial-strain-1", ["--target-angle", "30", "--axial-strain", "1"], r"'--axial-strain': must be in"),
          ("packing-medium", ["--target-angle", "30", "--packing", "medium"], r"'medium' is not one of"),
          ("inertial-0.5", ["--target-angle", "30", "--inertial-number", "0.5"], r"'--inertial-number'"),
          ("grains-30", ["--target-angle", "30", "--grains", "30", "--quick"], r"needs --grains ≥ 79"),
          ("mpi-with-yade", ["--target-angle", "30", "--mpi", "2"], r"--mpi: yade runs one process per seed"),
          ("levelset", ["--target-angle", "30", "--shape", "levelset"],
           r"--shape levelset: simulate triaxial's yade scene takes --shape clump only"),
          ("angle-mid", ["--target-angle", "30", "--angle", "mid"], r"'mid' is not one of 'ultimate', 'peak'"),
          ("tilt-step", ["--target-angle", "30", "--tilt-step", "1"],
           r"--tilt-step and --tilt-start are the tilt test's: calibrate triaxial takes neither"),
          ("huge", ["--target-angle", "30", "--grains", "2000", "--seeds", "20", "--max-frictions", "30"],
           r"a calibration of up to 30 frictions .* would take about .*; lower --max-frictions"),
      )],
    Case("calibrate-tilt-packing", ["simulate", "calibrate", "tilt", "{in}/grains", "--out", "cal", "--target-angle",
                                    "30", "--packing", "loose"], err=r"are the triaxial test's: calibrate tilt takes"),
    Case("calibrate-repose-angle", ["simulate", "calibrate", "repose", "{in}/grains", "--out", "cal",
                                    "--target-angle", "30", "--angle", "peak"],
         err=r"--angle are the triaxial test's: calibrate repose takes none of them"),
]


# --------------------------------------------------------------------------- inputs

def _binary_stl(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    tri = vertices[faces].astype("<f4")
    rec = np.zeros(len(faces), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tri
    return b"x" * 80 + struct.pack("<I", len(faces)) + rec.tobytes()


def _recipe(extra: str = "", count: int = 2, size: str = "mm = 1.0") -> str:
    return (f'method = "fso"\ncount = {count}\nseed = 1\n[params]\nsubdivisions = 2\n{extra}\n'
            f"[size]\n{size}\n")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """The shared inputs every case may read (made once, never written by a case)."""
    import zipfile

    from PIL import Image

    import grainforge
    from grainforge.io import write_mesh
    from grainforge.population.generate import write_run

    d = tmp_path_factory.mktemp("inputs")
    g = grainforge.fso(subdivisions=2, rng=0)
    write_mesh(g, d / "grain.stl")
    write_run("fso", grainforge.methods.get("fso").Params(subdivisions=2), seeds=[0, 1], out=d / "grains", size=5.0)
    data = (d / "grain.stl").read_bytes()
    (d / "trunc.stl").write_bytes(data[: len(data) // 2])
    (d / "rand.stl").write_bytes(np.random.default_rng(0).bytes(3000))
    (d / "ffff.stl").write_bytes(data[:80] + struct.pack("<I", 0xFFFFFFFF) + data[84:])
    (d / "empty.stl").write_bytes(b"")
    v = np.asarray(g.vertices, dtype=np.float64).copy()
    v[0] = np.nan
    (d / "nan.stl").write_bytes(_binary_stl(v, np.asarray(g.faces)))
    zipfile.ZipFile(d / "empty.3mf", "w").close()
    from grainforge.outline.contours import Contour
    from grainforge.outline.imaging import draw_contours

    img = draw_contours((160, 160), [(Contour.from_descriptors("rough-sphere", rng=0), (80, 80), 50.0)])
    Image.fromarray(img).save(d / "grain.png")
    Image.fromarray(np.full((64, 64), 255, np.uint8)).save(d / "white.png")
    (d / "png.stl").write_bytes((d / "grain.png").read_bytes())
    (d / "text.csv").write_text("file,L,I,S,sphericity,convexity,equivalent_diameter,volume\n"
                                "a,x,y,z,high,low,big,much\nb,x,y,z,high,low,big,much\n")
    (d / "folder.toml").mkdir()
    (d / "garbage.toml").write_bytes(b"\xff\xfe\x00garbage = = [\n")
    (d / "good.toml").write_text(_recipe())
    (d / "huge_size.toml").write_text(_recipe(size="mm = 1e300"))
    (d / "huge_median.toml").write_text(_recipe(size='distribution = "lognormal"\nmedian_mm = 1e300\nsigma = 0.3'))
    (d / "huge_count.toml").write_text(_recipe(count=2**63 - 1))
    (d / "bad_amplitude.toml").write_text(  # 0.45 is valid for some grains, not for grain 1
        _recipe('amplitude = { distribution = "uniform", low = 0.2, high = 0.45 }', count=4))
    z, y, x = np.indices((12, 12, 24))
    labels = np.zeros(z.shape, np.uint16)  # two balls, labels 1 and 2, clear of the faces
    for k, cx in ((1, 6), (2, 17)):
        labels[((z - 6) ** 2 + (y - 6) ** 2 + (x - cx) ** 2) < 16] = k
    np.save(d / "labels.npy", labels)
    labels.tofile(d / "labels.raw")
    np.save(d / "flat.npy", labels[6])
    np.save(d / "float.npy", labels.astype(np.float32))
    np.save(d / "void.npy", np.zeros_like(labels))
    np.save(d / "one-label.npy", np.ones_like(labels))
    np.save(d / "binary-255.npy", np.where(labels > 0, 255, 0).astype(np.uint8))  # binary: one non-zero value
    _truncated_images(d, labels)
    return d


def _truncated_images(d: Path, labels: np.ndarray) -> None:
    """Real TIFF and .npy files of ``labels``, then cut short as an interrupted copy leaves them."""
    import tifffile

    def cut(name: str, keep) -> None:
        data = (d / name).read_bytes()
        (d / name).write_bytes(data[: keep(len(data))])

    tifffile.imwrite(d / "trunc.tif", labels)  # uncompressed, memory-mapped: its pixel data cut
    cut("trunc.tif", lambda n: n // 2)
    tifffile.imwrite(d / "trunc-head.tif", labels)  # its first page's tags cut too
    cut("trunc-head.tif", lambda n: 200)
    tifffile.imwrite(d / "trunc-zip.tif", labels, compression="zlib")  # page by page: the page chain cut
    cut("trunc-zip.tif", lambda n: 2 * n // 3)
    np.save(d / "trunc.npy", labels)
    cut("trunc.npy", lambda n: n // 2)
    (d / "trunc-slices").mkdir()
    for z in range(len(labels)):
        tifffile.imwrite(d / "trunc-slices" / f"s{z}.tif", labels[z])
    cut("trunc-slices/s2.tif", lambda n: n // 2)


# --------------------------------------------------------------------------- the harness

def _snapshot(*folders: Path) -> set[str]:
    out = set()
    for f in folders:
        for p in f.rglob("*"):
            out.add(str(p))
    return out


def _limit_memory():
    """``preexec_fn`` of every command: the memory limit, and SIGINT handled by default as in a foreground
    job of an interactive shell. (A parent that ignores SIGINT, e.g. a test run started in the background
    by a non-interactive shell, passes that on; Python and grainforge then keep ignoring it, by the POSIX
    convention for background jobs, and a Ctrl-C test would wait for the whole job.)"""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    signal.signal(signal.SIGINT, signal.SIG_DFL)


#: sessions started by the current test (cleaned up after it, whatever happened)
_SESSIONS: list[subprocess.Popen] = []


def start(args: list[str], cwd: Path, inputs: Path) -> subprocess.Popen:
    """``grainforge ARGS`` in ``cwd``, in its own session, memory limited, stderr captured."""
    argv = CLI + [a.replace("{in}", str(inputs)) for a in args]
    env = dict(os.environ, COLUMNS="200")
    proc = subprocess.Popen(argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, start_new_session=True, preexec_fn=_limit_memory, env=env)
    _SESSIONS.append(proc)
    return proc


@pytest.fixture(autouse=True)
def _no_strays():
    """After each test, even a failed one: kill whatever its commands left running (a failing case must not
    leave processes on the machine)."""
    yield
    kill_sessions(_SESSIONS)


def assert_no_processes_left(sid: int, grace: float = 5.0) -> None:
    """No process of session ``sid`` may outlive the command (``grace`` seconds to exit)."""
    deadline = time.monotonic() + grace
    while (left := session_processes(sid)) and time.monotonic() < deadline:
        time.sleep(0.1)
    for pid in left:  # clean up before failing
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert not left, f"processes left behind: {left}"


def _readonly(folder: Path) -> bool:
    """Make ``folder`` unwritable (immutable as root, mode 555 otherwise); False if impossible."""
    if os.geteuid() == 0:
        if shutil.which("chattr") is None:
            return False
        ok = subprocess.run(["chattr", "+i", str(folder)], capture_output=True).returncode == 0
    else:
        folder.chmod(0o555)
        ok = True
    try:
        (folder / ".probe").touch()
    except OSError:
        return ok
    (folder / ".probe").unlink()
    return False


def _writable(folder: Path) -> None:
    if os.geteuid() == 0:
        subprocess.run(["chattr", "-i", str(folder)], capture_output=True)
    else:
        folder.chmod(0o755)


@pytest.fixture
def case_dir(tmp_path):
    """The folder a case runs in: ro/ (unwritable), afile, exists.png, exists.csv, exists.3mf, done/."""
    (tmp_path / "ro").mkdir()
    (tmp_path / "afile").write_text("a file\n")
    (tmp_path / "exists.png").write_bytes(b"old")
    (tmp_path / "exists.csv").write_text("old\n")
    (tmp_path / "exists.3mf").write_bytes(b"old")
    (tmp_path / "done").mkdir()  # a folder holding one output of each folder-writing command
    for name in ("fso-0000.stl", "calibration.csv", "figure2-fso-dimension.png"):
        (tmp_path / "done" / name).write_bytes(b"old")
    readonly = _readonly(tmp_path / "ro")
    yield tmp_path, readonly
    _writable(tmp_path / "ro")


def run_process(case: Case, d: Path, inputs: Path) -> tuple[int, str]:
    """``case`` as a real, memory-limited subprocess in ``d``: its exit code and stderr."""
    proc = start(case.args, d, inputs)
    try:
        _, err = proc.communicate(timeout=case.timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"grainforge {' '.join(case.args)} still ran after {case.timeout} s")
    assert_no_processes_left(proc.pid)
    return proc.returncode, err.decode("utf-8", "replace")


def _pool_processes() -> list[int]:
    """Descendants of this process, less multiprocessing's per-interpreter helpers themselves (the workers
    a fork server forks are its children, and counted)."""
    helpers = (b"multiprocessing.forkserver", b"multiprocessing.resource_tracker")
    out = []
    for pid in child_processes(os.getpid()):
        try:
            helper = (Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1] == str(os.getpid())
                      and any(h in Path(f"/proc/{pid}/cmdline").read_bytes() for h in helpers))
        except (OSError, IndexError):
            continue
        if not helper:
            out.append(pid)
    return out


def run_in_process(case: Case, d: Path, inputs: Path) -> tuple[int, str]:
    """``case`` in this process (click's ``CliRunner``, working directory ``d``): its exit code and stderr.

    An exception that escapes ``cli.main`` (a traceback in a real process) fails the test; so does a child
    process (a pool worker) still alive 5 s after the command returned.  The fork server and resource
    tracker that multiprocessing keeps for the life of the interpreter are not counted here: a real process
    takes them with it, which the subprocess rows and the signal tests check."""
    from click.testing import CliRunner

    from grainforge.cli.main import cli

    before = set(_pool_processes())
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(d)
        mp.setenv("COLUMNS", "200")
        r = CliRunner().invoke(cli, [a.replace("{in}", str(inputs)) for a in case.args], prog_name="grainforge")
    assert r.exception is None or isinstance(r.exception, SystemExit), (
        f"grainforge {' '.join(case.args)} raised {r.exception!r}; stderr:\n{r.stderr}")
    deadline = time.monotonic() + 5.0
    while (left := set(_pool_processes()) - before) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not left, f"processes left behind: {left}"
    return r.exit_code, r.stderr


def run_case(case: Case, d: Path, inputs: Path) -> tuple[int, str]:
    return run_process(case, d, inputs) if case.process else run_in_process(case, d, inputs)


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id, marks=[pytest.mark.slow] if c.process else [])
                                  for c in CASES])
def test_cli_contract(case: Case, case_dir, inputs):
    d, readonly = case_dir
    if case.readonly and not readonly:
        pytest.skip("cannot make a folder unwritable here (needs chattr as root)")
    before = _snapshot(d, inputs)
    code, err = run_case(case, d, inputs)
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == case.lines, f"expected {case.lines} line(s) on stderr, got:\n{err}"
    assert code == case.code, f"exit {code} (expected {case.code}); stderr:\n{err}"
    if case.err:
        assert re.search(case.err, err), f"stderr does not match {case.err!r}:\n{err}"
    after = _snapshot(d, inputs)
    expected = before | {str(d / c) for c in case.creates}
    assert after == expected, f"new: {sorted(after - expected)}; gone: {sorted(expected - after)}"
    if case.check is not None:
        case.check(d)


# --------------------------------------------------------------------------- sequences

def test_generate_overwrite_removes_the_earlier_runs_files(case_dir, inputs):
    """§5: a shorter run with --overwrite leaves only the files its own manifest lists."""
    d, _ = case_dir
    base = ["generate", "fso", "--subdivisions", "2", "--out", "g"]
    assert run_case(Case("first", base + ["--count", "4"]), d, inputs)[0] == 0
    code, err = run_case(Case("second", base + ["--count", "2"]), d, inputs)
    assert code == 2 and "--overwrite" in err and len(err.strip().splitlines()) == 1
    code, err = run_case(Case("third", base + ["--count", "2", "--overwrite"]), d, inputs)
    assert code == 0, err
    assert sorted(p.name for p in (d / "g").iterdir()) == ["fso-0000.stl", "fso-0001.stl", "manifest.csv"]


def test_failed_batch_does_not_block_the_fixed_rerun(case_dir, inputs):
    """§4: a batch refused for its recipe leaves nothing; the corrected recipe then runs without --resume."""
    d, _ = case_dir
    code, err = run_case(Case("bad", ["batch", "{in}/bad_amplitude.toml", "--out", "b", "--workers", "1"]), d, inputs)
    assert code == 2 and "amplitude" in err and not (d / "b").exists(), err
    code, err = run_case(Case("fixed", ["batch", "{in}/good.toml", "--out", "b", "--workers", "1"]), d, inputs)
    assert code == 0, err
    assert (d / "b" / "manifest.csv").is_file()


# --------------------------------------------------------------------------- one voxel size option, two units

@pytest.mark.parametrize("kind", ["mesh", "image"])
def test_the_voxel_size_in_um_or_mm_gives_the_same_table(kind, case_dir, inputs):
    """``analyse`` of a mesh (mm) and of an image (µm, which ``scan`` measures) take the voxel size as
    ``--voxel-size-um`` or ``--voxel-size-mm``: the same voxel size in either unit writes the same table, byte for
    byte (the README's ``analyse --voxel-size-mm`` and ``fit --voxel-size-um 7.3`` keep their spelling)."""
    d, _ = case_dir
    source = "{in}/grain.stl" if kind == "mesh" else "{in}/labels.npy"
    extra = ["--no-fractal", "--no-fourier", "--workers", "1"] if kind == "mesh" else ["--workers", "1"]
    tables = []
    for flag, value in (("--voxel-size-um", "50"), ("--voxel-size-mm", "0.05")):
        out = f"{flag.rsplit('-', 1)[1]}.csv"
        code, err = run_case(Case(flag, ["analyse", source, flag, value, "--atlas-csv", out, *extra]), d, inputs)
        assert code == 0 and "Traceback" not in err, err
        tables.append((d / out).read_bytes())
    assert tables[0] == tables[1]
    assert b"50" in tables[0].splitlines()[1]  # the table's voxel size column, in µm


# --------------------------------------------------------------------------- a Dask scheduler nothing answers at

def _closed_port() -> int:
    """A local port nothing listens on (bound, then released)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


SCHEDULER_COMMANDS = {
    "batch": ["batch", "{in}/good.toml", "--out", "b"],
    "analyse": ["analyse", "{in}/grains", "--csv", "a.csv"],
    "fit": ["fit", str(Path(__file__).resolve().parents[1] / "data" / "synthetic-rf-sand.csv"), "--out", "f"],
    "simulate": ["simulate", "repose", "{in}/grains", "--out", "s"],
    "simulate-calibrate": ["simulate", "calibrate", "tilt", "{in}/grains", "--target-angle", "30", "--out", "c"],
}


@pytest.mark.slow
@pytest.mark.parametrize("command", sorted(SCHEDULER_COMMANDS))
def test_a_refused_scheduler_connection_is_one_line_at_once(command, case_dir, inputs):
    """``--scheduler tcp://127.0.0.1:PORT`` where nothing listens: the refusal is seen at once (not after Dask's 20 s
    of retries), one line naming the address, exit 2, nothing written.  The real CLI with its default timeout; the
    bound is generous (the command's imports take a few seconds on a loaded machine)."""
    d, _ = case_dir
    before = _snapshot(d, inputs)
    address = f"tcp://127.0.0.1:{_closed_port()}"
    t0 = time.monotonic()
    code, err = run_process(Case(command, [*SCHEDULER_COMMANDS[command], "--scheduler", address], timeout=60), d,
                            inputs)
    took = time.monotonic() - t0
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"cannot connect to the Dask scheduler at {address}: connection refused" in err, err
    assert took < 10, f"the refusal took {took:.1f} s"
    assert _snapshot(d, inputs) == before


# --------------------------------------------------------------------------- interrupts

def _wait_for(predicate, timeout: float, proc: subprocess.Popen) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if proc.poll() is not None:
            pytest.fail(f"the command ended before the signal: {proc.communicate()[1].decode()}")
        if time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            pytest.fail("the command never reached the point to interrupt")
        time.sleep(0.05)


def _has(d: Path, pattern: str):
    return lambda: any(d.glob(pattern))


@pytest.mark.slow
def test_sigterm_on_generate_leaves_no_staging_folder(case_dir, inputs):
    d, _ = case_dir
    before = _snapshot(d)
    proc = start(["generate", "fso", "--count", "2000", "--subdivisions", "3", "--out", "g"], d, inputs)
    _wait_for(_has(d, "g/.grainforge-staging-*/*.stl"), 60, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=20)
    err = err.decode()
    assert proc.returncode == 128 + signal.SIGTERM and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and "Terminated" in err, err
    assert_no_processes_left(proc.pid)
    assert _snapshot(d) == before


TRAY = ["tray", "--method", "fso", "--param", "subdivisions=3", "--count", "30000", "--size", "5",
        "--workers", "2", "--out", "t.3mf"]


@pytest.mark.slow
def test_sigkill_on_tray_leaves_no_process_and_the_next_run_cleans_up(case_dir, inputs):
    d, _ = case_dir
    before = _snapshot(d)
    proc = start(TRAY, d, inputs)
    _wait_for(_has(d, ".t.3mf.*.tmp"), 90, proc)
    time.sleep(0.5)
    proc.kill()
    proc.communicate(timeout=20)
    assert_no_processes_left(proc.pid)  # the pool's workers notice their owner died
    code, err = run_case(Case("rerun", TRAY[:-6] + ["--count", "2", "--workers", "1", "--out", "t.3mf"]), d, inputs)
    assert code == 0, err
    assert _snapshot(d) == before | {str(d / n) for n in ("t.3mf", "t.csv", "t-plate1.png")}


def _forkserver_started(sid: int):
    def started():
        for pid in session_processes(sid):
            try:
                if b"multiprocessing.forkserver" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    return True
            except OSError:
                pass
        return False
    return started


@pytest.mark.slow
@pytest.mark.parametrize("phase", ["starting", "pool-starting", "writing"])
def test_ctrl_c_on_tray_is_quick_and_leaves_nothing(case_dir, inputs, phase):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) 0.3 s after the start (the
    command line loading its modules), while the worker pool starts (its fork server importing), and
    while grains are written: exit 130, one line, nothing left.

    30,000 grains take minutes even on an idle machine, so the job cannot finish before the signal."""
    d, _ = case_dir
    before = _snapshot(d)
    proc = start(["tray", "--method", "fso", "--param", "subdivisions=3", "--count", "30000", "--size", "5",
                  "--workers", "2", "--out", "sub/t.3mf"], d, inputs)
    if phase == "starting":
        time.sleep(0.3)
    else:
        _wait_for(_forkserver_started(proc.pid) if phase == "pool-starting" else _has(d, "sub/.t.3mf.*.tmp"),
                  90, proc)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)  # a hang guard, not a timing assertion (see docs/benchmarks.md)
    err = err.decode()
    assert proc.returncode == 130 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert_no_processes_left(proc.pid)
    assert _snapshot(d) == before
