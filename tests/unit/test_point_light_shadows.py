"""Point lights' cube-map shadows: the six faces' matrices, their caster culling, and the
plan's tiles (numpy only)."""
import numpy as np
import pytest

from csm_engine.core import cascades
from csm_engine.core.frame_layout import MAX_POINT_SHADOWS
from csm_engine.core.shadow_plan import (POINT_FACE_MARGIN_TEXELS, POINT_SHADOW_RESOLUTION,
                                         _plan_point_shadows)
from csm_engine.core.frame import PointLight

LIGHT = np.array([1.0, -2.0, 3.0])
ANGLE = cascades.point_light_face_angle(POINT_SHADOW_RESOLUTION, POINT_FACE_MARGIN_TEXELS)


def face_picked(direction):
    """The face the lighting shader picks for a point in ``direction`` from the light."""
    size = np.abs(direction)
    axis = int(np.argmax(size))
    return 2 * axis + (0 if direction[axis] >= 0 else 1)


def window(face, point):
    light_from_world, clip_from_light = cascades.point_light_face_matrices(
        LIGHT, face, ANGLE, 0.05, 50.0)
    clip = clip_from_light @ light_from_world @ np.append(point, 1.0)
    return clip[:3] / clip[3] * 0.5 + 0.5


def test_faces_are_a_little_wider_than_90_degrees():
    margin = np.tan(0.5 * ANGLE) - 1.0
    texel = 2.0 * np.tan(0.5 * ANGLE) / POINT_SHADOW_RESOLUTION
    assert margin == pytest.approx(POINT_FACE_MARGIN_TEXELS * texel)


@pytest.mark.parametrize("seed", range(5))
def test_every_direction_lands_inside_the_face_the_shader_picks(seed):
    rng = np.random.default_rng(seed)
    for direction in rng.normal(size=(200, 3)):
        point = LIGHT + direction / np.linalg.norm(direction) * rng.uniform(0.2, 40.0)
        w = window(face_picked(direction), point)
        # Inside the 90-degree part: at least the margin away from the map's edges.
        inner = 0.5 - 0.5 / np.tan(0.5 * ANGLE)
        assert np.all(w[:2] >= inner - 1e-9) and np.all(w[:2] <= 1.0 - inner + 1e-9), w
        assert 0.0 < w[2] < 1.0


def test_an_axis_lands_in_its_faces_centre_and_depth_grows_with_distance():
    for face, (axis, sign) in enumerate(cascades.POINT_LIGHT_FACES):
        step = np.zeros(3)
        step[axis] = sign
        near, far = window(face, LIGHT + 2.0 * step), window(face, LIGHT + 20.0 * step)
        assert near[:2] == pytest.approx([0.5, 0.5])
        assert near[2] < far[2]


def test_culling_keeps_boxes_in_the_face_and_within_reach():
    lo = np.array([[3.0, -2.5, 2.5],      # +x of the light, close
                   [-60.0, -2.5, 2.5],    # -x, beyond the light's reach
                   [0.5, -2.5, -10.0],    # straight below (-z)
                   [-1.0, -3.0, 2.0]])    # round the light: every face
    hi = lo + 1.0
    hi[3] = [3.0, -1.0, 4.0]
    picked = np.array([cascades.aabbs_in_point_light_face(lo, hi, LIGHT, face, 30.0)
                       for face in range(6)])       # (face, box)
    assert picked[:, 0].tolist() == [True, False, False, False, False, False]
    assert not picked[:, 1].any()
    assert picked[:, 2].tolist() == [False, False, False, False, False, True]
    assert picked[:, 3].all()


def point(casts_shadow):
    return PointLight(LIGHT, np.ones(3), 10.0, casts_shadow=casts_shadow, clip_start=0.1)


def test_the_plan_gives_six_tiles_to_each_shadowed_light_up_to_the_limit():
    tiles, warnings = [], []
    lights = [point(True)] * (MAX_POINT_SHADOWS + 1) + [point(False)]
    count = _plan_point_shadows(lights, 2048, tiles, warnings)
    assert count == MAX_POINT_SHADOWS and len(tiles) == 6 * MAX_POINT_SHADOWS
    assert all(t.is_perspective and t.resolution == POINT_SHADOW_RESOLUTION for t in tiles)
    assert [t.point_face[1] for t in tiles[:6]] == list(range(6))
    assert any(f"{MAX_POINT_SHADOWS + 1} point lights cast shadows" in w for w in warnings)


def test_lights_without_shadow_get_no_tiles():
    tiles, warnings = [], []
    assert _plan_point_shadows([point(False), point(True)], 2048, tiles, warnings) == 0
    assert tiles == [] and warnings == []
