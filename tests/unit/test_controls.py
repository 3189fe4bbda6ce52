"""First-person camera and sun-angle maths (``csm_engine.core.controls``), without Blender."""
import math

import numpy as np
import pytest

from csm_engine.core import controls


# ------------------------------------------------------------------------ movement math
def _camera(yaw=0.0, pitch=0.0, location=(1.0, 2.0, 3.0)):
    matrix = np.eye(4)
    matrix[:3, :3] = controls.view_rotation(yaw, pitch)
    matrix[:3, 3] = location
    return matrix


def test_w_moves_along_the_view_direction_and_s_back():
    start = _camera(yaw=30.0, pitch=-20.0)
    forward = -start[:3, 2]
    moved = controls.step(start, {"W"}, 0.5, 4.0)
    np.testing.assert_allclose(moved[:3, 3] - start[:3, 3], forward * 2.0, atol=1e-12)
    back = controls.step(start, {"S"}, 0.5, 4.0)
    np.testing.assert_allclose(back[:3, 3] - start[:3, 3], -forward * 2.0, atol=1e-12)
    np.testing.assert_allclose(moved[:3, :3], start[:3, :3])   # moving never turns


def test_a_d_strafe_and_q_e_follow_world_up_even_when_looking_down():
    start = _camera(yaw=90.0, pitch=-60.0)      # facing +Y, looking down
    right = controls.step(start, {"D"}, 1.0, 1.0)[:3, 3] - start[:3, 3]
    np.testing.assert_allclose(right, [1.0, 0.0, 0.0], atol=1e-12)
    left = controls.step(start, {"A"}, 1.0, 1.0)[:3, 3] - start[:3, 3]
    np.testing.assert_allclose(left, [-1.0, 0.0, 0.0], atol=1e-12)
    up = controls.step(start, {"E"}, 2.0, 1.5)[:3, 3] - start[:3, 3]
    np.testing.assert_allclose(up, [0.0, 0.0, 3.0], atol=1e-12)
    down = controls.step(start, {"Q"}, 1.0, 1.0)[:3, 3] - start[:3, 3]
    np.testing.assert_allclose(down, [0.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(controls.step(start, {"W", "S"}, 1.0, 1.0), start)
    diagonal = controls.step(start, {"W", "D"}, 1.0, 2.0)[:3, 3] - start[:3, 3]
    assert np.linalg.norm(diagonal) == pytest.approx(2.0)


def test_yaw_turns_about_world_z_and_pitch_is_clamped():
    start = _camera(yaw=0.0, pitch=10.0)
    turned = controls.turn(start, 90.0, 0.0)
    np.testing.assert_allclose(turned[:3, 3], start[:3, 3])      # turns in place
    forward = -turned[:3, 2]
    np.testing.assert_allclose(forward, [0.0, math.cos(math.radians(10)),
                                         math.sin(math.radians(10))], atol=1e-12)
    assert turned[2, 0] == pytest.approx(0.0, abs=1e-12)         # no roll: X stays level
    up = controls.turn(start, 0.0, 500.0)
    assert controls.yaw_pitch(up)[1] == pytest.approx(controls.PITCH_LIMIT_DEGREES)
    assert up[2, 1] > 0.0                                         # camera up never flips
    down = controls.turn(start, 0.0, -500.0)
    assert controls.yaw_pitch(down)[1] == pytest.approx(-controls.PITCH_LIMIT_DEGREES)
    yaw, pitch = controls.mouse_turn(10, 5)
    assert yaw < 0.0 < pitch            # drag right turns right, drag up looks up


def test_turning_a_top_view_keeps_its_heading():
    top = np.eye(4)     # Blender's top view: looking down -Z with +Y up on screen
    yaw, pitch = controls.yaw_pitch(top)
    assert (yaw, pitch) == (pytest.approx(90.0), pytest.approx(-90.0))
    turned = controls.turn(top, 0.0, 0.0)
    assert -turned[1, 2] > 0.0          # now looks slightly towards +Y, as the screen's up


def test_azimuth_elevation_round_trip_without_blender():
    for azimuth, elevation in ((0.0, 45.0), (-113.2, 30.0), (90.0, 5.0), (170.0, 80.0)):
        travel = controls.travel_from_azimuth_elevation(azimuth, elevation)
        assert np.linalg.norm(travel) == pytest.approx(1.0)
        back = controls.azimuth_elevation_from_travel(travel)
        assert back == (pytest.approx(azimuth), pytest.approx(elevation))
    assert controls.azimuth_elevation_from_travel((0.0, 0.0, -1.0))[1] == pytest.approx(90.0)
