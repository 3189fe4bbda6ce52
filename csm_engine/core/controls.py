"""Pure maths behind the interactive controls: the first-person camera and the sun's
azimuth/elevation.

Owns how keys and mouse drags move a ``world_from_camera`` matrix and how a sun direction
maps to azimuth/elevation degrees (Z-up, Blender world: azimuth from +X toward +Y of the
direction towards the sun, elevation above the horizon; the vector is where light travels).
numpy only; the operators in ``blender/`` call these.
"""

import math

import numpy as np


# ------------------------------------------------------------------ sun direction
def travel_from_azimuth_elevation(azimuth_degrees, elevation_degrees):
    """Unit vector the light travels along, for a sun at this azimuth/elevation."""
    azimuth = math.radians(azimuth_degrees)
    elevation = math.radians(elevation_degrees)
    towards_sun = (math.cos(elevation) * math.cos(azimuth),
                   math.cos(elevation) * math.sin(azimuth),
                   math.sin(elevation))
    return tuple(-c for c in towards_sun)


def azimuth_elevation_from_travel(travel):
    """(azimuth, elevation) in degrees of the sun whose light travels along ``travel``."""
    towards = -np.asarray(travel, dtype=np.float64)
    length = float(np.linalg.norm(towards))
    if length == 0.0:
        return 0.0, 90.0
    towards /= length
    elevation = math.degrees(math.asin(max(-1.0, min(1.0, towards[2]))))
    horizontal = math.hypot(towards[0], towards[1])
    azimuth = math.degrees(math.atan2(towards[1], towards[0])) if horizontal > 1e-9 else 0.0
    return azimuth, elevation


# ------------------------------------------------------------------ first-person camera
# Pitch stops this far from straight up/down, so the view never flips over.
PITCH_LIMIT_DEGREES = 89.0
MOUSE_DEGREES_PER_PIXEL = 0.2
WORLD_UP = np.array([0.0, 0.0, 1.0])
WORLD_UP.setflags(write=False)


def step(matrix, keys_down, dt, speed):
    """world_from_camera after moving for ``dt`` seconds at ``speed`` (scene units/s).

    ``keys_down`` holds letters: W/S forward/back along the view direction, A/D left/right
    along the camera's X axis, Q/E down/up along world Z. Opposite keys cancel; several
    directions at once move at ``speed`` along their normalized sum.
    """
    matrix = np.array(matrix, dtype=np.float64)
    right = matrix[:3, 0] / np.linalg.norm(matrix[:3, 0])
    forward = -matrix[:3, 2] / np.linalg.norm(matrix[:3, 2])
    held = {key.upper() for key in keys_down}
    move = ((("W" in held) - ("S" in held)) * forward +
            (("D" in held) - ("A" in held)) * right +
            (("E" in held) - ("Q" in held)) * WORLD_UP)
    length = float(np.linalg.norm(move))
    if length > 1e-12:
        matrix[:3, 3] += move / length * speed * dt
    return matrix


def yaw_pitch(matrix):
    """Heading (degrees from +X toward +Y) and pitch (degrees above horizontal) of a view."""
    matrix = np.asarray(matrix, dtype=np.float64)
    forward = -matrix[:3, 2] / np.linalg.norm(matrix[:3, 2])
    up = matrix[:3, 1] / np.linalg.norm(matrix[:3, 1])
    # Looking straight down (a top view) the heading is where the view's up points.
    heading = forward[:2] - forward[2] * up[:2]
    yaw = math.degrees(math.atan2(heading[1], heading[0]))
    pitch = math.degrees(math.asin(max(-1.0, min(1.0, forward[2]))))
    return yaw, pitch


def view_rotation(yaw_degrees, pitch_degrees):
    """3x3 world_from_camera rotation for a heading and pitch, with no roll."""
    yaw, pitch = math.radians(yaw_degrees), math.radians(pitch_degrees)
    forward = np.array([math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw),
                        math.sin(pitch)])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    up = np.cross(right, forward)
    return np.column_stack((right, up, -forward))


def turn(matrix, yaw_degrees, pitch_degrees):
    """world_from_camera turned about the camera position: yaw about world Z (positive =
    to the left, seen from above), then pitch about the camera's X (positive = look up),
    clamped to +-PITCH_LIMIT_DEGREES. Roll is removed, as in a first-person game."""
    matrix = np.array(matrix, dtype=np.float64)
    yaw, pitch = yaw_pitch(matrix)
    pitch = max(-PITCH_LIMIT_DEGREES, min(PITCH_LIMIT_DEGREES, pitch + pitch_degrees))
    scale = np.linalg.norm(matrix[:3, :3], axis=0)
    matrix[:3, :3] = view_rotation(yaw + yaw_degrees, pitch) * scale
    return matrix


def mouse_turn(dx_pixels, dy_pixels, degrees_per_pixel=MOUSE_DEGREES_PER_PIXEL):
    """(yaw, pitch) degrees for a mouse drag: right turns right, up looks up."""
    return -dx_pixels * degrees_per_pixel, dy_pixels * degrees_per_pixel

