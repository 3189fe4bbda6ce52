"""The one camera model (``csm_engine.core.camera``): projection round trips, the clip range
decoded in one place, and pixel centres back to world space."""
import math

import numpy as np
import pytest

from csm_engine.core.camera import CameraProjection, CameraView, as_projection, world_positions


def _look_down_minus_z(position=(0.0, 0.0, 10.0)):
    world_from_view = np.eye(4)
    world_from_view[:3, 3] = position
    return world_from_view


@pytest.mark.parametrize("projection", [
    CameraProjection(kind="PERSP", fov_y=math.radians(60), aspect=1.5, clip_start=0.25,
                     clip_end=400.0, shift_x=0.1),
    CameraProjection(kind="ORTHO", ortho_height=12.0, aspect=0.75, clip_start=-5.0,
                     clip_end=50.0, shift_y=-0.2),
])
def test_camera_view_decodes_kind_and_clip_range_from_the_matrix(projection):
    view = CameraView(_look_down_minus_z(), projection.clip_from_view(), 640, 480)
    assert view.is_perspective == projection.is_perspective
    assert view.clip_start == pytest.approx(projection.clip_start, rel=1e-9)
    assert view.clip_end == pytest.approx(projection.clip_end, rel=1e-9)
    back = view.projection
    assert back.kind == projection.kind
    assert back.aspect == pytest.approx(projection.aspect)
    assert as_projection(projection.clip_from_view()).kind == projection.kind


def test_exact_clip_values_given_by_blender_win_over_the_float32_matrix():
    matrix = CameraProjection(clip_start=0.1, clip_end=100.0).clip_from_view()
    view = CameraView(_look_down_minus_z(), matrix.astype(np.float32), 8, 8, 0.1, 100.0)
    assert (view.clip_start, view.clip_end) == (0.1, 100.0)


def test_camera_position_forward_and_clip_from_world():
    view = CameraView(_look_down_minus_z((1.0, 2.0, 3.0)),
                      CameraProjection().clip_from_view(), 16, 9)
    np.testing.assert_allclose(view.position, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(view.forward, [0.0, 0.0, -1.0])
    clip = view.clip_from_world @ np.array([1.0, 2.0, -7.0, 1.0])   # 10 m ahead, centred
    np.testing.assert_allclose(clip[:2] / clip[3], [0.0, 0.0], atol=1e-12)


def test_world_positions_rebuild_points_at_their_view_depth():
    projection = CameraProjection(fov_y=math.radians(50), aspect=2.0, clip_start=0.5,
                                  clip_end=80.0)
    view = CameraView(_look_down_minus_z(), projection.clip_from_view(), 4, 2)
    depth = np.full((2, 4), 20.0)
    points = world_positions(view, depth)
    assert points.shape == (2, 4, 3)
    np.testing.assert_allclose(points[..., 2], 10.0 - 20.0)          # 20 m ahead of z = 10
    # Pixel centres lie inside the view window at that depth, symmetric about the axis.
    half_h = math.tan(math.radians(25)) * 20.0
    np.testing.assert_allclose(points[0, :, 1], -0.5 * half_h)
    np.testing.assert_allclose(points[:, 0, 0], -0.75 * 2.0 * half_h)


def test_a_far_plane_float32_cannot_hold_decodes_and_unprojects_quietly():
    """clip_end / clip_start = 1e9 rounds the float32 matrix's z row to -1: the far plane
    decodes as infinite (taken as MAX_CLIP_RATIO x near) and pixels still find their
    points, without numpy warnings on the user's console."""
    import warnings
    matrix = CameraProjection(fov_y=math.radians(50), aspect=2.0, clip_start=1e-4,
                              clip_end=1e5).clip_from_view().astype(np.float32)
    assert matrix[2, 2] == -1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        view = CameraView(_look_down_minus_z(), matrix, 4, 2)
        assert view.is_perspective and math.isfinite(view.projection.clip_end)
        points = world_positions(view, np.full((2, 4), 20.0))
    np.testing.assert_allclose(points[..., 2], 10.0 - 20.0)
    half_h = math.tan(math.radians(25)) * 20.0
    np.testing.assert_allclose(points[0, :, 1], -0.5 * half_h, rtol=1e-6)
