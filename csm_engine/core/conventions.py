"""Coordinate conventions of the scene files, as numpy 4x4 matrices (float64).

Owns the meaning of the file's numbers in Blender terms:
- the file's world is Y-up right-handed (OpenGL); Blender is Z-up, and
  Blender (x, y, z) = file (x, -z, y) -- the same change of basis Blender's glTF importer
  applies to glTF meshes;
- an object's transform is ``T(translate) * Rx * Ry * Rz * S(scale)``, angles in degrees;
- a camera's view matrix is ``Rx * Ry * Rz * T(-translate)``, so ``rotate`` turns the
  world into the camera and ``rotate.y = 90`` looks down file +X;
- a directional light's ``direction`` is where the light travels.

Matrices are named ``target_from_source``; a product reads right to left. No bpy here.
"""

import math

import numpy as np

# NOTE: a proper rotation (det +1), so it maps right-handed frames to right-handed frames
# and its inverse is its transpose.
ZUP_FROM_YUP = np.array([
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 0.0, -1.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
])
YUP_FROM_ZUP = ZUP_FROM_YUP.T.copy()
ZUP_FROM_YUP.setflags(write=False)
YUP_FROM_ZUP.setflags(write=False)


def zup_from_yup():
    """Change of basis from the file's Y-up world to Blender's Z-up world."""
    return ZUP_FROM_YUP.copy()


def _vec3(value):
    if hasattr(value, "as_tuple"):
        value = value.as_tuple()
    elif hasattr(value, "x"):
        value = (value.x, value.y, value.z)
    return np.asarray(value, dtype=np.float64).reshape(3)


def translation(offset):
    matrix = np.eye(4)
    matrix[:3, 3] = _vec3(offset)
    return matrix


def scaling(factors):
    return np.diag(np.append(_vec3(factors), 1.0))


def rotation_x(degrees):
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]], dtype=np.float64)


def rotation_y(degrees):
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]], dtype=np.float64)


def rotation_z(degrees):
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=np.float64)


def rotation_xyz(rotate_degrees):
    """``Rx * Ry * Rz``: applied to a point, Z turns first, then Y, then X (the handout)."""
    x, y, z = _vec3(rotate_degrees)
    return rotation_x(x) @ rotation_y(y) @ rotation_z(z)


def object_matrix_yup(translate, rotate_degrees, scale):
    """world_from_object in the file's Y-up world: ``T * Rx * Ry * Rz * S``."""
    return translation(translate) @ rotation_xyz(rotate_degrees) @ scaling(scale)


def object_matrix_zup(translate, rotate_degrees, scale):
    """The same placement as a Blender (Z-up) world matrix: ``C * M * C^-1``.

    Mesh data imported with Y-up conversion is already in Z-up coordinates, so the
    Y-up transform is conjugated rather than just pre-multiplied.
    """
    return ZUP_FROM_YUP @ object_matrix_yup(translate, rotate_degrees, scale) @ YUP_FROM_ZUP


def blender_object_transform_zup(translate, rotate_degrees, scale):
    """``object_matrix_zup`` as Blender location, Euler mode, Euler radians and scale.

    Conjugating by C turns file Rx(a), Ry(b), Rz(c) into Blender rotations about +X by a,
    +Z by b and +Y by -c, and file scale (sx, sy, sz) into (sx, sz, sy). The file applies
    Z first, then Y, then X, which in Blender axes is Y, then Z, then X: Euler mode 'YZX'.
    Returning Euler values (rather than a decomposed matrix) keeps the numbers a user sees
    in the N panel the file's own angles.
    """
    t = _vec3(translate)
    a, b, c = (math.radians(v) for v in _vec3(rotate_degrees))
    sx, sy, sz = _vec3(scale)
    location = tuple(ZUP_FROM_YUP[:3, :3] @ t)
    return location, 'YZX', (a, -c, b), (sx, sz, sy)


def blender_camera_transform_zup(translate, rotate_degrees):
    """``camera_world_matrix_zup`` as Blender location, Euler mode and Euler radians.

    ``C * (Rx(a) Ry(b) Rz(c))^T = Ry'(c) * Rz'(-b) * Rx'(-a) * C`` in Blender axes, and C
    itself is a +90 degree turn about X, so the camera is Euler mode 'XZY' with
    (90 - a, c, -b) degrees: a level camera shows the familiar X = 90 degrees.
    """
    t = _vec3(translate)
    a, b, c = _vec3(rotate_degrees)
    location = tuple(ZUP_FROM_YUP[:3, :3] @ t)
    return location, 'XZY', (math.radians(90.0 - a), math.radians(c), math.radians(-b))


def euler_matrix(euler_radians, mode):
    """3x3 matrix of a Blender Euler rotation (the first letter of ``mode`` turns first)."""
    turns = {"X": lambda v: rotation_x(math.degrees(v)), "Y": lambda v: rotation_y(math.degrees(v)),
             "Z": lambda v: rotation_z(math.degrees(v))}
    angles = dict(zip("XYZ", euler_radians))
    matrix = np.eye(4)
    for axis in mode:
        matrix = turns[axis](angles[axis]) @ matrix
    return matrix[:3, :3]


def camera_view_matrix_yup(translate, rotate_degrees):
    """camera_from_world of the file's camera: ``Rx * Ry * Rz * T(-translate)``."""
    return rotation_xyz(rotate_degrees) @ translation(-_vec3(translate))


def camera_world_matrix_yup(translate, rotate_degrees):
    """world_from_camera in Y-up: the inverse view matrix, ``T(t) * (Rx Ry Rz)^T``."""
    world_from_camera = np.eye(4)
    world_from_camera[:3, :3] = rotation_xyz(rotate_degrees)[:3, :3].T
    world_from_camera[:3, 3] = _vec3(translate)
    return world_from_camera


def camera_world_matrix_zup(translate, rotate_degrees):
    """The Blender camera object's ``matrix_world``.

    The OpenGL camera and Blender's camera share their local frame (look down -Z, up is
    +Y), so only the world side changes basis: ``C * world_from_camera``.
    """
    return ZUP_FROM_YUP @ camera_world_matrix_yup(translate, rotate_degrees)


def camera_forward_yup(rotate_degrees):
    """Unit direction the file's camera looks along, in the file's Y-up world."""
    return rotation_xyz(rotate_degrees)[:3, :3].T @ np.array([0.0, 0.0, -1.0])


def direction_zup_from_yup(direction_yup):
    """Convert a direction from file to Blender axes and normalize it.

    Dividing by the largest component first keeps huge or tiny (but finite, non-zero)
    inputs from overflowing or underflowing the length.
    """
    direction = _vec3(direction_yup)
    largest = np.max(np.abs(direction))
    if not np.isfinite(largest) or largest == 0.0:
        raise ValueError(f"direction {tuple(direction)} has no usable length")
    direction = direction / largest
    direction = direction / np.linalg.norm(direction)
    return ZUP_FROM_YUP[:3, :3] @ direction


def look_rotation_zup(forward_zup, up_hint=(0.0, 0.0, 1.0)):
    """3x3 rotation whose local -Z axis is ``forward_zup`` and local +Y leans to up_hint.

    When the forward axis is (nearly) parallel to the hint, world +Y is used instead so
    the result is always a proper rotation.
    """
    forward = _vec3(forward_zup)
    forward = forward / np.linalg.norm(forward)
    z_axis = -forward
    up = _vec3(up_hint)
    if abs(float(np.dot(up / np.linalg.norm(up), z_axis))) > 0.999:
        up = np.array([0.0, 1.0, 0.0])
    x_axis = np.cross(up, z_axis)
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    return np.column_stack((x_axis, y_axis, z_axis))


def look_at_matrix_zup(eye, target, up_hint=(0.0, 0.0, 1.0)):
    """world_from_camera for a Blender camera at ``eye`` looking at ``target``."""
    eye = _vec3(eye)
    matrix = np.eye(4)
    matrix[:3, :3] = look_rotation_zup(_vec3(target) - eye, up_hint)
    matrix[:3, 3] = eye
    return matrix


def quaternion_from_rotation(rotation):
    """(w, x, y, z) unit quaternion of a 3x3 rotation matrix (Shepperd's method)."""
    m = np.asarray(rotation, dtype=np.float64)[:3, :3]
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = math.sqrt(trace + 1.0) * 2.0
        q = (0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2.0
        q = ((m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2.0
        q = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s)
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2.0
        q = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s)
    q = np.array(q)
    if q[0] < 0.0:
        q = -q
    return q / np.linalg.norm(q)


def sun_rotation_zup(direction_yup):
    """Rotation of a Blender sun whose light travels along the file's ``direction``.

    Blender's sun shines down its local -Z axis, so -Z is set to C * normalize(direction).
    Returns ``(rotation 3x3, quaternion (w, x, y, z))``.
    """
    rotation = look_rotation_zup(direction_zup_from_yup(direction_yup))
    return rotation, quaternion_from_rotation(rotation)


def sun_matrix_zup(direction_yup, location=(0.0, 0.0, 0.0)):
    """world_from_light 4x4 of the Blender sun object at ``location`` (Z-up)."""
    matrix = np.eye(4)
    matrix[:3, :3] = sun_rotation_zup(direction_yup)[0]
    matrix[:3, 3] = _vec3(location)
    return matrix
