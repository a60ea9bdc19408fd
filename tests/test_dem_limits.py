"""DEM inputs at the edges of their ranges: bounded memory, clear refusals."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from grainforge.dem import levelset


def _flat_box():
    box = trimesh.creation.box(extents=(4.0, 4.0, 0.2)).subdivide().subdivide()
    return np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces, dtype=np.int64)


def test_level_set_blocks_give_the_same_field(monkeypatch):
    v, f = _flat_box()
    small = levelset.level_set(v, f, spacing=0.2).distance
    monkeypatch.setattr(levelset, "DISTANCE_BLOCK", 10**9)
    whole = levelset.level_set(v, f, spacing=0.2).distance
    assert small.tobytes() == whole.tobytes()


def test_level_set_refuses_a_grid_over_the_node_budget(monkeypatch):
    v, f = _flat_box()
    monkeypatch.setattr(levelset, "MAX_NODES", 5_000)
    with pytest.raises(ValueError, match=r"spacing 0\.05 .* nodes, more than 5,000.*at least"):
        levelset.level_set(v, f, spacing=0.05)
    # the spacing the message proposes is accepted
    import re

    try:
        levelset.level_set(v, f, spacing=0.05)
    except ValueError as exc:
        proposed = float(re.search(r"at least ([0-9.e-]+)", str(exc)).group(1))
    assert levelset.level_set(v, f, spacing=proposed).distance.size <= 5_000


def test_a_manifest_of_random_bytes_is_named(tmp_path):
    from grainforge.dem.inputs import grain_paths

    bad = tmp_path / "manifest.csv"
    bad.write_bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    with pytest.raises(ValueError, match=r"manifest\.csv: not a grainforge manifest"):
        grain_paths([bad])
    with pytest.raises(ValueError, match=r"manifest\.csv: not a grainforge manifest"):
        grain_paths([tmp_path])
