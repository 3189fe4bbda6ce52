"""The shadow frusta of spot lights and of a point light's six cube faces.

Owns ``spot_light_matrices`` (a square perspective map whose inscribed circle holds the
cone), ``POINT_LIGHT_FACES`` (the cube faces in the order the lighting shader picks them),
``point_light_face_angle`` / ``point_light_face_matrices`` and ``spot_texel_size``.
numpy only.
"""

import math

import numpy as np

from ..checks import finite, matrix4
from .spaces import _rigid_inverse, perspective_clip_from_view


def spot_light_matrices(world_from_light, spot_angle_rad, clip_start, clip_end):
    """``(light_from_world, clip_from_light)`` of a spot light's perspective shadow map.

    The spot looks down its local -Z; ``spot_angle_rad`` is the full cone angle (Blender's
    ``spot_size``), used as the vertical and horizontal field of view of a square map, so
    the cone fits the map's inscribed circle. Object scale is ignored: only the position
    and orientation of ``world_from_light`` count.
    """
    world_from_light = matrix4("spot world_from_light", world_from_light)
    angle = finite("spot angle", spot_angle_rad)
    if not 0.0 < angle < math.pi:
        raise ValueError(f"spot angle must be between 0 and pi radians (180 degrees) for a "
                         f"shadow map, got {angle}")
    clip_start, clip_end = finite("spot clip start", clip_start), \
        finite("spot clip end", clip_end)
    if not clip_start > 0.0:
        raise ValueError(f"spot clip start must be above 0, got {clip_start}")
    if not clip_end > clip_start:
        raise ValueError(f"spot clip end ({clip_end}) must be greater than clip start "
                         f"({clip_start})")
    # Remove scale and shear: Gram-Schmidt on the z (aim) axis first, so the aim is exact.
    z_axis = world_from_light[:3, 2]
    y_axis = world_from_light[:3, 1]
    if np.linalg.norm(z_axis) < 1e-12:
        raise ValueError("spot world_from_light has a zero Z axis (object scaled to 0)")
    z_axis = z_axis / np.linalg.norm(z_axis)
    x_axis = np.cross(y_axis, z_axis)
    if np.linalg.norm(x_axis) < 1e-12:
        x_axis = np.cross(np.array([0.0, 1.0, 0.0]) if abs(z_axis[1]) < 0.9
                          else np.array([1.0, 0.0, 0.0]), z_axis)
    x_axis = x_axis / np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    rigid = np.eye(4)
    rigid[:3, 0], rigid[:3, 1], rigid[:3, 2], rigid[:3, 3] = \
        x_axis, y_axis, z_axis, world_from_light[:3, 3]
    light_from_world = _rigid_inverse(rigid)
    clip_from_light = perspective_clip_from_view(angle, 1.0, clip_start, clip_end)
    return light_from_world, clip_from_light


# A point light's six cube faces, in the order the lighting shader picks them: the axis
# (0 x, 1 y, 2 z) and the sign of the direction from the light each face looks along.
POINT_LIGHT_FACES = ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0))


def point_light_face_angle(resolution, margin_texels):
    """Full field of view (radians) of one cube face of ``resolution`` texels: 90 degrees
    plus ``margin_texels`` on every side, so a filter's taps near a face's edge still read
    rendered texels (the shader picks the face by the largest axis, i.e. inside 90)."""
    return 2.0 * math.atan(1.0 / (1.0 - 2.0 * margin_texels / resolution))


def point_light_face_matrices(position, face, angle_rad, clip_start, clip_end):
    """``(light_from_world, clip_from_light)`` of cube face ``face`` (an index into
    POINT_LIGHT_FACES) of a point light at ``position``: a square perspective map looking
    from the light along that axis."""
    axis, sign = POINT_LIGHT_FACES[face]
    look = np.zeros(3)
    look[axis] = sign
    # Any up vector not along the look axis; the map's orientation does not matter.
    up = np.array([0.0, 0.0, 1.0]) if axis != 2 else np.array([0.0, 1.0, 0.0])
    z_axis = -look                 # lights look down their local -Z
    x_axis = np.cross(up, z_axis)
    y_axis = np.cross(z_axis, x_axis)
    world_from_light = np.eye(4)
    world_from_light[:3, 0], world_from_light[:3, 1], world_from_light[:3, 2] = \
        x_axis, y_axis, z_axis
    world_from_light[:3, 3] = np.asarray(position, dtype=np.float64)
    return spot_light_matrices(world_from_light, angle_rad, clip_start, clip_end)


def spot_texel_size(spot_angle_rad, resolution, distance):
    """Scene units covered by one spot shadow-map texel at ``distance`` along the aim."""
    return 2.0 * math.tan(0.5 * spot_angle_rad) * distance / resolution

