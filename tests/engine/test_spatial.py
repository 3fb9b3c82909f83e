"""Tests for engine.spatial: quaternion helpers and Transform."""

import numpy as np
import pytest

from engine.spatial import (
    Transform,
    quat_conjugate,
    quat_from_axis_angle,
    quat_from_euler,
    quat_identity,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_to_matrix,
)


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def _random_quats(rng, n):
    return quat_normalize(rng.normal(size=(n, 4)))


def test_rotate_agrees_with_matrix(rng):
    vectors = rng.normal(size=(50, 3))
    for q in _random_quats(rng, 10):
        np.testing.assert_allclose(quat_rotate(q, vectors), vectors @ quat_to_matrix(q).T, atol=1e-12)
    qs = _random_quats(rng, 50)
    per_point = quat_rotate(qs, vectors)
    by_matrix = np.einsum("nij,nj->ni", quat_to_matrix(qs), vectors)
    np.testing.assert_allclose(per_point, by_matrix, atol=1e-12)


def test_matrix_is_a_proper_rotation(rng):
    m = quat_to_matrix(_random_quats(rng, 20))
    np.testing.assert_allclose(m @ np.swapaxes(m, -1, -2), np.broadcast_to(np.eye(3), m.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(m), 1.0, atol=1e-12)


def test_one_quaternion_matrix_is_the_stacked_one_bit_for_bit(rng):
    """One quaternion takes a Python-float path: it must give the array path's bits, for unit, non-unit, signed
    zero, tiny, huge and non-finite quaternions alike (the zero quaternion keeps numpy's inf and warning)."""
    qs = np.concatenate([_random_quats(rng, 200), rng.normal(size=(200, 4)) * rng.choice([1e-160, 1e-3, 7.0, 1e150],
                                                                                        (200, 1)),
                         [[1.0, 0.0, 0.0, 0.0], [-0.0, 0.0, -0.0, 1.0], [1.0, -0.0, 0.0, -0.0],
                          [np.nan, 0.0, 1.0, 0.0], [np.inf, 0.0, 0.0, 1.0], [1e200, 1e200, 0.0, 0.0]]])
    with np.errstate(over="ignore", invalid="ignore"):  # the huge and non-finite rows
        stacked = quat_to_matrix(qs)
    for q, want in zip(qs, stacked):
        with np.errstate(over="ignore", invalid="ignore"):
            assert quat_to_matrix(q).tobytes() == want.tobytes()
    with pytest.warns(RuntimeWarning):
        assert quat_to_matrix(np.zeros(4)).tobytes() == quat_to_matrix(np.zeros((1, 4)))[0].tobytes()


def test_axis_angle_known_rotations():
    q = quat_from_axis_angle([0.0, 0.0, 2.0], np.pi / 2)  # axis need not be unit
    np.testing.assert_allclose(quat_rotate(q, [1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-15)
    q = quat_from_axis_angle([1.0, 1.0, 1.0], 2 * np.pi / 3)  # cycles the axes x -> y -> z
    np.testing.assert_allclose(quat_rotate(q, np.eye(3)), np.roll(np.eye(3), 1, axis=1), atol=1e-12)
    np.testing.assert_allclose(quat_from_axis_angle([0, 1, 0], 0.0), quat_identity())
    with pytest.raises(ValueError, match="axis"):
        quat_from_axis_angle([0.0, 0.0, 0.0], 1.0)


def test_mul_composes_and_conjugate_inverts(rng):
    a, b = _random_quats(rng, 2)
    v = rng.normal(size=(20, 3))
    np.testing.assert_allclose(quat_rotate(quat_mul(a, b), v), quat_rotate(a, quat_rotate(b, v)), atol=1e-12)
    np.testing.assert_allclose(quat_rotate(quat_conjugate(a), quat_rotate(a, v)), v, atol=1e-12)
    np.testing.assert_allclose(quat_mul(a, quat_conjugate(a)), quat_identity(), atol=1e-15)


def test_normalize(rng):
    q = quat_normalize([2.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(q, quat_identity())
    np.testing.assert_allclose(np.linalg.norm(quat_normalize(rng.normal(size=(5, 4))), axis=1), 1.0)
    with pytest.raises(ValueError, match="zero quaternion"):
        quat_normalize([0.0, 0.0, 0.0, 0.0])


def test_euler_axes_y_up_right_handed():
    forward, right = np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(quat_rotate(quat_from_euler(np.pi / 2, 0, 0), forward), [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(quat_rotate(quat_from_euler(0, np.pi / 2, 0), forward), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(quat_rotate(quat_from_euler(0, 0, np.pi / 2), right), [0, 1, 0], atol=1e-15)
    # Order: roll, then pitch, then yaw. Pitch up 90° then yaw 90°: forward points up regardless of yaw.
    q = quat_from_euler(np.pi / 2, np.pi / 2, 0)
    np.testing.assert_allclose(quat_rotate(q, forward), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(quat_rotate(q, right), [0, 0, -1], atol=1e-15)


def test_transform_defaults_are_independent_and_float64():
    a, b = Transform(), Transform()
    a.position[0] = 5.0
    assert b.position[0] == 0.0
    np.testing.assert_array_equal(b.rotation, [1, 0, 0, 0])
    np.testing.assert_array_equal(b.scale, [1, 1, 1])
    assert Transform(position=[1, 2, 3]).position.dtype == np.float64
    np.testing.assert_array_equal(b.matrix(), np.eye(4))
    with pytest.raises(ValueError, match="position"):
        Transform(position=[1.0, 2.0])


def test_transform_matrix_is_trs_and_matches_to_world(rng):
    t = Transform(position=[1.0, -2.0, 3.0], rotation=_random_quats(rng, 1)[0], scale=[2.0, 0.5, 3.0])
    points = rng.normal(size=(30, 3))
    homogeneous = np.hstack([points, np.ones((30, 1))])
    np.testing.assert_allclose((homogeneous @ t.matrix().T)[:, :3], t.to_world(points), atol=1e-12)
    trs = np.eye(4)
    trs[:3, 3] = t.position
    r = np.eye(4)
    r[:3, :3] = quat_to_matrix(t.rotation)
    np.testing.assert_allclose(trs @ r @ np.diag([2.0, 0.5, 3.0, 1.0]), t.matrix(), atol=1e-12)
    np.testing.assert_allclose(t.to_local(t.to_world(points)), points, atol=1e-12)
    np.testing.assert_allclose(np.linalg.inv(t.matrix()) @ homogeneous[0], [*t.to_local(points[:1])[0], 1.0],
                               atol=1e-12)


def test_transform_basis_vectors():
    t = Transform()
    np.testing.assert_array_equal(t.forward(), [0, 0, -1])
    np.testing.assert_array_equal(t.right(), [1, 0, 0])
    np.testing.assert_array_equal(t.up(), [0, 1, 0])
    t = Transform(rotation=quat_from_euler(0.3, -0.7, 1.1), scale=[3.0, 3.0, 3.0])
    f, r, u = t.forward(), t.right(), t.up()
    np.testing.assert_allclose([np.linalg.norm(f), np.linalg.norm(r), np.linalg.norm(u)], 1.0)
    np.testing.assert_allclose(np.cross(r, u), -f, atol=1e-12)  # right-handed, looking down -Z
    np.testing.assert_allclose(t.matrix()[:3, 2] / 3.0, -f, atol=1e-12)
    t = Transform(rotation=quat_from_euler(np.pi / 2, 0.0, 0.0))
    np.testing.assert_allclose(t.forward(), [-1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(t.right(), [0, 0, -1], atol=1e-15)


def test_cross_gives_the_bits_of_np_cross_for_any_broadcast():
    from engine.spatial import cross

    rng = np.random.default_rng(5)
    for shape_a, shape_b in (((3,), (3,)), ((100, 3), (100, 3)), ((3,), (7, 3)), ((4, 1, 3), (1, 6, 3))):
        a, b = rng.normal(size=shape_a), rng.normal(size=shape_b)
        assert np.array_equal(cross(a, b), np.cross(a, b))
    assert np.array_equal(cross([1, 0, 0], (0, 1, 0)), [0.0, 0.0, 1.0])


def test_single_euler_angles_take_a_fast_path_with_the_array_paths_bits():
    """Scripts and cameras build one rotation per call; the scalar path must give the bytes of the array path
    (signed zeros included), or state hashes would depend on how the angles were passed."""
    from engine.spatial import quat_from_axis_angle, quat_from_euler, quat_mul

    rng = np.random.default_rng(3)
    cases = [tuple(v) for v in rng.uniform(-10.0, 10.0, (500, 3))] + [(0.0, -0.0, 0.0), (-0.0, -0.0, -0.0),
                                                                      (np.pi, -np.pi / 2, 0.0)]
    for yaw, pitch, roll in cases:
        array = quat_mul(quat_from_axis_angle((0.0, 1.0, 0.0), yaw),
                         quat_mul(quat_from_axis_angle((1.0, 0.0, 0.0), pitch),
                                  quat_from_axis_angle((0.0, 0.0, 1.0), roll)))
        assert quat_from_euler(float(yaw), float(pitch), float(roll)).tobytes() == array.tobytes()
    stacked = quat_from_euler(np.array([0.1, -0.4]), 0.2, 0.0)  # arrays still broadcast
    assert stacked.shape == (2, 4) and stacked[1].tobytes() == quat_from_euler(-0.4, 0.2, 0.0).tobytes()


def test_quat_is_identity_is_exact():
    from engine.spatial import quat_identity, quat_is_identity

    assert quat_is_identity(quat_identity())
    assert quat_is_identity(np.array([1.0, -0.0, 0.0, -0.0]))
    assert not quat_is_identity(quat_from_axis_angle([0.0, 1.0, 0.0], 1e-9))
    assert not quat_is_identity(np.array([-1.0, 0.0, 0.0, 0.0]))  # the same rotation, but not the identity's bits
