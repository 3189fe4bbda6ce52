"""Fit to Visible Depth (sample-distribution shadow maps), checked in pixels and plans:
the cascades divide the depth the camera actually sees, shadows stay where a ray cast says,
and small camera moves leave the fitted range (and so the shadow maps) as they were."""
import numpy as np
import pytest

from csm_engine.core import cascades
from tests.bpy.bpy_helpers import render_result
from tests.bpy.scenes import (COURSE_SUN, pillar_field, ray_cast_shadowed,  # noqa: F401
                              sun_facing_points, world_bvh)


def _texels_per_pixel(result):
    """Median shadow texel size over pixel size (world units), over shadowed-cascade pixels."""
    images = result.images
    aux, position = images["aux"], images["position"][..., :3]
    cascade = np.rint(aux[..., 1]).astype(int)
    texel = np.array([t.texel_world for t in result.plan.tiles[:result.plan.cascade_count]])
    step = np.maximum(np.linalg.norm(np.diff(position, axis=1), axis=-1)[:-1],
                      np.linalg.norm(np.diff(position, axis=0), axis=-1)[:, :-1])
    ok = (aux[:-1, :-1, 3] > 0.5) & (aux[1:, :-1, 3] > 0.5) & (aux[:-1, 1:, 3] > 0.5) & \
        (cascade[:-1, :-1] >= 0)
    ok &= step < 5.0 * np.median(step[ok])          # not across a silhouette
    return float(np.median(texel[cascade[:-1, :-1][ok]] / step[ok]))


def test_fitted_cascades_start_where_the_view_does_and_shadows_stay_right(pillar_field):
    scene, _sun = pillar_field
    scene.camera.data.clip_start = 0.1
    # Each pixel in its depth slice's cascade, so only the fit differs (Shadow Map
    # selection sharpens the plain fit too: test_shadows.py).
    scene.csm.cascade_selection = 'DEPTH'
    scene.csm.fit_to_visible = False
    plain = render_result(scene, 480, 320)
    scene.csm.fit_to_visible = True
    fitted = render_result(scene, 480, 320)
    depth = fitted.images["aux"][..., 2][fitted.images["aux"][..., 3] > 0.5]
    # The first split sits at (just below) the nearest visible depth, not at the clip start.
    assert plain.plan.splits[0] == pytest.approx(0.1)
    assert 0.9 * depth.min() < fitted.plan.splits[0] <= depth.min()
    assert depth.max() <= fitted.plan.splits[-1] < 1.1 * depth.max()
    # Smaller texels for the same pixels.
    assert _texels_per_pixel(fitted) < 0.8 * _texels_per_pixel(plain)
    # And the shadows are still where a ray cast puts them.
    to_light = -COURSE_SUN.normalized()
    rows, cols, points, normals = sun_facing_points(fitted.images, to_light)
    expected = ray_cast_shadowed(world_bvh(scene), points, normals, to_light)
    shadowed = fitted.images["aux"][rows, cols, 0] < 0.5
    assert np.mean(shadowed != expected) < 0.01


def test_a_small_camera_move_keeps_the_fitted_range():
    previous = cascades.visible_depth_range(12.3, 140.0)
    assert previous[0] <= 12.3 and previous[1] >= 140.0
    assert cascades.visible_depth_range(12.5, 138.0, previous) == previous
    moved_far = cascades.visible_depth_range(12.5, 400.0, previous)
    assert moved_far != previous and moved_far[1] >= 400.0
    shrunk = cascades.visible_depth_range(60.0, 80.0, previous)
    assert shrunk[0] > previous[0] and shrunk[1] < previous[1]
    assert cascades.visible_depth_range(0.0, 0.0) is None


def test_an_empty_view_falls_back_to_the_plain_fit(empty_scene):
    from tests.bpy.scenes import add_camera, add_ground, add_sun
    scene = empty_scene
    add_ground(10, location=(0, 0, -50))
    add_sun((0.3, 0.2, -1.0))
    add_camera(scene, (0, 0, 0), (0, 0, 10))          # looking up at nothing
    scene.csm.fit_to_visible = True
    result = render_result(scene, 64, 48)
    assert result.plan.splits[0] == pytest.approx(scene.camera.data.clip_start)
