"""Final-render anti-aliasing maths: sample offsets over Blender's pixel filter, jittered
cameras (core/antialiasing.py)."""
import math

import numpy as np
import pytest

from csm_engine.core.antialiasing import blackman_harris, jittered, sample_offsets
from csm_engine.core.camera import CameraProjection, CameraView


def test_first_sample_is_the_pixel_centre_and_weights_sum_to_one():
    offsets, weights = sample_offsets(8, 1.5)
    assert offsets.shape == (8, 2) and weights.shape == (8,)
    assert np.array_equal(offsets[0], [0.0, 0.0])
    assert weights.sum() == pytest.approx(1.0)
    assert sample_offsets(1)[0].tolist() == [[0.0, 0.0]]


def test_offsets_stay_inside_the_filter_and_centre_on_the_pixel():
    offsets, _ = sample_offsets(256, 1.5)
    assert np.abs(offsets).max() <= 1.5
    assert np.abs(offsets.mean(axis=0)).max() < 0.05
    # Blackman-Harris puts most samples near the centre: half within a third of the radius.
    assert np.median(np.abs(offsets)) < 0.5
    # Different samples look at different places (no duplicates).
    assert len(np.unique(np.round(offsets, 6), axis=0)) == 256


def test_filter_size_scales_the_spread_and_a_tiny_filter_still_covers_the_pixel():
    wide, _ = sample_offsets(64, 3.0)
    narrow, _ = sample_offsets(64, 1.5)
    assert np.abs(wide).std() == pytest.approx(2.0 * np.abs(narrow).std())
    tiny, _ = sample_offsets(64, 0.01)
    assert np.abs(tiny).max() > 0.2


def test_sample_count_must_be_positive():
    with pytest.raises(ValueError, match="at least 1"):
        sample_offsets(0)


def test_blackman_harris_is_one_in_the_middle_and_zero_at_the_ends():
    assert blackman_harris(0.0, 2.0) == pytest.approx(1.0)
    assert blackman_harris(1.0, 2.0) == pytest.approx(0.0, abs=1e-4)
    assert blackman_harris(5.0, 2.0) == 0.0


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
def test_a_jittered_camera_moves_every_point_by_the_offset_in_pixels(kind):
    projection = CameraProjection(kind=kind, fov_y=math.radians(50), ortho_height=4.0,
                                  aspect=4 / 3, clip_start=0.1, clip_end=100.0)
    camera = CameraView(np.eye(4), projection.clip_from_view(), 160, 120)
    moved = jittered(camera, (0.25, -0.5))

    def pixel(cam, point):
        clip = cam.clip_from_world @ np.append(point, 1.0)
        ndc = clip[:2] / clip[3]
        return (ndc + 1.0) * 0.5 * np.array([cam.width, cam.height])

    for point in ([0.3, -0.2, -2.0], [-1.0, 0.5, -20.0]):
        shift = pixel(moved, np.array(point)) - pixel(camera, np.array(point))
        assert shift == pytest.approx([0.25, -0.5], abs=1e-6)
    assert moved.clip_start == camera.clip_start and moved.clip_end == camera.clip_end
