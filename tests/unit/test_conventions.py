"""The file's Y-up conventions in Blender's Z-up world (pure numpy, no Blender)."""

import math

import numpy as np
import pytest

from csm_engine.core import conventions as cv

C = cv.zup_from_yup()


def apply(matrix, point):
    return (matrix @ np.append(np.asarray(point, float), 1.0))[:3]


def direction(matrix, vector):
    return matrix[:3, :3] @ np.asarray(vector, float)


def test_zup_from_yup_maps_file_axes_to_blender_axes():
    # Blender (x, y, z) = file (x, -z, y): file up (+Y) is Blender up (+Z), and file
    # "towards the viewer" (+Z) is Blender -Y.
    assert np.allclose(apply(C, (1, 2, 3)), (1, -3, 2))
    assert np.allclose(apply(C, (0, 1, 0)), (0, 0, 1))
    assert np.allclose(apply(C, (0, 0, 1)), (0, -1, 0))
    assert math.isclose(np.linalg.det(C), 1.0)   # a rotation: handedness is kept
    assert np.allclose(C @ cv.YUP_FROM_ZUP, np.eye(4))


def test_rotations_are_right_handed_degrees():
    assert np.allclose(direction(cv.rotation_x(90), (0, 1, 0)), (0, 0, 1))
    assert np.allclose(direction(cv.rotation_y(90), (0, 0, 1)), (1, 0, 0))
    assert np.allclose(direction(cv.rotation_z(90), (1, 0, 0)), (0, 1, 0))


def test_object_matrix_turns_z_first_then_y_then_x():
    # (1,0,0): Rz(90) -> (0,1,0), then Rx(90) -> (0,0,1). X first would give (0,1,0).
    matrix = cv.object_matrix_yup((0, 0, 0), (90, 0, 90), (1, 1, 1))
    assert np.allclose(apply(matrix, (1, 0, 0)), (0, 0, 1))


def test_object_matrix_is_translate_rotate_scale():
    matrix = cv.object_matrix_yup((10, 20, 30), (0, 90, 0), (2, 3, 4))
    # scale first: (1,1,1) -> (2,3,4); Ry(90): (x,y,z) -> (z, y, -x) -> (4,3,-2); then T.
    assert np.allclose(apply(matrix, (1, 1, 1)), (14, 23, 28))


def test_object_matrix_zup_places_converted_points_where_the_file_does():
    rng = np.random.default_rng(562)
    for _ in range(50):
        t, r, s = rng.normal(size=3) * 50, rng.uniform(-360, 360, 3), rng.uniform(-3, 3, 3)
        point = rng.normal(size=3)
        file_world = apply(cv.object_matrix_yup(t, r, s), point)
        blender_world = apply(cv.object_matrix_zup(t, r, s), apply(C, point))
        assert np.allclose(blender_world, apply(C, file_world))


def test_blender_object_transform_composes_to_the_zup_matrix():
    rng = np.random.default_rng(7)
    for _ in range(50):
        t, r, s = rng.normal(size=3) * 50, rng.uniform(-360, 360, 3), rng.uniform(-3, 3, 3)
        location, mode, euler, scale = cv.blender_object_transform_zup(t, r, s)
        composed = np.eye(4)
        composed[:3, :3] = cv.euler_matrix(euler, mode) @ np.diag(scale)
        composed[:3, 3] = location
        assert np.allclose(composed, cv.object_matrix_zup(t, r, s))


def test_euler_matrix_turns_the_first_letter_first():
    # Blender's 'XYZ' mode turns about X first: (1,0,0) -Rx(90)-> (1,0,0) -Rz(90)-> (0,1,0)
    matrix = cv.euler_matrix((math.pi / 2, 0.0, math.pi / 2), 'XYZ')
    assert np.allclose(matrix @ (1, 0, 0), (0, 1, 0))
    matrix = cv.euler_matrix((math.pi / 2, 0.0, math.pi / 2), 'ZYX')
    assert np.allclose(matrix @ (1, 0, 0), (0, 0, 1))


def camera_forward_zup(translate, rotate):
    return direction(cv.camera_world_matrix_zup(translate, rotate), (0, 0, -1))


def camera_up_zup(translate, rotate):
    return direction(cv.camera_world_matrix_zup(translate, rotate), (0, 1, 0))


def test_camera_rotate_y_90_looks_down_file_plus_x():
    assert np.allclose(cv.camera_forward_yup((0, 90, 0)), (1, 0, 0))
    assert np.allclose(camera_forward_zup((0, 0, 0), (0, 90, 0)), (1, 0, 0))  # Blender +X
    assert np.allclose(camera_up_zup((0, 0, 0), (0, 90, 0)), (0, 0, 1))


def test_camera_rotate_zero_looks_down_file_minus_z_which_is_blender_plus_y():
    assert np.allclose(cv.camera_forward_yup((0, 0, 0)), (0, 0, -1))
    assert np.allclose(camera_forward_zup((5, 6, 7), (0, 0, 0)), (0, 1, 0))
    assert np.allclose(camera_up_zup((5, 6, 7), (0, 0, 0)), (0, 0, 1))


def test_camera_positive_rotate_x_looks_down():
    forward = camera_forward_zup((0, 0, 0), (30, 0, 0))
    assert np.allclose(forward, (0, math.cos(math.radians(30)), -math.sin(math.radians(30))))


def test_camera_world_matrix_sits_at_translate_and_inverts_the_view_matrix():
    t, r = (-190, 40, 50), (10, 100, -20)
    world = cv.camera_world_matrix_zup(t, r)
    assert np.allclose(world[:3, 3], apply(C, t))
    assert np.allclose(cv.camera_world_matrix_yup(t, r) @ cv.camera_view_matrix_yup(t, r), np.eye(4))


def test_course_camera_sees_the_course_island():
    # sceneShadow: camera (-190, 40, 50), rotate.y = 100, FOVy 30, island centre (0, 33, 0).
    view = cv.camera_view_matrix_yup((-190, 40, 50), (0, 100, 0))
    x, y, z = apply(view, (0, 33, 0))
    assert z < 0                                            # in front
    assert abs(y / -z) < math.tan(math.radians(15))         # inside the vertical FOV


def test_blender_camera_transform_composes_to_the_world_matrix():
    rng = np.random.default_rng(11)
    for _ in range(50):
        t, r = rng.normal(size=3) * 50, rng.uniform(-360, 360, 3)
        location, mode, euler = cv.blender_camera_transform_zup(t, r)
        composed = np.eye(4)
        composed[:3, :3] = cv.euler_matrix(euler, mode)
        composed[:3, 3] = location
        assert np.allclose(composed, cv.camera_world_matrix_zup(t, r))
    # A level camera shows Blender's familiar X = 90 degrees.
    assert cv.blender_camera_transform_zup((0, 0, 0), (0, 0, 0))[2] == (math.pi / 2, 0.0, -0.0)


@pytest.mark.parametrize("travel", [
    (0.3, -0.6, -0.7),      # the course's sun
    (0.0, -1.0, 0.0),       # straight down: parallel to the look-at up hint
    (0.0, 1.0, 0.0),        # straight up
    (1.0, 0.0, 0.0),
    (1e-30, -2e-30, 0.0),   # tiny but non-zero
    (1e308, -1e308, 1e308),  # huge: the length overflows without care
])
def test_sun_minus_z_is_the_converted_travel_direction(travel):
    rotation, quaternion = cv.sun_rotation_zup(travel)
    t = np.asarray(travel, float)
    expected = C[:3, :3] @ (t / np.max(np.abs(t)) / np.linalg.norm(t / np.max(np.abs(t))))
    assert np.allclose(rotation @ (0, 0, -1), expected)
    assert np.allclose(rotation.T @ rotation, np.eye(3))
    assert math.isclose(np.linalg.det(rotation), 1.0)
    w, x, y, z = quaternion
    from_quaternion = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])
    assert np.allclose(from_quaternion, rotation)


def test_course_sun_shines_down_and_away_in_blender():
    rotation, _ = cv.sun_rotation_zup((0.3, -0.6, -0.7))
    travel = rotation @ (0, 0, -1)
    # file (0.3, -0.6, -0.7) -> Blender (0.3, 0.7, -0.6), normalized
    assert np.allclose(travel, np.array([0.3, 0.7, -0.6]) / np.linalg.norm([0.3, 0.7, -0.6]))
    matrix = cv.sun_matrix_zup((0.3, -0.6, -0.7), (1, 2, 3))
    assert np.allclose(matrix[:3, 3], (1, 2, 3))


def test_zero_direction_is_refused():
    with pytest.raises(ValueError):
        cv.direction_zup_from_yup((0, 0, 0))


def test_look_at_points_minus_z_at_the_target_with_z_up():
    matrix = cv.look_at_matrix_zup((10, -10, 8), (0, 0, 0))
    forward = direction(matrix, (0, 0, -1))
    assert np.allclose(forward, -np.array([10, -10, 8]) / np.linalg.norm([10, -10, 8]))
    assert direction(matrix, (0, 1, 0))[2] > 0           # camera up leans to world up
    assert abs(direction(matrix, (1, 0, 0))[2]) < 1e-12   # horizon is level
