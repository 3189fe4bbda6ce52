"""A final render's cascade boxes are step functions of their receivers
(core/cascades/quantizing.py, ``quantize`` in ``compute_cascades``).

The flight of ``test_cascade_holding``: a camera 5 m over an endless flat ground, looking
20 degrees down, 5 cm forward and 0.1 degree of turn per frame. Every frame is fitted
afresh (no ``held``), as each frame of a final-render animation is: the same inputs must
give the same boxes whatever was fitted before, consecutive frames must mostly give the
same boxes (so their shadow maps are kept), and every box must hold every receiver of its
slice and not be much coarser than the fit a render made before quantization (or shadows
would be missing or blurred).
"""
import itertools

import numpy as np
import pytest

from csm_engine.core import cascades
from csm_engine.core.cascades import holding, quantizing
from tests.unit.test_cascade_holding import (BLOCKS, LIGHT, PROJECTION, STEP_M, _camera,
                                             _receivers_inside)

SCENE_BOUNDS = (np.array([-200.0, -200.0, -1.0]), np.array([200.0, 400.0, 3.0]))


def _fit(world_from_view, depth_blocks=BLOCKS, quantize=True, held=None):
    depth_range = None
    if depth_blocks is not None:
        depth_range = cascades.visible_depth_range(depth_blocks[2].min(),
                                                   depth_blocks[3].max())
    return cascades.compute_cascades(world_from_view, PROJECTION, LIGHT, count=3,
                                     shadow_distance=60.0, depth_range=depth_range,
                                     depth_blocks=depth_blocks, held=held,
                                     scene_bounds=SCENE_BOUNDS, quantize=quantize)


def _flight_camera(frame):
    return _camera(frame * STEP_M, frame * 0.1)


def _same(a, b):
    return a.clip_from_world.tobytes() == b.clip_from_world.tobytes()


@pytest.mark.parametrize("depth_blocks", [BLOCKS, None], ids=["fit to visible", "whole slice"])
def test_a_flight_keeps_most_boxes_and_each_holds_its_receivers(depth_blocks):
    frames = [_fit(_flight_camera(frame), depth_blocks) for frame in range(40)]
    pairs = [(a, b) for before, after in zip(frames, frames[1:])
             for a, b in zip(before.cascades, after.cascades)]
    kept = sum(_same(a, b) for a, b in pairs)
    # Before quantization every fresh fit moved with the camera: (almost) none was kept.
    assert kept >= 0.7 * len(pairs), f"{kept} of {len(pairs)} boxes kept"
    plain = [_fit(_flight_camera(frame), depth_blocks, quantize=False) for frame in range(40)]
    assert sum(_same(a, b) for before, after in zip(plain, plain[1:])
               for a, b in zip(before.cascades, after.cascades)) < 0.5 * len(pairs)
    for frame, fitted in enumerate(frames):
        camera = _flight_camera(frame)
        for fit in fitted.cascades:
            assert _receivers_inside(fit, camera, depth_blocks), f"frame {frame}"


def test_the_box_holds_the_depths_the_slice_needs():
    camera = _flight_camera(7)
    rotation = cascades.light_view_matrix(LIGHT)[:3, :3]
    corners = np.array(list(itertools.product(*zip(*SCENE_BOUNDS))))
    scene_near = float(-(corners @ rotation[2]).max())
    for fit in _fit(camera).cascades:
        near, far = holding.box_depths(fit)
        sphere_depth = -float(rotation[2] @ fit.sphere_center_world)
        # Toward the light: past every caster of the scene; away: past the slice.
        assert near <= scene_near + 1e-9
        assert far >= sphere_depth + fit.sphere_radius - 1e-9
        # ... and not far past either (depth precision).
        assert far - near <= 1.25 * (sphere_depth + fit.sphere_radius - near) + 1e-9


def test_the_same_inputs_give_the_same_boxes_whatever_came_before():
    camera = _flight_camera(13)
    alone = _fit(camera)
    after_others = [_fit(_flight_camera(frame)) for frame in (0, 12, 30)][-1]
    again = _fit(camera, held=after_others.cascades)
    assert [f.clip_from_world.tobytes() for f in alone.cascades] == \
        [f.clip_from_world.tobytes() for f in again.cascades]
    # ``held`` is not read when quantizing; it is when not (the check can fail).
    held = _fit(_flight_camera(12), quantize=False).cascades
    assert [f.clip_from_world.tobytes() for f in _fit(camera, quantize=False, held=held)
            .cascades] != [f.clip_from_world.tobytes()
                           for f in _fit(camera, quantize=False).cascades]


def test_density_cost_is_bounded():
    """Texel size of a quantized box over a plain first fit's (what a render drew before)
    and over the receivers' own extent (the sharpest a box could be)."""
    rotation = cascades.light_view_matrix(LIGHT)
    over_plain, over_exact = [], []
    for frame in range(40):
        camera = _flight_camera(frame)
        for fit, plain in zip(_fit(camera).cascades, _fit(camera, quantize=False).cascades):
            over_plain.append(np.max(fit.texel_size_xy / plain.texel_size_xy))
            receivers = cascades.receiver_square(camera, PROJECTION, BLOCKS, fit.split_near,
                                                 fit.split_far, rotation, exact=True)
            over_exact.append(np.max(fit.box_max[:2] / receivers[1]))
    # The ladder's step, the grid's room, the texel of slack and the 9-bit texel.
    ladder = 2.0 ** (1 / quantizing.HALF_WIDTH_STEPS_PER_OCTAVE)
    room = 1.0 + 1.0 / quantizing.CENTRE_STEPS_PER_BOX
    assert max(over_exact) <= ladder * room * 1.01
    assert np.mean(over_plain) <= 1.045 and max(over_plain) <= 1.07


def test_boxes_sit_on_whole_texels_of_a_grid_fixed_in_light_space():
    for frame in (0, 5, 21):
        for fit in _fit(_flight_camera(frame)).cascades:
            position = -fit.light_from_world[:2, 3] / fit.texel_size_xy
            assert np.array_equal(position, np.round(position))


def test_ladder_and_grid():
    assert quantizing.ladder_half_width(1.0) == 1.0
    step = 2.0 ** (1 / quantizing.HALF_WIDTH_STEPS_PER_OCTAVE)
    assert quantizing.ladder_half_width(1.001) == pytest.approx(step)
    assert quantizing.ladder_half_width(step * 0.999) == pytest.approx(step)
    # Receivers that drift less than a grid step (1/32 of the box) keep the box when they
    # start on a grid point; each box holds its rectangle.
    centre, texel = quantizing.quantized_box((-1.0, -1.0), (1.0, 1.0), 1024)
    width = 1024 * texel[0]
    for shift in np.linspace(0.0, 0.49 * width / quantizing.CENTRE_STEPS_PER_BOX, 7):
        moved = quantizing.quantized_box((-1.0 + shift, -1.0), (1.0 + shift, 1.0), 1024)
        assert np.array_equal(moved[0], centre) and np.array_equal(moved[1], texel)
        half = 0.5 * 1024 * moved[1]
        assert np.all(moved[0] - half <= (-1.0 + shift, -1.0))
        assert np.all(moved[0] + half >= (1.0 + shift, 1.0))
    near, far = quantizing.quantized_depths(3.3, 10.1, 16.0)
    assert (near, far) == (3.0, 11.0)
    assert quantizing.quantized_depths(3.7, 10.9, 16.0) == (near, far)
