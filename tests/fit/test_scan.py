"""`grainforge scan`: a μCT image's grains measured against the same grains measured by `atlas_descriptors`.

The scene: ellipsoids and generated CRI grains, each voxelised the way `atlas_descriptors` voxelises it
(`voxel_image` at the same voxel size), placed in one labelled volume at whole-voxel offsets, in contact along a
row; two more touch the image's faces; two labels of a few voxels.  A grain cut out of the volume is then the very
image `atlas_descriptors` measures, so its descriptors must agree to rounding.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

import grainforge
from grainforge.analysis.atlas import atlas_descriptors, voxel_image
from grainforge.analysis.scan import compare_labels, label_boxes, measure_labels, segment
from grainforge.cli.main import cli
from grainforge.fit import DESCRIPTORS, read_sand
from grainforge.geometry.solid import signed_volume, solid_problems
from grainforge.io import read_mesh
from grainforge.io.volume import Volume, open_volume

H = 0.05  # voxel edge, mesh units (grains ~1 across: ~20 voxels across)
H_UM = 10.0  # the scan's voxel size in µm


def _ellipsoid(axes, seed):
    m = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    m.apply_scale(axes)
    from grainforge.geometry.rotations import random_rotation

    R = random_rotation(seed)
    m.vertices = m.vertices @ R.T
    return m


def _tight(mask):
    idx = np.argwhere(mask)
    lo, hi = idx.min(0), idx.max(0) + 1
    return mask[tuple(slice(a, b) for a, b in zip(lo, hi))]


def _place(vol, mask, pos, label):
    sl = tuple(slice(p, p + s) for p, s in zip(pos, mask.shape))
    assert not (vol[sl][mask] > 0).any()
    vol[sl][mask] = label


def _overlaps(vol, mask, pos):
    if min(pos) < 0 or any(p + s > n for p, s, n in zip(pos, mask.shape, vol.shape)):
        return True
    sl = tuple(slice(p, p + s) for p, s in zip(pos, mask.shape))
    return bool((vol[sl][mask] > 0).any())


@pytest.fixture(scope="module")
def scene():
    """(labels, truth {label: atlas_descriptors}, interior labels, border labels, small labels)."""
    meshes = [_ellipsoid((0.55, 0.45, 0.35), 1), _ellipsoid((0.6, 0.4, 0.4), 2), _ellipsoid((0.5, 0.5, 0.3), 3),
              _ellipsoid((0.45, 0.4, 0.38), 4)]
    for seed in (5, 6):
        g = grainforge.cri(rng=seed)
        meshes.append(trimesh.Trimesh(g.vertices * 0.5, g.faces, process=False))
    border_meshes = [_ellipsoid((0.5, 0.4, 0.35), 7), _ellipsoid((0.45, 0.45, 0.35), 8)]
    masks = [_tight(voxel_image(m, voxel_size=H)[0]) for m in meshes + border_meshes]
    vol = np.zeros((34, 34, 150), np.uint16)
    truth, interior, border = {}, [], []
    x = 3
    for k, (m, mask) in enumerate(zip(meshes, masks[: len(meshes)]), start=1):
        pos = [3 + (26 - mask.shape[0]) // 2, 3 + (26 - mask.shape[1]) // 2, x]
        while not _overlaps(vol, mask, [pos[0], pos[1], pos[2] - 1]) and pos[2] > 3:
            pos[2] -= 1  # slide until it touches the previous grain
        _place(vol, mask, pos, k)
        x = pos[2] + mask.shape[2]
        truth[k] = atlas_descriptors(m, voxel_size=H)
        interior.append(k)
    for j, (m, mask) in enumerate(zip(border_meshes, masks[len(meshes):])):
        k = len(meshes) + 1 + j
        pos = [0, 3, x + 2] if j == 0 else [vol.shape[0] - mask.shape[0], 3, x + 4 + masks[-2].shape[2]]
        _place(vol, mask, pos, k)
        truth[k] = atlas_descriptors(m, voxel_size=H)
        border.append(k)
    assert x + 4 + masks[-2].shape[2] + masks[-1].shape[2] < vol.shape[2] - 2
    small = [20, 21]
    vol[15, 31, 140:143] = 20  # 3 voxels
    vol[28:30, 30:32, 145:147] = 21  # 8 voxels
    return vol, truth, interior, border, small


def test_scene_grains_touch(scene):
    vol, _, interior, _, _ = scene
    from scipy import ndimage

    # consecutive interior grains are in contact: one connected binary piece holds them all
    pieces, _ = ndimage.label(np.isin(vol, interior))
    assert len(np.unique(pieces[np.isin(vol, interior)])) == 1


def test_labelled_volume_matches_atlas_descriptors(scene):
    vol, truth, interior, border, small = scene
    v = Volume.from_array(vol)
    boxes = label_boxes(v)
    assert [b.label for b in boxes] == sorted(interior + border + small)
    rows = {r["label"]: r for r in measure_labels(v, boxes, voxel_size=H)}
    assert {k for k, r in rows.items() if r["status"] == "measured"} == set(interior)
    assert {k for k, r in rows.items() if r["status"] == "border"} == set(border)
    assert {k for k, r in rows.items() if r["status"] == "small"} == set(small)
    for k in interior:
        got, want = rows[k], truth[k]
        for name in ("voxels", "volume", "equivalent_diameter", "major", "middle", "minor", *DESCRIPTORS):
            assert got[name] == pytest.approx(want[name], rel=1e-9, abs=1e-12), (k, name)
        # the opening's ball: the voxel image's d_eq here, the mesh's there (within a voxel's rounding)
        assert abs(got["opening_fraction"] - want["opening_fraction"]) < 0.02, k
    # --keep-border measures the border grains as well, as the same grains
    rows = {r["label"]: r for r in measure_labels(v, boxes, voxel_size=H, border=True)}
    for k in border:
        assert rows[k]["border"] and rows[k]["status"] == "measured"
        for name in DESCRIPTORS:
            assert rows[k][name] == pytest.approx(truth[k][name], rel=1e-9), (k, name)


def _run(args, cwd):
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    return result.exit_code, result.output


@pytest.fixture()
def saved(scene, tmp_path):
    vol = scene[0]
    np.save(tmp_path / "labels.npy", vol)
    return tmp_path


def test_cli_table_border_and_small_counts(scene, saved):
    vol, truth, interior, border, small = scene
    code, out = _run(["scan", saved / "labels.npy", "--voxel-size-um", H_UM, "--atlas-csv", saved / "sand.csv"],
                     saved)
    assert code == 0, out
    assert f"{len(interior)} grain(s) measured of {len(interior) + len(border) + len(small)} label(s)" in out
    assert f"{len(border)} touch the image's faces (left out" in out
    assert f"{len(small)} under 66 voxels (left out)" in out
    sand = read_sand(saved / "sand.csv")
    assert sand.count == len(interior) and sand.voxel_size == H_UM
    for i, k in enumerate(interior):
        for name in DESCRIPTORS:
            assert sand.values[name][i] == pytest.approx(truth[k][name], rel=1e-5, abs=1e-6)
        assert sand.equivalent_diameter[i] == pytest.approx(truth[k]["equivalent_diameter"] / H * H_UM, rel=1e-5)
    # the Sand Atlas columns as `analyse --atlas-csv` writes them (grainforge.fit.write_sand), then ours
    from grainforge.fit import OPENING_COLUMN, SAND_HEADER

    header = (saved / "sand.csv").read_text(encoding="utf-8").splitlines()[0].split(",")
    assert header[: len(SAND_HEADER) + 1] == [*SAND_HEADER, OPENING_COLUMN]
    assert header[len(SAND_HEADER) + 1:] == ["Voxels (-)", "Centroid X (µm)", "Centroid Y (µm)", "Centroid Z (µm)",
                                             "Border (-)"]
    # centroids in µm: x along the image's last axis
    line = (saved / "sand.csv").read_text(encoding="utf-8").splitlines()[1].split(",")
    k = int(line[0])
    idx = np.argwhere(vol == k).mean(axis=0)
    assert [float(c) for c in line[-4:-1]] == pytest.approx(list((idx[::-1] + 0.5) * H_UM), rel=1e-5)
    # --keep-border: the border grains too, flagged
    code, out = _run(["scan", saved / "labels.npy", "--voxel-size-um", H_UM, "--atlas-csv", saved / "all.csv",
                      "--keep-border"], saved)
    assert code == 0, out
    lines = (saved / "all.csv").read_text(encoding="utf-8").splitlines()[1:]
    flags = {int(r.split(",")[0]): r.split(",")[-1] for r in lines}
    assert flags == {**{k: "0" for k in interior}, **{k: "1" for k in border}}


def test_binary_segment_recovers_the_grains(scene, saved):
    vol, _, interior, border, small = scene
    np.save(saved / "binary.npy", (vol > 0).astype(np.uint8))
    code, out = _run(["scan", saved / "binary.npy", "--voxel-size-um", H_UM, "--segment", "--labels-out",
                      saved / "seg.npy", "--atlas-csv", saved / "seg.csv"], saved)
    assert code == 0, out
    found = np.load(saved / "seg.npy")
    rec = compare_labels(vol, found)
    assert rec["truth"] == len(interior) + len(border) + len(small)
    assert rec["found"] == rec["truth"], rec
    assert rec["merged"] == rec["split"] == rec["missed"] == rec["spurious"] == 0
    assert f"{len(interior)} grain(s) measured" in out
    # the API: the same
    labels, info = segment(vol > 0)
    assert info["grains"] == rec["truth"]


def test_meshes_are_closed_single_bodies(scene, saved):
    vol, truth, interior, _, _ = scene
    code, out = _run(["scan", saved / "labels.npy", "--voxel-size-um", H_UM, "--meshes", saved / "meshes"], saved)
    assert code == 0, out
    files = sorted((saved / "meshes").glob("*.stl"))
    assert [f.name for f in files] == [f"grain-{k:06d}.stl" for k in interior]
    for f, k in zip(files, interior):
        m = read_mesh(f)
        assert solid_problems(m.vertices, m.faces) == [], f.name
        # physical scale in mm: the volume within a few % of the grain's voxels
        want = truth[k]["voxels"] * (H_UM / 1000.0) ** 3
        assert signed_volume(m.vertices, m.faces) == pytest.approx(want, rel=0.12), f.name
    # ready for analyse: one closed body a file
    code, out = _run(["analyse", files[0], "--no-fractal", "--no-fourier", "--json"], saved)
    (row,) = json.loads(out[out.index("["):])
    assert code == 0 and row["flags"] == "", row["flags"]  # (not a substring test: a tmp path holds "popen")
    assert not [p for p in (saved / "meshes").iterdir() if p.name.startswith(".")]


def test_tiff_stack_folder_and_raw_read_the_same(scene, saved):
    tifffile = pytest.importorskip("tifffile")
    vol = scene[0]
    tifffile.imwrite(saved / "stack.tif", vol, imagej=True, resolution=(1 / H_UM, 1 / H_UM),
                     metadata={"spacing": H_UM, "unit": "um", "axes": "ZYX"})
    (saved / "slices").mkdir()
    for z in range(vol.shape[0]):
        tifffile.imwrite(saved / "slices" / f"s{z}.tif", vol[z])  # s10 after s9: numbers compared as numbers
    tifffile.imwrite(saved / "zip.tif", vol, compression="zlib")
    vol.tofile(saved / "v.raw")
    ref = label_boxes(Volume.from_array(vol))
    for v in (open_volume(saved / "stack.tif"), open_volume(saved / "slices"), open_volume(saved / "zip.tif"),
              open_volume(saved / "v.raw", raw_shape=vol.shape, raw_dtype="uint16"),
              open_volume(saved / "labels.npy")):
        assert v.shape == vol.shape
        assert label_boxes(v) == ref, v.path
        assert np.array_equal(v.read(5, 9), vol[5:9])
    assert open_volume(saved / "stack.tif").voxel_size_um == pytest.approx(H_UM)
    vol.astype(">u2").tofile(saved / "big.raw")  # big-endian raw
    big = open_volume(saved / "big.raw", raw_shape=vol.shape, raw_dtype=">u2")
    assert label_boxes(big) == ref and big.read(3, 4).dtype.isnative
    # the voxel size from the TIFF's metadata
    code, out = _run(["scan", saved / "stack.tif", "--atlas-csv", saved / "t.csv"], saved)
    assert code == 0, out
    assert "voxel size from" in out and read_sand(saved / "t.csv").voxel_size == pytest.approx(H_UM)
    # --labels-out as a TIFF keeps the voxel size: it can be scanned again as a labelled image
    tifffile.imwrite(saved / "binary.tif", (vol > 0).astype(np.uint8), imagej=True, resolution=(1 / H_UM, 1 / H_UM),
                     metadata={"spacing": H_UM, "unit": "um", "axes": "ZYX"})
    code, out = _run(["scan", saved / "binary.tif", "--segment", "--labels-out", saved / "seg.tif"], saved)
    assert code == 0, out
    again = open_volume(saved / "seg.tif")
    assert again.voxel_size_um == pytest.approx(H_UM) and again.shape == vol.shape
    assert compare_labels(vol, again.read(0, vol.shape[0]))["found"] == len(label_boxes(Volume.from_array(vol)))


def _bad_inputs(d: Path, vol: np.ndarray):
    np.save(d / "flat.npy", vol[0])
    np.save(d / "float.npy", vol.astype(np.float32))
    np.save(d / "empty.npy", np.zeros((10, 10, 10), np.uint16))
    np.save(d / "full.npy", np.full((10, 10, 10), 3, np.uint16))
    one = np.zeros((20, 20, 20), np.uint8)
    one[5:15, 5:15, 5:15] = 1
    np.save(d / "one.npy", one)
    np.save(d / "neg.npy", -vol.astype(np.int32))
    vol.tofile(d / "v.raw")
    (d / "notes.txt").write_text("hello", encoding="utf-8")
    return {
        "2D": (["flat.npy", "--voxel-size-um", 10], "not a 3D image"),
        "float": (["float.npy", "--voxel-size-um", 10], "cannot hold labels"),
        "empty": (["empty.npy", "--voxel-size-um", 10], "every voxel is 0"),
        "one label everywhere": (["full.npy", "--voxel-size-um", 10], "no void"),
        "binary without --segment": (["one.npy", "--voxel-size-um", 10], "add --segment"),
        "negative": (["neg.npy", "--voxel-size-um", 10], "negative"),
        "raw size": (["v.raw", "--raw-shape", 34, 34, 149, "--voxel-size-um", 10], "check --raw-shape"),
        "raw dtype": (["v.raw", "--raw-shape", 34, 34, 150, "--raw-dtype", "uint8", "--voxel-size-um", 10],
                      "check --raw-shape"),
        "voxel size 0": (["labels.npy", "--voxel-size-um", 0], "--voxel-size-um"),
        "voxel size < 0": (["labels.npy", "--voxel-size-um", -1], "--voxel-size-um"),
        "voxel size nan": (["labels.npy", "--voxel-size-um", "nan"], "--voxel-size-um"),
        "no voxel size": (["labels.npy"], "--voxel-size-um"),
        "not an image": (["notes.txt", "--voxel-size-um", 10], "unknown image format"),
        "missing": (["nothing.npy", "--voxel-size-um", 10], "no such file"),
        "segment empty": (["empty.npy", "--voxel-size-um", 10, "--segment"], "every voxel is 0"),
        "segment full": (["full.npy", "--voxel-size-um", 10, "--segment"], "no void"),
        "segment float": (["float.npy", "--voxel-size-um", 10, "--segment"], "cannot hold labels"),
        "labels-out without --segment": (["labels.npy", "--voxel-size-um", 10, "--labels-out", "l.npy"],
                                         "needs --segment"),
        "labels-out suffix": (["one.npy", "--voxel-size-um", 10, "--segment", "--labels-out", "l.png"], "must end in"),
    }


def test_bad_inputs_one_line_exit_2_nothing_written(scene, saved):
    cases = _bad_inputs(saved, scene[0])
    before = sorted(p.name for p in saved.rglob("*"))
    for name, (args, words) in cases.items():
        args = [saved / a if isinstance(a, str) and a.endswith((".npy", ".raw", ".txt", ".png")) else a
                for a in args]
        result = CliRunner().invoke(cli, ["scan", *map(str, args), "--atlas-csv", str(saved / "out.csv"),
                                          "--meshes", str(saved / "m")])
        err = result.output.strip()
        assert result.exit_code == 2, (name, err)
        assert len(err.splitlines()) == 1 and err.startswith("Error"), (name, err)
        assert words in err, (name, err)
        assert sorted(p.name for p in saved.rglob("*")) == before, name


def test_existing_outputs_need_overwrite(saved):
    (saved / "sand.csv").write_text("x", encoding="utf-8")
    code, out = _run(["scan", saved / "labels.npy", "--voxel-size-um", H_UM, "--atlas-csv", saved / "sand.csv"],
                     saved)
    assert code == 2 and "--overwrite" in out
    assert (saved / "sand.csv").read_text(encoding="utf-8") == "x"
    code, out = _run(["scan", saved / "labels.npy", "--voxel-size-um", H_UM, "--atlas-csv", saved / "sand.csv",
                      "--overwrite"], saved)
    assert code == 0 and math.isfinite(read_sand(saved / "sand.csv").voxel_size)


def test_tiff_without_tifffile_says_how_to_install(saved, monkeypatch):
    import sys

    (saved / "x.tif").write_bytes(b"II*\x00" + bytes(16))
    monkeypatch.setitem(sys.modules, "tifffile", None)  # import tifffile now raises ImportError
    result = CliRunner().invoke(cli, ["scan", str(saved / "x.tif"), "--voxel-size-um", "10"])
    err = result.output.strip()
    assert result.exit_code == 2 and len(err.splitlines()) == 1, err
    assert "pip install 'grainforge[scan]'" in err


def test_analyse_of_an_image_is_the_scan(saved):
    """`analyse IMAGE` takes scan's options and writes scan's table, byte for byte; an image among meshes (not
    first) is refused in one line that points to the scan."""
    for command, name in (("analyse", "a.csv"), ("scan", "s.csv")):
        code, out = _run([command, saved / "labels.npy", "--voxel-size-um", H_UM, "--atlas-csv", saved / name], saved)
        assert code == 0, out
    assert (saved / "a.csv").read_bytes() == (saved / "s.csv").read_bytes()
    stack = saved / "slices"
    stack.mkdir()
    (stack / "z000.tif").write_bytes(b"II*\x00")
    from grainforge.cli.main import _is_image_request

    assert _is_image_request([str(stack)]) and _is_image_request(["x.bin", "--raw-shape", "1", "2", "3"])
    assert not _is_image_request([str(saved)]) and not _is_image_request(["grain.stl", "--csv", "x.tif"])
    import trimesh

    trimesh.creation.box().export(saved / "g.stl")
    result = CliRunner().invoke(cli, ["analyse", str(saved / "g.stl"), str(saved / "labels.npy")])
    err = result.output.strip()
    assert result.exit_code == 2 and len(err.splitlines()) == 1, err
    assert "grainforge scan" in err


def test_beyond_memory_is_refused_before_any_work(saved, monkeypatch):
    import grainforge.runtime.estimate

    monkeypatch.setattr(grainforge.runtime.estimate, "machine_memory", lambda: 2_000_000)  # 1 MB allowed
    before = sorted(p.name for p in saved.rglob("*"))
    for extra in (["--segment"], []):
        result = CliRunner().invoke(cli, ["scan", str(saved / "labels.npy"), "--voxel-size-um", "10",
                                          "--atlas-csv", str(saved / "o.csv"), "--meshes", str(saved / "m"), *extra])
        err = result.output.strip()
        assert result.exit_code == 2 and len(err.splitlines()) == 1 and "GiB" in err, err
        assert sorted(p.name for p in saved.rglob("*")) == before


def test_a_label_in_two_pieces_meshes_its_largest():
    from grainforge.analysis.scan import grain_mesh

    z, y, x = np.indices((24, 24, 40))
    mask = ((z - 12) ** 2 + (y - 12) ** 2 + (x - 12) ** 2 <= 64) | ((z - 12) ** 2 + (y - 12) ** 2 + (x - 30) ** 2 <= 16)
    v, f, dropped = grain_mesh(mask, (0, 0, 0), 0.01)
    assert dropped == 1 and solid_problems(v, f) == []
    assert v[:, 0].max() < 0.21  # the big ball (x up to 20 voxels), not the small one


def test_thin_labels_are_counted_not_measured(tmp_path):
    img = np.zeros((12, 12, 40), np.uint16)
    img[6, 6, 2:5] = 1  # a line of 3 voxels: no voxel of the smoothed image reaches 0.5
    z, y, x = np.indices(img.shape)
    img[(z - 6) ** 2 + (y - 6) ** 2 + (x - 25) ** 2 <= 16] = 2
    np.save(tmp_path / "thin.npy", img)
    result = CliRunner().invoke(cli, ["scan", str(tmp_path / "thin.npy"), "--voxel-size-um", "10", "--min-voxels",
                                      "1", "--atlas-csv", str(tmp_path / "t.csv"), "--workers", "1"])
    assert result.exit_code == 0, result.output
    assert "1 grain(s) measured of 2 label(s)" in result.output and "1 a voxel or so thin" in result.output
    assert read_sand(tmp_path / "t.csv").count == 1


SPAM_SCAN = Path(__file__).parents[1] / "data" / "spam-scan.npz"


def test_scan_matches_spam_on_the_same_labelled_image(tmp_path):
    """Four grains touching in one labelled volume: each label's true sphericity from `grainforge scan` equals
    spam's on that volume (``benchmarks/spam_reference.py --scan`` stored spam 0.9.1's values; float32 there)."""
    with np.load(SPAM_SCAN) as data:
        labels, spam, names = data["labels"], data["spam_sphericity"], data["names"]
    np.save(tmp_path / "labels.npy", labels)
    code, out = _run(["scan", tmp_path / "labels.npy", "--voxel-size-um", "29", "--atlas-csv", tmp_path / "s.csv"],
                     tmp_path)
    assert code == 0 and f"{len(spam)} grain(s) measured of {len(spam)} label(s)" in out, out
    import csv

    with open(tmp_path / "s.csv", encoding="utf-8", newline="") as fh:
        rows = {int(r["Particle ID"]): float(r["True Sphericity (-)"]) for r in csv.DictReader(fh)}
    assert sorted(rows) == list(range(1, len(spam) + 1))
    for k, value in enumerate(spam, start=1):
        assert rows[k] == pytest.approx(value, abs=1e-6), (k, names[k - 1])


def test_the_stored_spam_values_are_live_spams_if_installed():
    """The reference above is spam's own today (run where spam is installed, e.g. its throwaway environment)."""
    spam_label = pytest.importorskip("spam.label", reason="spam (the Sand Atlas's library) is not installed")
    with np.load(SPAM_SCAN) as data:
        labels, stored = data["labels"], data["spam_sphericity"]
    live = np.asarray(spam_label.trueSphericity(labels.astype(np.uint32)), dtype=np.float64)[1:5]
    assert live == pytest.approx(stored, abs=1e-6)
