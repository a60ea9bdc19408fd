"""The one random-rotation implementation, against scipy's (an independent reference)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from grainforge.geometry.rotations import quaternion_matrix, random_rotation


@pytest.mark.parametrize("seed", [0, 1, 7, 12345])
def test_scipy_convention_is_scipys_random_rotation_bit_for_bit(seed):
    expected = Rotation.random(random_state=np.random.default_rng(seed)).as_matrix()
    assert np.array_equal(random_rotation(seed), expected)


@pytest.mark.parametrize("seed", [0, 1, 7, 12345])
def test_scalar_first_is_the_scalar_first_quaternion(seed):
    q = np.random.default_rng(seed).standard_normal(4)
    w, x, y, z = q
    reference = Rotation.from_quat([x, y, z, w]).as_matrix()  # scipy reads (x, y, z, w)
    got = random_rotation(seed, convention="scalar-first")
    assert np.allclose(got, reference, atol=1e-14)
    assert np.array_equal(got, quaternion_matrix(q))


def test_a_generator_is_advanced_by_four_draws():
    rng = np.random.default_rng(3)
    random_rotation(rng, convention="scalar-first")
    ref = np.random.default_rng(3)
    ref.standard_normal(4)
    assert rng.standard_normal() == ref.standard_normal()


@pytest.mark.parametrize("convention", ["scipy", "scalar-first"])
def test_rotations_are_uniform(convention):
    """A uniform rotation sends a fixed axis uniformly over the sphere: each coordinate's mean is
    0 (±4 standard errors) and its mean square 1/3."""
    rng = np.random.default_rng(11)
    z = np.array([random_rotation(rng, convention) @ [0.0, 0.0, 1.0] for _ in range(4000)])
    se = np.sqrt(1 / 3 / len(z))
    assert np.all(np.abs(z.mean(axis=0)) < 4 * se)
    assert np.allclose((z**2).mean(axis=0), 1 / 3, atol=0.03)
    dets = [np.linalg.det(random_rotation(s, convention)) for s in range(20)]
    assert np.allclose(dets, 1.0)


def test_unknown_convention_is_refused():
    with pytest.raises(ValueError, match="convention"):
        random_rotation(0, convention="xyzw")
