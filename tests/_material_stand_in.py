"""A stand-in engine for material calibrations: each test's angle a known smooth function of (μ, μ_r) plus a
seed's noise (0.5° sd), so that a calibration's answer can be checked against the (μ, μ_r) that reach the
targets. Installed by the fixture ``material_engine`` (tests/simulate/test_simulate_material.py)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

#: the seed-to-seed noise of the stand-in's angles, degrees
NOISE = 0.5


def angle(test: str, mu: float, mr: float) -> float:
    """The stand-in's noiseless angle of ``test`` at (μ, μ_r): the tilt rises mostly with μ, the triaxial friction
    angle more with μ_r (degrees)."""
    if test == "tilt":
        return 15.0 + 25.0 * (1.0 - math.exp(-2.0 * mu)) + 12.0 * mr
    return 18.0 + 15.0 * (1.0 - math.exp(-1.5 * mu)) + 35.0 * mr


def run_deck(deck, *, engine="yade", mpi=None, progress=None) -> dict:
    """A run of the deck in ``deck``: its angle at the deck's μ and μ_r, with the seed's noise; its result.json."""
    deck = Path(deck)
    scene = json.loads((deck / "grains.json").read_text())["scene"]
    test = deck.name.split("-seed")[0]
    mu = math.tan(math.radians(float(scene["friction_deg"])))
    mr = float(scene.get("rolling_friction", 0.0))
    rng = np.random.default_rng([int(scene["seed"]), round(mu * 1e6), round(mr * 1e6), len(test)])
    result = {"test": test, "angle": angle(test, mu, mr) + float(rng.normal(0.0, NOISE)), "mu": mu, "mr": mr}
    (deck / "result.json").write_text(json.dumps(result))
    if progress is not None:
        progress(1.0, test)
    return result


def measure_result(result: dict) -> dict:
    """The row of a stand-in run (a triaxial run's friction angles are its angle)."""
    a = float(result["angle"])
    row = {"test": result["test"], "angle_deg": a, "grains": 30, "inserted": 30, "lost": 0, "steps": 1, "dt_s": 1e-5,
           "simulated_time_s": 1.0, "note": ""}
    if result["test"] == "triaxial":
        row.update(peak_friction_deg=a + 2.0, ultimate_friction_deg=a, problems="")
    return row
