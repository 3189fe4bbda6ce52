"""Filter Exact (shadow volumes) against a CPU ray cast toward the sun, pixel by pixel, on
small scenes built with plain operators; and the Shadow error view against the same ray
cast.

The ray cast (a ``mathutils`` BVH of the scene) starts at each pixel's G-buffer position,
the very point the volume count was taken at, so the two may disagree only where a shadow
edge passes within rounding of a pixel's centre: pixels whose ray-cast answer changes
within 2 mm of their point are left out (``STRADDLE``), and only they."""

import bpy
import numpy as np
import pytest
from mathutils import Vector

from tests.bpy.bpy_helpers import render_result, viewport_frame
from tests.bpy.scenes import (add_box, add_camera, add_ground, add_light, add_sun,
                              set_world_color, world_bvh)


def _exact(scene, width=240, height=160):
    scene.csm.shadow_filter = 'EXACT'
    scene.csm.fxaa = False
    # Maps of 256 texels, which a map-based filter could not pass these tests with: the
    # volumes have no resolution.
    scene.csm.resolution = 256
    return render_result(scene, width, height)


# How far (scene units) around a pixel's point the ray cast is repeated: a pixel whose
# shadow flips within it straddles a shadow edge, and is left out.
STRADDLE = 2e-3


def _blocked(bvh, origin, target=None, direction=None):
    if target is not None:
        ray = Vector(target) - origin
        return bvh.ray_cast(origin, ray.normalized(), ray.length - 1e-3)[0] is not None
    return bvh.ray_cast(origin, direction)[0] is not None


def _truth(bvh, points, normals, to_light=None, light=None):
    """Per point: shadowed by the ray cast (from the point nudged 1 mm off its surface), and
    whether the answer is the same from four points ``STRADDLE`` away along the surface."""
    shadowed = np.zeros(len(points), dtype=bool)
    steady = np.ones(len(points), dtype=bool)
    for i, (p, n) in enumerate(zip(points, normals)):
        n = Vector(n).normalized()
        base = Vector(p) + n * 1e-3
        tangent = n.orthogonal().normalized()
        bitangent = n.cross(tangent)
        answers = []
        for offset in (Vector(), tangent, -tangent, bitangent, -bitangent):
            origin = base + offset * STRADDLE
            if light is None:
                answers.append(_blocked(bvh, origin + Vector(to_light) * 1e-3,
                                        direction=Vector(to_light)))
            else:
                answers.append(_blocked(bvh, origin, target=light))
        shadowed[i] = answers[0]
        steady[i] = all(a == answers[0] for a in answers)
    return shadowed, steady


def _sun_truth(scene, images, to_light):
    """Per pixel: covered and facing the sun, the ray cast's shadowed, and clear of a
    shadow edge (see ``_truth``)."""
    position, normal = images["position"], images["normal"][..., :3]
    covered = position[..., 3] > 0.5
    facing = covered & ((normal @ np.asarray(to_light, np.float32)) > 0.05)
    rows, cols = np.nonzero(facing)
    shadowed = np.zeros(covered.shape, dtype=bool)
    clear = np.zeros(covered.shape, dtype=bool)
    shadowed[rows, cols], clear[rows, cols] = _truth(
        world_bvh(scene), position[rows, cols, :3], normal[rows, cols],
        to_light=Vector(to_light).normalized())
    return facing, shadowed, clear


def _check_sun(scene, sun_object, width=240, height=160, limit=0.0002):
    to_light = -(sun_object.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
    result = _exact(scene, width, height)
    images = result.images
    facing, expected, clear = _sun_truth(scene, images, to_light)
    exact_shadowed = images["aux"][..., 0] < 0.5
    judged = facing & clear
    assert 0.03 < expected[facing].mean() < 0.97, "the view shows both shadow and light"
    assert judged.sum() > 0.98 * facing.sum(), "few pixels straddle a shadow edge"
    wrong = np.mean(exact_shadowed[judged] != expected[judged])
    assert wrong <= limit, (f"{wrong:.4%} of {judged.sum()} lit-or-shadowed pixels "
                            f"disagree with the ray cast")
    return result


def test_pillar_row_under_a_grazing_sun(empty_scene):
    scene = empty_scene
    add_ground(80, location=(20, 0, 0))
    for i in range(8):
        add_box((i * 5.0, 0, 2.0), (0.5, 0.5, 2.0))
    sun = add_sun((0.35, 0.5, -0.17))          # about 16 degrees above the horizon
    add_camera(scene, (4, 26, 10), (16, 4, 0), lens=28)
    _check_sun(scene, sun)


def test_camera_inside_a_shadow_volume(empty_scene):
    """The camera stands in the shadow of a roof: depth-fail counts only behind the
    surfaces, so being inside a volume changes nothing."""
    scene = empty_scene
    add_ground(60)
    add_box((0, 0, 6.0), (4.0, 4.0, 0.3))
    add_box((5, 6, 1.0), (1.0, 1.0, 1.0))
    sun = add_sun((0.1, 0.2, -1.0))
    add_camera(scene, (0.5, -1.5, 1.6), (6, 10, 0), lens=24)
    result = _check_sun(scene, sun)
    assert result.passes is not None


def test_mirrored_caster(empty_scene):
    """A cone turned inside out by a negative scale casts the same shadow as a ray says."""
    scene = empty_scene
    add_ground(30)
    bpy.ops.mesh.primitive_cone_add(location=(0, 0, 2.0), rotation=(0.4, 0.3, 0.0))
    bpy.context.object.scale = (-1.2, 1.0, 1.5)
    sun = add_sun((0.4, 0.3, -0.8))
    add_camera(scene, (-1, 8, 6), (1.5, 1, 0.5), lens=40)
    _check_sun(scene, sun)


def test_open_plane_caster(empty_scene):
    """An open, tilted plane (no closed volume to take silhouettes of) over a box."""
    scene = empty_scene
    add_ground(30)
    bpy.ops.mesh.primitive_plane_add(size=3.0, location=(0, 0, 3.0), rotation=(0.5, 0.2, 0))
    add_box((2.5, 1.5, 0.5), (0.5, 0.5, 0.5))
    sun = add_sun((0.3, 0.4, -0.85))
    add_camera(scene, (5, -8, 8), (0, 0, 1), lens=30)
    _check_sun(scene, sun)


def test_volumes_are_kept_while_only_the_camera_moves(empty_scene):
    """In the viewport a camera move builds no volume; turning the sun builds them again,
    and the picture follows it."""
    from csm_engine.blender import engine, mesh_cache
    from csm_engine.render import pipeline
    scene = empty_scene
    add_ground(20)
    add_box((0, 0, 1.0), (1.0, 1.0, 1.0))
    sun = add_sun((0.3, 0.2, -0.9))
    add_camera(scene, (6, -6, 5), (0, 0, 0))
    scene.csm.shadow_filter = 'EXACT'
    render_result(scene, 32, 32)             # a GPU context exists from here on
    cache, renderer = mesh_cache.MeshCache(), pipeline.Pipeline()
    handler = lambda _scene, depsgraph: engine.apply_depsgraph_updates(  # noqa: E731
        cache, depsgraph.updates)
    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        first = viewport_frame(scene, renderer, cache, 64, 48)
        volumes = renderer.shadow_volumes
        built = volumes.builds
        assert built == 2 and volumes.triangle_count > 0
        scene.camera.location.x += 1.0
        bpy.context.view_layer.update()
        moved = viewport_frame(scene, renderer, cache, 64, 48)
        assert volumes.builds == built, "a camera move rebuilt volumes"
        assert np.abs(moved - first).max() > 0.01, "the view moved"
        sun.rotation_euler.x += 0.2
        bpy.context.view_layer.update()
        viewport_frame(scene, renderer, cache, 64, 48)
        assert volumes.builds == built + 2, "a sun turn rebuilds every volume"
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)


def test_shadow_error_view_lights_up_where_a_ray_cast_says_the_map_is_wrong(empty_scene):
    """Cascades of 64 texels under Filter Hard: the Shadow error view is red or cyan where
    the map's shadow differs from the ray cast, grey where it agrees, and its counts are
    those of its pixels."""
    scene = empty_scene
    add_ground(40, location=(8, 0, 0))
    for i in range(4):
        add_box((i * 4.0, 0, 1.5), (0.4, 0.4, 1.5))
    sun = add_sun((0.5, 0.45, -0.6))
    add_camera(scene, (2, 16, 9), (9, 2, 0), lens=30)
    scene.csm.cascade_count = 1
    scene.csm.resolution = 64
    scene.csm.shadow_filter = 'HARD'
    scene.csm.debug_view = 'SHADOW_ERROR'
    scene.csm.fxaa = False
    result = render_result(scene, 240, 160)
    images = result.images
    to_light = -(sun.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
    facing, expected, _clear = _sun_truth(scene, images, to_light)
    map_wrong = ((images["aux"][..., 0] < 0.5) != expected)[facing]
    color = images["combined"][..., :3]
    lit_up = (np.abs(color[..., 0] - color[..., 1]) > 0.5)[facing]
    assert map_wrong.sum() > 100, "a 64-texel map gets many pixels wrong"
    # Only a shadow edge within rounding of a pixel's centre may tell the ray cast and the
    # volumes apart.
    assert np.sum(lit_up != map_wrong) <= 0.0005 * facing.sum(), \
        (np.sum(lit_up & ~map_wrong), np.sum(map_wrong & ~lit_up), facing.sum())
    error = result.shadow_error
    assert error is not None and error.surface_pixels == int((color.max(axis=2) > 0.1).sum())
    shown = np.abs(color[..., 0] - color[..., 1]) > 0.5
    assert abs(error.false_shadow + error.missed_shadow -
               shown.sum() / error.surface_pixels) < 1e-6


@pytest.mark.parametrize("kind", ["SPOT", "POINT"])
def test_spot_and_point_lights_against_a_ray_cast_to_the_light(empty_scene, kind):
    """A box, a tilted open plane and a mirrored cone under one spot or point light: the
    light's exact visibility (its image with shadows over its image without) against a ray
    cast to the light."""
    scene = empty_scene
    set_world_color(scene, (0.0, 0.0, 0.0))
    add_ground(20)
    add_box((1.5, -1.0, 0.6), (0.6, 0.6, 0.6))
    bpy.ops.mesh.primitive_plane_add(size=1.6, location=(-1.5, 1.0, 1.8),
                                     rotation=(0.4, 0.2, 0))
    bpy.ops.mesh.primitive_cone_add(location=(-1.8, -1.8, 0.8), rotation=(0.3, 0.2, 0.0))
    bpy.context.object.scale = (-0.6, 0.6, 0.8)
    light_location = (0.3, 0.2, 4.0)
    settings = dict(spot_size=2.2) if kind == "SPOT" else {}
    light = add_light(kind, light_location, 500.0, target=(0, 0, 0),
                      shadow_soft_size=0.0, **settings)
    add_camera(scene, (0.0, -8.0, 7.0), (0, 0, 0.3), lens=30)

    def combined(use_shadow):
        light.data.use_shadow = use_shadow
        return _exact(scene, 240, 160)

    result = combined(True)
    lit = result.images["combined"][..., :3].sum(axis=2)
    free = combined(False).images
    unshadowed = free["combined"][..., :3].sum(axis=2)
    position, normal = free["position"], free["normal"][..., :3]
    to_light = np.asarray(light_location, np.float32) - position[..., :3]
    lighted = (position[..., 3] > 0.5) & (unshadowed > 1e-3) & \
        (np.einsum("ijk,ijk->ij", normal, to_light) > 0.05 * np.linalg.norm(to_light, axis=2))
    rows, cols = np.nonzero(lighted)
    expected = np.zeros(lighted.shape, dtype=bool)
    clear = np.zeros(lighted.shape, dtype=bool)
    expected[rows, cols], clear[rows, cols] = _truth(
        world_bvh(scene), position[rows, cols, :3], normal[rows, cols], light=light_location)
    exact_shadowed = lit < 0.5 * unshadowed
    judged = lighted & clear
    assert 0.03 < expected[lighted].mean() < 0.97, expected[lighted].mean()
    assert judged.sum() > 0.98 * lighted.sum()
    wrong = np.mean(exact_shadowed[judged] != expected[judged])
    assert wrong <= 0.0002, f"{wrong:.4%} of {judged.sum()} pixels disagree with the ray cast"


def test_the_legend_names_the_shares_of_false_and_missed_shadow():
    from types import SimpleNamespace

    from csm_engine.render import overlays
    from csm_engine.render.shadow_volumes import ShadowError
    snap = SimpleNamespace(settings=SimpleNamespace(debug_view="SHADOW_ERROR"))
    rows = overlays.legend_rows(snap, None, ShadowError(0.0123, 0.0456, 1000))
    assert [row.label for row in rows] == ["false shadow 1.23 %", "missed shadow 4.56 %"]
    assert [row.color for row in rows] == list(overlays.SHADOW_ERROR_COLORS)
    snap.settings.debug_view = "NONE"
    assert overlays.legend_rows(snap, None, ShadowError(0.1, 0.1, 10)) == []


def test_counts_are_kept_with_the_gbuffer_and_redrawn_when_the_sun_turns(empty_scene):
    """An unchanged re-render keeps the counted volumes; turning the sun (the G-buffer
    is still kept) counts them again, and the shadow moves."""
    scene = empty_scene
    add_ground(20)
    add_box((0, 0, 1.0), (1.0, 1.0, 1.0))
    sun = add_sun((0.3, 0.2, -0.9))
    add_camera(scene, (6, -6, 5), (0, 0, 0))
    first = _exact(scene, 64, 48)
    again = _exact(scene, 64, 48)
    assert again.passes.gbuffers_kept == 1
    np.testing.assert_array_equal(first.images["aux"][..., 0], again.images["aux"][..., 0])
    sun.rotation_euler.z += 0.8
    turned = _exact(scene, 64, 48)
    assert turned.passes.gbuffers_kept == 1
    assert np.mean(turned.images["aux"][..., 0] != first.images["aux"][..., 0]) > 0.01


def test_a_caster_with_a_hashed_shadow_casts_no_exact_shadow(empty_scene):
    """The filter's documented choice: a material whose shadow is alpha-hashed (or
    clipped) is left out of the volumes; the same plane made opaque casts."""
    from tests.bpy.scenes import principled
    scene = empty_scene
    add_ground(20)
    bpy.ops.mesh.primitive_plane_add(size=3.0, location=(0, 0, 2.0))
    card = bpy.context.object
    material = principled("card")
    bsdf = next(n for n in material.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    bsdf.inputs["Alpha"].default_value = 0.6
    if hasattr(material, "surface_render_method"):          # 4.2+
        material.surface_render_method = 'DITHERED'
        material.use_transparent_shadow = True
    else:
        material.blend_method = 'HASHED'
        material.shadow_method = 'HASHED'
    card.data.materials.append(material)
    add_sun((0.2, 0.1, -1.0))
    add_camera(scene, (6, -6, 7), (0, 0, 0))
    shadowed = lambda: (_exact(scene, 96, 64).images["aux"][..., 0] < 0.5).sum()  # noqa: E731
    assert shadowed() == 0
    bsdf.inputs["Alpha"].default_value = 1.0
    assert shadowed() > 100
