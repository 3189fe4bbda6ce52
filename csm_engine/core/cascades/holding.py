"""Keeping a viewport's cascade box from one frame to the next while it still serves (a
final render keeps nothing: its boxes are quantized, ``quantizing``).

Owns ``CascadeNeed`` (what one cascade must cover this frame: the receivers' rectangle in
the light's rotated frame and the depths along the light its box must span),
``hold_cascade`` (the box of the frame before, kept while it holds the need and is not
much coarser than a fresh fit) and ``lead_box`` (a refitted box moved ahead of the
receivers in the direction they drift). A kept box gives the same light matrix, so the
shadow pass keeps its tile (``render/shadow_atlas.py``, tile signatures): a camera that
moves a little redraws no shadow map. Plain functions of their arguments; what is kept
from the frame before is passed in (``view_state.ShadowViewState``). numpy only.
"""

import dataclasses
from typing import NamedTuple

import numpy as np

from .stabilization import snap_to_texel_grid

# NOTE: a fresh fit is at most this much coarser (per axis) than the best fit of this frame
# (texel size over the fresh one's), or it is refitted: the price of keeping a box, in
# texel density, is below this share (docs/cascades.md).
HOLD_COARSER_AT_MOST = 1.0 / 16.0
# Of the room a refitted box has around the receivers on each axis, the share it is put
# ahead of them in the direction they drifted since the box before (the rest stays
# behind, for a camera that turns back a little).
LEAD_SHARE = 0.75


class CascadeNeed(NamedTuple):
    """What one cascade must cover this frame, in the light's rotated frame (light axes,
    world origin; depth along the light is -z):

    - ``low_xy``, ``high_xy``: the receivers' rectangle (the slice's corners, or its
      visible receivers with Fit to Visible Depth), unrounded;
    - ``near_depth``: the depth the box's near plane must reach toward the light (the
      occluder margin included): a kept box's near plane is at most ``depth_slack``
      nearer;
    - ``far_depth``: the depth its far plane must reach: a kept box's at most
      ``depth_slack`` farther;
    - ``depth_slack``: scene units of depth a kept box may have beyond the need (its depth
      range costs no texels, only which casters it sees).
    """
    low_xy: np.ndarray
    high_xy: np.ndarray
    near_depth: float
    far_depth: float
    depth_slack: float


def box_centre_xy(fit):
    """A fit's box centre in the light's rotated frame (light_from_world's translation is
    minus the centre)."""
    return -fit.light_from_world[:2, 3]


def box_depths(fit):
    """(near plane, far plane) of a fit's box as depths along the light (rotated frame)."""
    near = float(fit.light_from_world[2, 3])
    return near, near + float(fit.far)


def holds(held, fresh, need):
    """Whether the ``held`` ``CascadeFit`` (the frame before's) can stand for ``fresh``
    (this frame's fit): the same light rotation and resolution, both stabilized, its box
    holds ``need`` (``CascadeNeed``) on every axis and its texels are at most
    ``HOLD_COARSER_AT_MOST`` larger than ``fresh``'s."""
    if held is None or not (held.stabilized and fresh.stabilized) or \
            held.resolution != fresh.resolution or \
            held.light_from_world[:3, :3].tobytes() != fresh.light_from_world[:3, :3].tobytes():
        return False
    if np.any(np.asarray(held.texel_size_xy) >
              np.asarray(fresh.texel_size_xy) * (1.0 + HOLD_COARSER_AT_MOST)):
        return False
    centre, half = box_centre_xy(held), held.box_max[:2]
    if np.any(need.low_xy < centre - half) or np.any(need.high_xy > centre + half):
        return False
    near, far = box_depths(held)
    return need.near_depth - need.depth_slack <= near <= need.near_depth and \
        need.far_depth <= far <= need.far_depth + need.depth_slack


def hold_cascade(held, fresh, need):
    """``held`` in place of ``fresh`` when it ``holds``, else ``fresh``; the returned fit
    carries ``fresh``'s slice (its split distances and receiver rectangle)."""
    if not holds(held, fresh, need):
        return fresh
    return dataclasses.replace(held, split_near=fresh.split_near, split_far=fresh.split_far,
                               receiver_rectangle=fresh.receiver_rectangle)


def lead_box(centre_xy, half_xy, texel_xy, need, previous_need_xy):
    """Where to put a refitted box of half widths ``half_xy`` that ``centre_xy`` (snapped to
    ``texel_xy``) would put: ahead of the receivers (``need``) in the direction they moved
    since the box before was fitted (its need's centre, ``previous_need_xy``), by
    ``LEAD_SHARE`` of the room the box has around them, snapped to whole texels. Without a
    box before, or where the receivers fill the box, it stays at ``centre_xy``; on an axis
    where they moved less than a texel, it is centred on them.

    NOTE: a camera that flies on moves its receivers the same way frame after frame; a box
    centred on them is left after half its room, one put ahead only after all of it."""
    if previous_need_xy is None:
        return centre_xy
    need_centre = 0.5 * (need.low_xy + need.high_xy)
    room = half_xy - 0.5 * (need.high_xy - need.low_xy) - texel_xy
    if np.any(room <= 0.0):
        return centre_xy
    moved = need_centre - np.asarray(previous_need_xy, dtype=np.float64)
    direction = np.where(np.abs(moved) > texel_xy, np.sign(moved), 0.0)
    # The snap moves it by half a texel at most, which the texel of room left absorbs.
    return snap_to_texel_grid(need_centre + direction * LEAD_SHARE * room, texel_xy)
