"""The spaces cascades are fitted in, and the matrices between them.

Owns the camera's depth slices (``view_slice_corners`` in view space,
``frustum_slice_corners`` in the world), the light's rotation (``light_view_matrix``, and
the check that a matrix is one), OpenGL's orthographic and perspective projections, and
the small point and box helpers the other cascade modules share. numpy only.
"""

import numpy as np

from ..camera import CameraProjection, as_projection
from ..checks import finite, matrix4, vector3
from ..memo import ValueMemo


def _bounds(name, bounds):
    """(min, max) world AABB as two float64 (3,) arrays, checked."""
    try:
        low, high = bounds
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (min, max) of 3-vectors, got {bounds!r}") \
            from None
    low, high = vector3(f"{name} min", low), vector3(f"{name} max", high)
    if np.any(low > high):
        raise ValueError(f"{name} min {low.tolist()} exceeds max {high.tolist()}")
    return low, high


# Corner i of a box takes the high side on axis a when bit a of i is set.
_CORNER_PICK = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=bool)
_CORNER_PICK.setflags(write=False)


def _box_corners(low, high):
    """The 8 corners of an axis-aligned box, (8, 3)."""
    return np.where(_CORNER_PICK, high, low)


def _transform_points(matrix, points):
    """Affine transform of (N, 3) points by a 4x4 matrix (no perspective divide)."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def view_slice_corners(projection, near_d, far_d):
    """The 8 corners of the view-depth slice ``near_d .. far_d`` in *view* space, (8, 3).

    Order: near plane then far plane, each (left, bottom), (right, bottom), (right, top),
    (left, top); so corner ``i`` and ``i + 4`` lie on the same frustum edge.
    """
    projection = as_projection(projection)
    near_d, far_d = finite("slice near depth", near_d), finite("slice far depth", far_d)
    if not far_d > near_d:
        raise ValueError(f"slice far depth ({far_d}) must be greater than slice near depth "
                         f"({near_d})")
    if projection.is_perspective and not near_d > 0.0:
        raise ValueError(f"slice near depth must be above 0 for a perspective camera, "
                         f"got {near_d}")
    left, right, bottom, top = projection.view_window()
    window = np.array([[left, bottom], [right, bottom], [right, top], [left, top]])
    corners = np.empty((8, 3))
    for half, depth in ((0, near_d), (1, far_d)):
        scale = depth if projection.is_perspective else 1.0
        corners[4 * half:4 * half + 4, :2] = window * scale
        corners[4 * half:4 * half + 4, 2] = -depth
    return corners


def frustum_slice_corners(world_from_view, projection, near_d, far_d):
    """The 8 world-space corners (8, 3) of the camera frustum between view depths
    ``near_d`` and ``far_d`` (scene units). ``projection`` is a ``CameraProjection`` or an
    OpenGL ``clip_from_view`` matrix. Corner order as in ``view_slice_corners``."""
    world_from_view = matrix4("world_from_view", world_from_view)
    return _transform_points(world_from_view, view_slice_corners(projection, near_d, far_d))


def light_view_matrix(light_dir_world, up_hint=None):
    """``light_from_world`` rotation (no translation) of a light travelling along
    ``light_dir_world``: light space looks down its -Z along the light, +Y is as close to
    ``up_hint`` as possible.

    ``up_hint`` defaults to world +Y, then world +Z when the light travels (nearly) along Y.
    +Y first because the common case, a sun straight down (0, 0, -1), is then far from the
    degenerate case. For an animated sun pass the sun's own local +Y axis
    (``world_from_sun[:3, 1]``): it is never parallel to the sun's direction and turns with
    it, so the shadow grid never flips.
    """
    return _light_view(vector3("light direction", light_dir_world), up_hint).copy()


def _light_view_uncached(forward, up_hint):
    length = np.linalg.norm(forward)
    if not length > 1e-12:
        raise ValueError(f"light direction must not be zero, got {forward.tolist()}")
    forward = forward / length
    candidates = [] if up_hint is None else [vector3("light up hint", up_hint)]
    candidates += [np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])]
    for up in candidates:
        # NOTE: Gram-Schmidt loses precision as up approaches the light direction; below
        # ~0.1 (sin of ~6 degrees) of independent length fall back to the next hint.
        side = np.cross(forward, up)
        if np.linalg.norm(side) > 0.1 * np.linalg.norm(up):
            break
    x_axis = side / np.linalg.norm(side)
    z_axis = -forward
    y_axis = np.cross(z_axis, x_axis)
    light_from_world = np.eye(4)
    light_from_world[0, :3], light_from_world[1, :3], light_from_world[2, :3] = \
        x_axis, y_axis, z_axis
    return light_from_world


# The sun rarely turns between viewport redraws, and the two cross products cost more than
# the rest of a cascade: the rotation is remembered by the direction's and hint's values.
_light_view = ValueMemo(
    _light_view_uncached, 64,
    key=lambda forward, up_hint: (forward.tobytes(), None if up_hint is None else
                                  np.asarray(up_hint, dtype=np.float64).tobytes()))


_IDENTITY3 = np.eye(3)
_IDENTITY3.setflags(write=False)
_BOTTOM_ROW = np.array([0.0, 0.0, 0.0, 1.0])
_BOTTOM_ROW.setflags(write=False)


def _close(a, b, atol):
    """``np.allclose(a, b, atol=atol)`` (rtol 1e-5) for finite arrays, without its
    per-call overhead (~25 us; this runs once per cascade per frame)."""
    return bool((np.abs(a - b) <= atol + 1e-5 * np.abs(b)).all())


def _check_rotation(light_from_world_rot):
    m = matrix4("light_from_world rotation", light_from_world_rot)
    rotation = m[:3, :3]
    if not (_close(rotation @ rotation.T, _IDENTITY3, 1e-6)
            and np.linalg.det(rotation) > 0.0 and _close(m[:3, 3], 0.0, 1e-9)
            and _close(m[3], _BOTTOM_ROW, 1e-8)):
        raise ValueError("light_from_world rotation must be a pure rotation "
                         "(orthonormal, determinant +1, no translation); "
                         "build it with light_view_matrix()")
    return rotation


def _rigid_inverse(matrix):
    inverse = np.eye(4)
    inverse[:3, :3] = matrix[:3, :3].T
    inverse[:3, 3] = -matrix[:3, :3].T @ matrix[:3, 3]
    return inverse


def orthographic_clip_from_view(left, right, bottom, top, near, far):
    """OpenGL glOrtho: light-space box (z from -near to -far) to clip -1..1."""
    m = np.eye(4)
    m[0, 0] = 2.0 / (right - left)
    m[1, 1] = 2.0 / (top - bottom)
    m[2, 2] = -2.0 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


def perspective_clip_from_view(fov_y, aspect, near, far):
    """OpenGL gluPerspective: symmetric frustum, full vertical angle ``fov_y`` radians."""
    return CameraProjection(kind="PERSP", fov_y=fov_y, aspect=aspect,
                            clip_start=near, clip_end=far).clip_from_view()

