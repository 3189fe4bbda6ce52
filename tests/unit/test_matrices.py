"""The closed-form inverses (core/matrices.py) against numpy's LAPACK inverse."""

import numpy as np
import pytest

from csm_engine.core import matrices


def _rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def test_inverse_transpose_3x3_is_the_inverse_transposed():
    rng = np.random.default_rng(1)
    for _ in range(50):
        a = rng.normal(size=(3, 3)) * rng.uniform(0.01, 100.0)
        np.testing.assert_allclose(matrices.inverse_transpose_3x3(a), np.linalg.inv(a).T,
                                   rtol=1e-9, atol=1e-12 * np.abs(np.linalg.inv(a)).max())


def test_inverse_transpose_3x3_refuses_a_singular_matrix():
    with pytest.raises(np.linalg.LinAlgError):
        matrices.inverse_transpose_3x3(np.array([[1.0, 2, 3], [2, 4, 6], [0, 0, 1]]))


def test_inverse_rigid_of_a_rotation_and_translation():
    rng = np.random.default_rng(2)
    m = np.eye(4)
    m[:3, :3] = _rotation(rng)
    m[:3, 3] = rng.normal(size=3) * 1000.0
    np.testing.assert_allclose(matrices.inverse_rigid(m), np.linalg.inv(m), atol=1e-9)
    np.testing.assert_allclose(matrices.inverse_rigid(m) @ m, np.eye(4), atol=1e-9)


@pytest.mark.parametrize("scale", [(2.0, 2.0, 2.0), (1.0, 1.0, 1.001), (1.0, -1.0, 1.0)])
def test_inverse_rigid_of_a_scaled_matrix_is_the_general_inverse(scale):
    rng = np.random.default_rng(3)
    m = np.eye(4)
    m[:3, :3] = _rotation(rng) @ np.diag(scale)
    m[:3, 3] = (1.0, 2.0, 3.0)
    np.testing.assert_allclose(matrices.inverse_rigid(m), np.linalg.inv(m), atol=1e-12)


def test_inverse_projection_is_the_same_for_every_call_and_read_only():
    p = np.array([[1.2, 0, 0.1, 0], [0, 2.0, 0, 0], [0, 0, -1.01, -0.2], [0, 0, -1, 0]])
    first = matrices.inverse_projection(p)
    np.testing.assert_allclose(first @ p, np.eye(4), atol=1e-12)
    np.testing.assert_array_equal(first, np.linalg.inv(p))
    np.testing.assert_array_equal(matrices.inverse_projection(p.copy()), first)
    assert not first.flags.writeable
    # Another lens asked for in between does not change what this one gets.
    other = p.copy()
    other[0, 0] = 0.8
    np.testing.assert_array_equal(matrices.inverse_projection(other), np.linalg.inv(other))
    np.testing.assert_array_equal(matrices.inverse_projection(p), np.linalg.inv(p))
