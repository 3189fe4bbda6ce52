"""Caster culling: which boxes may cast a shadow into a sun cascade or a point light's cube
face.

Owns the conservative box tests (``aabbs_in_cascade``, ``aabb_in_cascade``,
``aabbs_in_point_light_face``), the part of them that depends only on the sun's rotation
(``boxes_in_light_frame``, shared by the cascades of one sun) and the check of the boxes
(``boxes_are_valid``). Wrongly culling a caster is visible and drawing one too many is
not, so every test keeps what it cannot rule out. numpy only.
"""

import numpy as np

from ..checks import vector3
from .light_frusta import POINT_LIGHT_FACES


def aabbs_in_cascade(aabb_min_world, aabb_max_world, cascade, checked=False, rotated=None):
    """Which of N world AABBs may cast into the cascade: (N, 3), (N, 3) -> (N,) bool.

    Conservative: each box is taken to light space as the AABB of its 8 transformed corners
    (computed exactly as centre + |rotation| * half-extent), and it is kept when that
    overlaps the shadow box in x and y and its nearest-to-light point is not beyond the far
    plane. Anything between the light and the box stays: it can shadow the slice.
    ``checked``: the boxes are known to be finite float64 (N, 3) pairs with min <= max
    (``boxes_are_valid``), so they are not checked again for every cascade.
    ``rotated``: ``boxes_in_light_frame`` of these boxes for a light with this cascade's
    rotation (the cascades of one sun share it), so it is not computed again.
    """
    low = np.asarray(aabb_min_world, dtype=np.float64)
    high = np.asarray(aabb_max_world, dtype=np.float64)
    if not checked:
        _check_boxes(low, high)
    return _boxes_in_cascade(low, high, cascade, rotated)


def boxes_in_light_frame(aabb_min_world, aabb_max_world, light_from_world):
    """The part of culling (N, 3) world boxes that depends only on the light's rotation:
    their centres turned into the light's axes (before its translation) and their half
    extents along those axes, as ``aabbs_in_cascade`` computes them."""
    low = np.asarray(aabb_min_world, dtype=np.float64)
    high = np.asarray(aabb_max_world, dtype=np.float64)
    rotation = light_from_world[:3, :3]
    return 0.5 * (low + high) @ rotation.T, 0.5 * (high - low) @ np.abs(rotation).T


def boxes_are_valid(aabb_min_world, aabb_max_world):
    """Whether (N, 3) mins and maxs are what ``aabbs_in_cascade`` accepts."""
    try:
        _check_boxes(np.asarray(aabb_min_world, dtype=np.float64),
                     np.asarray(aabb_max_world, dtype=np.float64))
    except ValueError:
        return False
    return True


def _check_boxes(low, high):
    if low.ndim != 2 or low.shape[1] != 3 or low.shape != high.shape:
        raise ValueError(f"AABB mins and maxs must both be (N, 3), got {low.shape} "
                         f"and {high.shape}")
    bad = ~(np.all(np.isfinite(low), axis=1) & np.all(np.isfinite(high), axis=1)) | \
        np.any(low > high, axis=1)
    if np.any(bad):
        index = int(np.flatnonzero(bad)[0])
        raise ValueError(f"AABB {index} is not a box: min {low[index].tolist()}, "
                         f"max {high[index].tolist()}")


def _boxes_in_cascade(low, high, cascade, rotated=None):
    matrix = cascade.light_from_world
    if rotated is None:
        rotated = boxes_in_light_frame(low, high, matrix)
    centre_turned, extent = rotated
    centre = centre_turned + matrix[:3, 3]      # _transform_points, the rotation done
    near_low, near_high = centre - extent, centre + extent
    # NOTE: a relative tolerance keeps boxes that merely touch the shadow box (or sit a
    # rounding error away) in: wrongly culling a caster is visible, drawing one is not.
    slack = 1e-9 * (np.abs(cascade.box_max - cascade.box_min).max() + np.abs(centre).max(
        axis=1, initial=0.0))
    box_low, box_high = cascade.box_min, cascade.box_max
    overlap_xy = np.all((near_high[:, :2] >= box_low[:2] - slack[:, None])
                        & (near_low[:, :2] <= box_high[:2] + slack[:, None]), axis=1)
    # Light looks down -z: the point nearest the light has the largest z.
    before_far = near_high[:, 2] >= box_low[2] - slack
    return overlap_xy & before_far


def aabb_in_cascade(aabb_min_world, aabb_max_world, cascade):
    """Whether one world AABB may cast into the cascade (see ``aabbs_in_cascade``)."""
    low = vector3("AABB min", aabb_min_world)
    high = vector3("AABB max", aabb_max_world)
    return bool(aabbs_in_cascade(low[None], high[None], cascade)[0])


def aabbs_in_point_light_face(lo, hi, position, face, reach):
    """Which (N, 3) boxes ``lo``..``hi`` may hold casters for cube face ``face`` of a point
    light at ``position`` whose light ends at ``reach``: the box meets the sphere of that
    radius and the face's pyramid (conservative: each of the pyramid's four planes through
    the light has some corner of the box on its inner side)."""
    lo = np.asarray(lo, dtype=np.float64) - position
    hi = np.asarray(hi, dtype=np.float64) - position
    nearest = np.clip(0.0, lo, hi)
    inside = np.einsum("ij,ij->i", nearest, nearest) <= reach * reach
    axis, sign = POINT_LIGHT_FACES[face]
    # Along the look axis, the box's farthest reach in the face's direction.
    along = hi[:, axis] if sign > 0 else -lo[:, axis]
    inside &= along > 0.0
    for other in (a for a in range(3) if a != axis):
        # sign * d[axis] >= +-d[other] somewhere in the box.
        inside &= along - lo[:, other] >= 0.0
        inside &= along + hi[:, other] >= 0.0
    return inside

