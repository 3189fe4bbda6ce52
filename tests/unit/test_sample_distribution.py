"""Fitting cascades to what the camera sees (core/cascades/receivers.py:
depth_blocks_from_reduction, visible_depth_range, receiver_square; core/frame_block.py:
window_normal_from_world)."""
import math

import numpy as np
import pytest

from csm_engine.core import cascades
from csm_engine.core.camera import CameraProjection
from csm_engine.core.cascades import depth_blocks_from_reduction
from csm_engine.core.frame_block import WINDOW_FROM_CLIP, window_normal_from_world

PROJECTION = CameraProjection(kind="PERSP", fov_y=math.radians(50), aspect=16 / 9,
                              clip_start=0.1, clip_end=500.0)
ROTATION = cascades.light_view_matrix(np.array([0.3, 0.2, -1.0]))


def _blocks(near, far, rows=9, cols=16):
    pairs = np.empty((rows, cols, 2))
    pairs[..., 0], pairs[..., 1] = near, far
    pairs[0, 0] = (3.0e38, 0.0)                     # one block of background
    return depth_blocks_from_reduction(pairs, 16, cols * 16, rows * 16)


def test_blocks_skip_background_and_cover_the_screen():
    low, high, nearest, farthest = _blocks(10.0, 40.0)
    assert len(nearest) == 9 * 16 - 1
    assert low.min() == pytest.approx(-1.0) and high.max() == pytest.approx(1.0)
    assert np.all(nearest == 10.0) and np.all(farthest == 40.0)


def test_receiver_rectangle_holds_every_receiver_of_the_slice():
    world_from_view = np.eye(4)
    world_from_view[:3, 3] = (5.0, -3.0, 2.0)
    blocks = _blocks(10.0, 40.0)
    centre, half = cascades.receiver_square(world_from_view, PROJECTION, blocks, 15.0, 30.0,
                                            ROTATION)
    # Points the slice shows: every pixel corner at depths 15 and 30.
    left, right, bottom, top = PROJECTION.view_window()
    points = []
    for x in np.linspace(left, right, 9):
        for y in np.linspace(bottom, top, 9):
            for d in (15.0, 30.0):
                points.append(world_from_view[:3, :3] @ (x * d, y * d, -d) +
                              world_from_view[:3, 3])
    rot = np.asarray(points) @ ROTATION[:3, :3].T[:, :2]
    assert np.all(rot >= centre - half - 1e-9) and np.all(rot <= centre + half + 1e-9)
    # ... and no more than the slice needs (rounding up costs at most 1/8).
    assert np.all(half <= 1.13 * 0.5 * (rot.max(axis=0) - rot.min(axis=0)))
    assert cascades.receiver_square(world_from_view, PROJECTION, blocks, 50.0, 60.0,
                                    ROTATION) is None


def test_fitted_cascades_use_smaller_texels_than_the_sphere():
    blocks = _blocks(20.0, 60.0)
    plain = cascades.compute_cascades(np.eye(4), PROJECTION, np.array([0.3, 0.2, -1.0]))
    fitted = cascades.compute_cascades(np.eye(4), PROJECTION, np.array([0.3, 0.2, -1.0]),
                                       depth_range=(20.0, 60.0), depth_blocks=blocks)
    assert fitted.splits[0] == 20.0 and fitted.splits[-1] == 60.0
    for a, b in zip(plain.cascades, fitted.cascades):
        assert b.texel_size_world < a.texel_size_world


def test_unstabilized_cascades_fit_the_receivers_exactly():
    """Stabilize off is the tightest fit: each cascade's box is its slice's box cut to the
    receivers' exact (unrounded) rectangle, never wider than the stabilized fit, and it
    still holds every receiver the slice shows (before, Stabilize off ignored the
    receivers and was looser than on)."""
    sun = np.array([0.3, 0.2, -1.0])
    world_from_view = np.eye(4)
    world_from_view[:3, 3] = (5.0, -3.0, 2.0)
    # The receivers only fill the screen's lower 4 block rows of 9 (sky above).
    rows, cols = 9, 16
    pairs = np.empty((rows, cols, 2))
    pairs[..., 0], pairs[..., 1] = 20.0, 60.0
    pairs[rows // 2:] = (3.0e38, 0.0)
    blocks = depth_blocks_from_reduction(pairs, 16, cols * 16, rows * 16)
    kwargs = dict(depth_range=(20.0, 60.0), depth_blocks=blocks)
    stable = cascades.compute_cascades(world_from_view, PROJECTION, sun, **kwargs)
    tight = cascades.compute_cascades(world_from_view, PROJECTION, sun, stabilize=False,
                                      **kwargs)
    no_receivers = cascades.compute_cascades(world_from_view, PROJECTION, sun,
                                             stabilize=False, depth_range=(20.0, 60.0))
    rotation = cascades.light_view_matrix(sun)
    for s, t, loose in zip(stable.cascades, tight.cascades, no_receivers.cascades):
        width_t, width_s = t.box_max[:2] - t.box_min[:2], s.box_max[:2] - s.box_min[:2]
        assert np.all(width_t <= width_s + 1e-9)
        # The rectangle is exact: the box is the receivers' extent, not rounded up.
        centre, half = cascades.receiver_square(world_from_view, PROJECTION, blocks,
                                                t.split_near, t.split_far, rotation,
                                                exact=True)
        assert np.all(width_t <= 2.0 * half + 1e-9)
        # Most of the screen is sky: the receivers need visibly less than the slice.
        assert (width_t[0] * width_t[1] <
                0.9 * np.prod(loose.box_max[:2] - loose.box_min[:2]))
        # Every receiver corner of the slice (the screen's lower 4 of 9 block rows) is
        # inside.
        left, right, bottom, top = PROJECTION.view_window()
        points = [world_from_view[:3, :3] @ (x * d, y * d, -d) + world_from_view[:3, 3]
                  for x in np.linspace(left, right, 9)
                  for y in np.linspace(bottom, bottom + (top - bottom) * 4 / 9, 5)
                  for d in (max(t.split_near, 20.0), t.split_far)]
        in_light = (t.light_from_world[:2, :3] @ np.asarray(points).T +
                    t.light_from_world[:2, 3:4]).T
        assert np.all(in_light >= t.box_min[:2] - 1e-6)
        assert np.all(in_light <= t.box_max[:2] + 1e-6)


def test_window_normal_gives_the_receiver_planes_depth_slope():
    fit = cascades.compute_cascades(np.eye(4), PROJECTION, np.array([0.3, 0.2, -1.0]),
                                    count=1).cascades[0]

    class Tile:
        is_perspective = False
        clip_from_world = fit.clip_from_world

    normal_from_world = window_normal_from_world(Tile)
    window_from_world = WINDOW_FROM_CLIP @ fit.clip_from_world
    # A tilted plane through p: moving along it changes window depth as the slope says.
    n = np.array([0.2, -0.3, 1.0])
    n /= np.linalg.norm(n)
    p = np.array([1.0, 2.0, -20.0])
    along = np.cross(n, [1.0, 0.0, 0.0])
    w0 = window_from_world @ np.append(p, 1.0)
    w1 = window_from_world @ np.append(p + along, 1.0)
    wn = normal_from_world[:3, :3] @ n
    predicted = -(wn[0] * (w1[0] - w0[0]) + wn[1] * (w1[1] - w0[1])) / wn[2]
    assert w1[2] - w0[2] == pytest.approx(predicted, rel=1e-9, abs=1e-12)


def _corner_bounds(world_from_view, projection, blocks, near_depth, far_depth, rotation):
    """The receivers' light-frame xy bounds the plain way: every block's 8 corners."""
    ndc_low, ndc_high, nearest, farthest = blocks
    inside = (farthest >= near_depth) & (nearest <= far_depth)
    d0 = np.maximum(nearest[inside], near_depth)
    d1 = np.minimum(farthest[inside], far_depth)
    left, right, bottom, top = projection.view_window()
    corners = []
    for x_ndc in (ndc_low[inside, 0], ndc_high[inside, 0]):
        for y_ndc in (ndc_low[inside, 1], ndc_high[inside, 1]):
            x = left + (x_ndc + 1.0) * 0.5 * (right - left)
            y = bottom + (y_ndc + 1.0) * 0.5 * (top - bottom)
            for d in (d0, d1):
                scale = d if projection.is_perspective else 1.0
                corners.append(np.stack([x * scale, y * scale, -d], axis=-1))
    view = np.concatenate(corners)
    world = view @ world_from_view[:3, :3].T + world_from_view[:3, 3]
    xy = world @ rotation[:2, :3].T
    return xy.min(axis=0), xy.max(axis=0)


@pytest.mark.parametrize("projection", [
    PROJECTION,
    CameraProjection(kind="ORTHO", ortho_height=20.0, aspect=16 / 9, clip_start=-30.0,
                     clip_end=300.0)])
def test_receiver_rectangle_bounds_equal_every_corners_bounds(projection):
    """receiver_square finds each axis's extremes per block without forming its 8
    corners; the bounds must be those of the corners (the rectangle's centre is their
    middle and each half width is rounded up from half their span)."""
    rng = np.random.default_rng(7)
    for trial in range(20):
        q, r = np.linalg.qr(rng.normal(size=(3, 3)))
        q = q * np.sign(np.diag(r))
        if np.linalg.det(q) < 0:
            q[:, 0] *= -1
        world_from_view = np.eye(4)
        world_from_view[:3, :3], world_from_view[:3, 3] = q, rng.normal(size=3) * 50.0
        rotation = cascades.light_view_matrix(rng.normal(size=3))
        low = rng.uniform(-1.0, 0.95, size=(500, 2))
        nearest = rng.uniform(0.5 if projection.is_perspective else -20.0, 60.0, size=500)
        blocks = (low, low + rng.uniform(0.0, 0.05, size=(500, 2)), nearest,
                  nearest + rng.uniform(0.0, 20.0, size=500))
        centre, half = cascades.receiver_square(world_from_view, projection, blocks,
                                                10.0, 40.0, rotation)
        lo, hi = _corner_bounds(world_from_view, projection, blocks, 10.0, 40.0, rotation)
        np.testing.assert_allclose(centre, 0.5 * (lo + hi), rtol=1e-12, atol=1e-10)
        assert np.all(half >= 0.5 * (hi - lo)) and np.all(half <= (hi - lo) + 1e-9)


def test_a_views_receiver_cache_gives_what_computing_afresh_gives():
    """A view keeps its per-block terms (``ReceiverTermsCache``) from frame to frame; with
    the blocks, the camera, the lens or the light changed between frames, every rectangle
    must be the one computed without it."""
    cache = cascades.ReceiverTermsCache()
    narrow = CameraProjection(kind="PERSP", fov_y=math.radians(30), aspect=16 / 9,
                              clip_start=0.1, clip_end=500.0)
    moved = np.eye(4)
    moved[:3, 3] = (3.0, -1.0, 0.5)
    turned = cascades.light_view_matrix(np.array([-0.4, 0.1, -1.0]))
    near_blocks, far_blocks = _blocks(10.0, 40.0), _blocks(12.0, 35.0)
    # A view the scene fills: every frame's blocks share the same read-only corner arrays.
    filled = [depth_blocks_from_reduction(np.full((9, 16, 2), (near, 40.0)), 16, 256, 144)
              for near in (10.0, 11.0)]
    assert filled[0][0] is filled[1][0] and not filled[0][0].flags.writeable
    frames = [(np.eye(4), PROJECTION, filled[0], ROTATION),
              (np.eye(4), narrow, filled[1], ROTATION),
              (moved, narrow, filled[1], ROTATION),
              (moved, PROJECTION, filled[0], turned),(np.eye(4), PROJECTION, near_blocks, ROTATION),
              (np.eye(4), PROJECTION, near_blocks, ROTATION),      # nothing changed
              (moved, PROJECTION, near_blocks, ROTATION),
              (moved, narrow, near_blocks, ROTATION),
              (moved, narrow, far_blocks, ROTATION),
              (moved, narrow, far_blocks, turned),
              (np.eye(4), PROJECTION, near_blocks, ROTATION)]
    for world_from_view, projection, blocks, rotation in frames:
        for near, far in ((10.0, 20.0), (15.0, 30.0)):
            kept = cascades.receiver_square(world_from_view, projection, blocks, near, far,
                                            rotation, cache=cache)
            fresh = cascades.receiver_square(world_from_view, projection, blocks, near, far,
                                             rotation)
            np.testing.assert_array_equal(kept[0], fresh[0])
            np.testing.assert_array_equal(kept[1], fresh[1])
