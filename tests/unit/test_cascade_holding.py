"""A view keeps its cascades' boxes while they still serve (core/cascades/holding.py, and
``held`` in ``compute_cascades``; the fitted depth range's lead in
``visible_depth_range``).

The flight: a camera 5 m over an endless flat ground, looking 20 degrees down, flying 5 cm
forward per frame. Over a flat ground every screen block shows the same view depths
wherever the camera is, so the depth blocks stay the same while the receivers move with
the camera. A kept box must hold every receiver of its slice (or the shadows there would be
wrong), and must not be much coarser than a fresh fit (or they would be blurred).
"""
import math

import numpy as np
import pytest

from csm_engine.core import cascades
from csm_engine.core.camera import CameraProjection
from csm_engine.core.cascades import depth_blocks_from_reduction, holding

WIDTH, HEIGHT, BLOCK = 320, 180, 16
PROJECTION = CameraProjection(fov_y=math.radians(50), aspect=WIDTH / HEIGHT, clip_start=0.1,
                              clip_end=120.0)
LIGHT = np.array([0.4, 0.3, -0.87])
PITCH = math.radians(20.0)
HEIGHT_M = 5.0
STEP_M = 0.05


def _camera(x, turn_degrees=0.0):
    """world_from_view of the flying camera ``x`` metres along +Y (turned about Z)."""
    turn = math.radians(turn_degrees)
    # Looking along +Y, tipped down by PITCH, then turned about the world's Z.
    look = np.array([math.sin(turn) * math.cos(PITCH), math.cos(turn) * math.cos(PITCH),
                     -math.sin(PITCH)])
    right = np.array([math.cos(turn), -math.sin(turn), 0.0])
    up = np.cross(right, look)
    world_from_view = np.eye(4)
    world_from_view[:3, 0], world_from_view[:3, 1], world_from_view[:3, 2] = right, up, -look
    world_from_view[:3, 3] = (0.0, x, HEIGHT_M)
    return world_from_view


def _ground_blocks(far=60.0):
    """Depth blocks of a flat ground 5 m below the camera (beyond ``far``: background)."""
    rows, cols = math.ceil(HEIGHT / BLOCK), math.ceil(WIDTH / BLOCK)
    _left, _right, bottom, top = PROJECTION.view_window()
    pairs = np.empty((rows, cols, 2))
    for row in range(rows):
        depths = []
        for edge in (row, row + 1):
            y = bottom + (top - bottom) * min(edge * BLOCK, HEIGHT) / HEIGHT
            # The ray (x, y, -1) in view space dips by sin(PITCH) - y cos(PITCH) per unit
            # of view depth; it meets the ground after 5 m of dip.
            dip = math.sin(PITCH) - y * math.cos(PITCH)
            depths.append(HEIGHT_M / dip if dip > 1e-6 else math.inf)
        near, far_edge = min(depths), max(depths)
        pairs[row] = (near, min(far_edge, far)) if near < far else (3.0e38, 0.0)
    return depth_blocks_from_reduction(pairs, BLOCK, WIDTH, HEIGHT)


BLOCKS = _ground_blocks()


def _fit(world_from_view, held=None, depth_blocks=BLOCKS):
    depth_range = None
    if depth_blocks is not None:
        depth_range = cascades.visible_depth_range(depth_blocks[2].min(), depth_blocks[3].max())
    return cascades.compute_cascades(world_from_view, PROJECTION, LIGHT, count=3,
                                     shadow_distance=60.0, depth_range=depth_range,
                                     depth_blocks=depth_blocks, held=held,
                                     scene_bounds=(np.array([-200.0, -200.0, -1.0]),
                                                   np.array([200.0, 400.0, 3.0])))


def _receivers_inside(fit, world_from_view, depth_blocks):
    """Whether the box of ``fit`` holds every receiver of its slice (the slice's corners
    when there are no depth blocks)."""
    rotation = cascades.light_view_matrix(LIGHT)
    near = fit.split_near if not math.isnan(fit.split_near) else PROJECTION.clip_start
    if depth_blocks is None:
        corners = cascades.frustum_slice_corners(world_from_view, PROJECTION, near,
                                                 fit.split_far)
        xy = corners @ rotation[:2, :3].T
        low, high = xy.min(axis=0), xy.max(axis=0)
    else:
        square = cascades.receiver_square(world_from_view, PROJECTION, depth_blocks, near,
                                          fit.split_far, rotation, exact=True)
        if square is None:
            return True
        low, high = square[0] - square[1], square[0] + square[1]
    centre, half = holding.box_centre_xy(fit), fit.box_max[:2]
    return bool(np.all(low >= centre - half - 1e-9) and np.all(high <= centre + half + 1e-9))


def _flight(frames, depth_blocks=BLOCKS, turn_degrees=0.0):
    """Each frame's cascades, each planned with the frame before's as ``held``."""
    held, result = None, []
    for frame in range(frames):
        fitted = _fit(_camera(frame * STEP_M, frame * turn_degrees), held, depth_blocks)
        held = fitted.cascades
        result.append(fitted)
    return result


def _kept_all(before, after):
    return all(a.clip_from_world.tobytes() == b.clip_from_world.tobytes()
               for a, b in zip(before.cascades, after.cascades))


@pytest.mark.parametrize("depth_blocks", [BLOCKS, None], ids=["fit to visible", "whole slice"])
def test_a_flying_camera_keeps_its_boxes_most_frames_and_they_hold_every_receiver(
        depth_blocks):
    frames = _flight(40, depth_blocks, turn_degrees=0.1)
    kept = sum(_kept_all(a, b) for a, b in zip(frames, frames[1:]))
    assert kept >= 0.6 * (len(frames) - 1), f"{kept} of {len(frames) - 1} frames kept"
    for index, fitted in enumerate(frames):
        camera = _camera(index * STEP_M, index * 0.1)
        fresh = _fit(camera, None, depth_blocks)
        for fit, fresh_fit in zip(fitted.cascades, fresh.cascades):
            assert _receivers_inside(fit, camera, depth_blocks), f"frame {index}"
            # Never much coarser than this frame's own first fit: the 1/32 room of a
            # refit and the 1/16 a kept box may lose, and the rounding of either.
            assert np.all(fit.texel_size_xy <= 1.15 * fresh_fit.texel_size_xy)


def test_a_refitted_box_is_put_ahead_of_the_receivers(monkeypatch):
    led = _flight(40, turn_degrees=0.1)
    monkeypatch.setattr(holding, "LEAD_SHARE", 0.0)
    centred = _flight(40, turn_degrees=0.1)
    kept_led = sum(_kept_all(a, b) for a, b in zip(led, led[1:]))
    kept_centred = sum(_kept_all(a, b) for a, b in zip(centred, centred[1:]))
    assert kept_led > kept_centred


def test_a_first_fit_is_the_sharpest_and_does_not_depend_on_a_held_box():
    camera = _camera(0.0)
    first = _fit(camera)
    rotation = cascades.light_view_matrix(LIGHT)
    for fit in first.cascades:
        receivers = cascades.receiver_square(camera, PROJECTION, BLOCKS, fit.split_near,
                                             fit.split_far, rotation, exact=True)
        _centre, half = cascades.rounded_square(receivers)
        # The receivers' half widths rounded up, and the texel of slack for the snap.
        assert np.allclose(fit.box_max[:2], half * fit.resolution / (fit.resolution - 1),
                           rtol=2.0 ** -8)


def test_a_box_much_coarser_than_a_fresh_fit_or_missing_receivers_is_refitted():
    camera = _camera(0.0)
    wide = _fit(camera)
    # The camera comes down close to the ground: the receivers shrink, the held box would
    # hold them but is far too coarse.
    close = _fit(camera, wide.cascades, _ground_blocks(far=15.0))
    fresh = _fit(camera, None, _ground_blocks(far=15.0))
    for held, fit, fresh_fit in zip(wide.cascades, close.cascades, fresh.cascades):
        assert fit.clip_from_world.tobytes() != held.clip_from_world.tobytes()
        assert np.all(fit.texel_size_xy <= 1.1 * fresh_fit.texel_size_xy)
    # A camera 30 m on: nothing it sees is in the boxes of before.
    moved = _fit(_camera(30.0), wide.cascades)
    for held, fit in zip(wide.cascades, moved.cascades):
        assert fit.clip_from_world.tobytes() != held.clip_from_world.tobytes()
        assert _receivers_inside(fit, _camera(30.0), BLOCKS)


def test_another_light_direction_or_resolution_refits_every_box():
    camera = _camera(0.0)
    first = _fit(camera)
    turned = cascades.compute_cascades(camera, PROJECTION, LIGHT + np.array([0.01, 0, 0]),
                                       count=3, shadow_distance=60.0, held=first.cascades)
    finer = cascades.compute_cascades(camera, PROJECTION, LIGHT, count=3, shadow_distance=60.0,
                                      base_resolution=4096, held=first.cascades)
    for before, a, b in zip(first.cascades, turned.cascades, finer.cascades):
        assert a.light_from_world.tobytes() != before.light_from_world.tobytes()
        assert b.resolution == 2 * before.resolution


def test_the_fitted_depth_range_leads_one_step_the_way_it_was_left():
    step = 2.0 ** (1.0 / 8.0)
    first = cascades.visible_depth_range(10.0, 50.0)
    assert cascades.visible_depth_range(10.0 * 1.001, 50.0, previous=first) == first
    nearer = cascades.visible_depth_range(first[0] * 0.99, 50.0, previous=first)
    plain = cascades.visible_depth_range(first[0] * 0.99, 50.0)
    assert nearer[0] == pytest.approx(plain[0] / step) and nearer[1] == plain[1]
    farther = cascades.visible_depth_range(10.0, first[1] * 1.01, previous=first)
    plain = cascades.visible_depth_range(10.0, first[1] * 1.01)
    assert farther[1] == pytest.approx(plain[1] * step) and farther[0] == plain[0]
