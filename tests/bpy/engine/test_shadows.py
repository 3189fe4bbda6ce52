"""What a user sees of the sun's cascaded shadows (and the spot light's), checked in pixels.

Scenes are built here with plain Blender calls (the builders in ``tests/bpy/scenes.py``)
so each test shows its whole set-up. The reference for "where should the shadow be" is an
independent CPU ray cast (mathutils BVHTree) from the very surface points the G-buffer saw.
"""
import bpy
import numpy as np
import pytest
from mathutils import Vector

from tests.bpy.bpy_helpers import render_result, render_scene
from tests.bpy.scenes import (COURSE_SUN, add_box, add_camera, add_ground, add_sun,  # noqa: F401
                              pillar_field, ray_cast_shadowed, set_world_color,
                              sun_facing_points, world_bvh)


def test_pillar_shadows_fall_where_a_ray_cast_says(pillar_field):
    scene, sun = pillar_field
    images = render_scene(scene, 480, 320)
    to_light = -COURSE_SUN.normalized()
    rows, cols, points, normals = sun_facing_points(images, to_light)
    expected = ray_cast_shadowed(world_bvh(scene), points, normals, to_light)
    csm_shadowed = images["aux"][rows, cols, 0] < 0.5
    assert len(points) > 10000
    assert 0.02 < expected.mean() < 0.6, "the view must show both shadow and light"
    mismatch = np.mean(csm_shadowed != expected)
    assert mismatch < 0.01, f"{mismatch:.2%} of sun-facing pixels disagree with the ray cast"


def test_sun_use_shadow_off_removes_every_shadow(pillar_field):
    scene, sun = pillar_field
    sun.data.use_shadow = False
    images = render_scene(scene, 240, 160)
    assert images["aux"][..., 0].min() == 1.0


@pytest.fixture
def long_ground(empty_scene):
    scene = empty_scene
    add_ground(600, location=(0, 250, 0))
    add_sun((0.2, 0.4, -1.0))
    add_camera(scene, (0, -5, 4), (0, 60, 0), lens=30, clip_end=300)
    scene.csm.debug_view = 'CASCADES'
    scene.csm.split_lambda = 0.75      # splits at ~43 and ~150 m: both well on screen
    scene.csm.fit_to_visible = False   # the splits over clip start .. far, as written above
    scene.csm.cascade_selection = 'DEPTH'   # the course's bands: a cascade per depth slice
    return scene


def test_cascade_colours_in_depth_order(long_ground):
    scene = long_ground
    images = render_scene(scene, 320, 240)
    cascade = images["aux"][..., 1]
    covered = images["aux"][..., 3] > 0.5
    column = [cascade[r, 160] for r in range(239, -1, -1) if covered[r, 160]]  # near -> far
    steps = np.diff(column)
    assert np.all(steps >= -1e-6), "cascade index must not decrease with view depth"
    assert {0, 1, 2} <= set(np.round(column).astype(int)), "all 3 cascades on screen"
    color = images["combined"][..., :3]
    for index, channel in ((0, 0), (1, 1), (2, 2)):   # red, green, blue
        pixels = color[np.isclose(cascade, index) & covered]
        assert len(pixels) > 100
        mean = pixels.mean(axis=0)
        assert mean[channel] > 1.5 * np.delete(mean, channel).max(), (index, mean)


def test_map_selection_gives_ground_past_a_split_the_finer_map(long_ground):
    """Cascade Selection = Shadow Map: a cascade's map reaches past its slice's far split
    (a stabilized map is a square around the slice's sphere), and ground there reads that
    finer map: cascades still rise with distance, every one starts later than its split,
    and the shadows stay where the ray cast puts them."""
    scene = long_ground
    for x in (-14, -8, 8, 14):                    # pillars past the first split, off the middle column
        for y in (35, 50, 70, 95):
            add_box((x, y, 4), (0.8, 0.8, 4))
    by_depth = render_result(scene, 640, 480)
    scene.csm.cascade_selection = 'MAP'
    by_map = render_result(scene, 640, 480)
    splits = by_map.plan.splits
    covered = by_map.images["aux"][..., 3] > 0.5
    depth = by_map.images["aux"][..., 2]
    for result in (by_depth, by_map):
        column = [result.images["aux"][r, 320, 1] for r in range(479, -1, -1) if covered[r, 320]]
        assert np.all(np.diff(column) >= -1e-6), "cascade index must not fall with depth"
    cascade_depth = np.rint(by_depth.images["aux"][..., 1])
    cascade_map = by_map.images["aux"][..., 1]
    finest_past_split = covered & (depth > splits[1] * 1.1) & (cascade_map == 0.0)
    assert not np.any(covered & (depth > splits[1] * 1.1) & (cascade_depth == 0.0))
    assert finest_past_split.sum() > 1000, "the first map also serves ground past its split"
    assert np.all(cascade_map[covered] <= cascade_depth[covered] + 1e-6), "never coarser"
    # Shadows as the ray cast says, with either selection.
    to_light = (-Vector((0.2, 0.4, -1.0))).normalized()
    bvh = world_bvh(scene)
    for result in (by_depth, by_map):
        rows, cols, points, normals = sun_facing_points(result.images, to_light)
        expected = ray_cast_shadowed(bvh, points, normals, to_light)
        assert expected.sum() > 60, "the pillars' shadows are on screen"
        shadowed = result.images["aux"][rows, cols, 0] < 0.5
        found, false = np.mean(shadowed[expected]), np.mean(shadowed[~expected])
        assert found > 0.9 and false < 0.002, (found, false)


def test_map_selection_fades_between_cascades_at_a_maps_edge(pillar_field):
    """Shadow Map selection on the course's shadow test: where the first map ends, the next
    one is mixed in over 48 texels (a band of pixels whose cascade value lies between the
    two), and with Blend Band 0 the switch is hard (no pixel between cascades)."""
    scene, _sun = pillar_field
    assert scene.csm.cascade_selection == 'MAP'

    def mixed(band):
        scene.csm.blend_band = band
        aux = render_scene(scene, 480, 270)["aux"]
        cascade, covered = aux[..., 1][aux[..., 3] > 0.5], aux[..., 3] > 0.5
        between = np.abs(cascade - np.round(cascade)) > 0.01
        return np.mean(between), cascade[between], covered

    hard, _, _ = mixed(0.0)
    soft, values, _ = mixed(2.0)
    assert hard == 0.0, "Blend Band 0: every pixel reads one cascade"
    assert soft > 0.01, ("at a map's edge both cascades are mixed", soft)
    assert values.min() > 0.0 and values.max() < 2.0


def test_blend_band_removes_the_step_at_a_split(long_ground):
    scene = long_ground
    column = 160

    def tint_steps(band):
        scene.csm.blend_band = band
        images = render_scene(scene, 320, 240)
        cascade = images["aux"][:, column, 1]
        covered = images["aux"][:, column, 3] > 0.5
        tint = images["combined"][:, column, :3]
        tint = tint / np.maximum(tint.max(axis=1, keepdims=True), 1e-6)
        rows = np.nonzero(covered)[0]
        jump = np.abs(np.diff(tint[rows], axis=0)).max()
        fractional = np.mean(np.abs(cascade[rows] - np.round(cascade[rows])) > 0.01)
        return jump, fractional

    hard_jump, hard_fraction = tint_steps(0.0)
    soft_jump, soft_fraction = tint_steps(25.0)
    assert hard_fraction == 0.0 and hard_jump > 0.5, "without a band the switch is a step"
    assert soft_fraction > 0.02, "inside the band both cascades are mixed"
    assert soft_jump < 0.5 * hard_jump, (hard_jump, soft_jump)


def test_larger_pcf_radius_widens_the_penumbra(pillar_field):
    scene, _ = pillar_field
    scene.csm.fade_out = False
    scene.csm.blend_band = 0.0

    # At the default PCF Sharpen (3) and with the kernel's own ramp (1).
    def penumbra_pixels(radius, sharpen):
        scene.csm.pcf_radius = radius
        scene.csm.pcf_sharpen = sharpen
        visibility = render_scene(scene, 480, 320)["aux"][..., 0]
        return int(np.sum((visibility > 0.02) & (visibility < 0.98)))

    for sharpen in (3.0, 1.0):
        counts = [penumbra_pixels(r, sharpen) for r in (0, 1, 3)]
        assert counts[0] < 0.2 * counts[1], counts   # a single tap is a hard edge
        assert counts[1] < 0.6 * counts[2], counts


def test_pcf_sharpen_keeps_the_edge_and_narrows_its_ramp(pillar_field):
    """PCF Sharpen (3 by default) steepens the filtered edge around 0.5: every pixel
    stays on its side of the edge (the same pixels are shadowed), the ramp gets narrower,
    and lit ground that the 3x3 kernel reached from a shadow edge or a box's base becomes
    fully lit."""
    scene, _ = pillar_field
    scene.csm.fade_out = False
    scene.csm.blend_band = 0.0
    assert scene.csm.pcf_sharpen == 3.0 and scene.csm.pcf_radius == 1

    def visibility(sharpen):
        scene.csm.pcf_sharpen = sharpen
        images = render_scene(scene, 480, 320)
        return images["aux"][..., 0], images["aux"][..., 3] > 0.5

    plain, covered = visibility(1.0)
    sharp, _ = visibility(3.0)
    assert np.array_equal((plain < 0.5)[covered], (sharp < 0.5)[covered])
    partial_plain = np.count_nonzero(((plain > 0.02) & (plain < 0.98))[covered])
    partial_sharp = np.count_nonzero(((sharp > 0.02) & (sharp < 0.98))[covered])
    assert partial_plain > 200, partial_plain
    assert partial_sharp < 0.5 * partial_plain, (partial_sharp, partial_plain)
    # The plain kernel's spill: lit pixels just short of 1. Sharpened, they are 1.
    spill = covered & (plain > 5.0 / 6.0) & (plain < 0.999)
    assert np.count_nonzero(spill) > 50
    assert np.all(sharp[spill] >= 0.999)


def test_stabilized_shadows_hold_still_while_the_camera_moves_less_than_a_texel(empty_scene):
    scene = empty_scene
    add_ground(200)
    for x in range(-12, 13, 6):
        add_box((x, x * 0.5, 2.0), (0.7, 0.7, 2.0))
    add_sun((0.37, 0.52, -0.77))
    camera = add_camera(scene, (0.0, 0.0, 40.0), (0.0, 0.0, 0.0))
    camera.data.type = 'ORTHO'
    camera.data.ortho_scale = 40.0
    camera.data.clip_end = 100.0
    width, height = 400, 400
    pixel = camera.data.ortho_scale / width        # 0.1 scene units
    scene.csm.resolution = 400     # texels of about 0.13 units in the first cascade,
    #                                which holds the ground here (Shadow Map selection)
    # The whole frustum's fit: the texel size depends only on the camera's slices.
    scene.csm.fit_to_visible = False

    def shadow_mask(x):
        camera.location.x = x
        result = render_result(scene, width, height)
        return result.images["aux"][..., 0] < 0.5, result

    def moved_pixels(stabilize):
        scene.csm.stabilize = stabilize
        before, result = shadow_mask(0.0)
        after, _ = shadow_mask(pixel)              # the image moves by exactly one pixel
        ground_cascade = int(result.images["aux"][height // 2, width // 2, 1])
        texel = result.plan.tiles[ground_cascade].texel_world
        assert pixel < texel, "the move must be smaller than a shadow texel"
        changed = before[:, 1:] != after[:, :-1]
        return changed.sum() / max(before.sum(), 1)

    stable = moved_pixels(True)
    unstable = moved_pixels(False)
    assert stable < 0.001, f"{stable:.3%} of the shadow changed with stabilization on"
    assert unstable > 0.01, "control: the tight fit swims, so the test can see movement"


def test_off_screen_caster_still_casts_into_view(empty_scene):
    scene = empty_scene
    add_ground(300)
    add_box((-40.0, 0.0, 15.0), (1.5, 1.5, 15.0))   # a tower well outside the view
    add_sun((1.0, 0.0, -0.55))                      # low sun from -x: shadow points at +x
    camera = add_camera(scene, (10.0, 0.0, 30.0), (10.0, 0.0, 0.0))
    camera.data.type = 'ORTHO'
    camera.data.ortho_scale = 20.0                  # sees x in 0..20 only
    camera.data.clip_end = 60.0
    scene.csm.fade_out = False

    images = render_scene(scene, 200, 200)
    shadowed = images["aux"][..., 0] < 0.5
    assert 0.02 < shadowed.mean() < 0.5, "the tower's shadow reaches into the view"

    scene.csm.occluder_margin_auto = False
    scene.csm.occluder_margin = 0.0
    images = render_scene(scene, 200, 200)
    assert (images["aux"][..., 0] < 0.5).mean() < 0.001, \
        "control: with no margin the off-screen tower is clipped and casts nothing"


def test_spot_light_casts_a_shadow(empty_scene):
    scene = empty_scene
    add_ground(40)
    add_box((0, 0, 1.0), (1, 1, 1))
    bpy.ops.object.light_add(type='SPOT', location=(-6.0, 0.0, 6.0))
    spot = bpy.context.object
    spot.rotation_euler = (Vector((2.0, 0.0, 0.0)) - spot.location).to_track_quat(
        '-Z', 'Y').to_euler()
    spot.data.energy = 1000.0
    spot.data.spot_size = np.radians(70.0)
    spot.data.use_custom_distance = True
    spot.data.cutoff_distance = 30.0
    add_camera(scene, (4.0, -14.0, 14.0), (2.0, 0.0, 0.0))
    set_world_color(scene, (0.0, 0.0, 0.0))

    brightness, blocked, points = lit_ground(scene, spot.location, 320, 240)
    to_light = np.array(spot.location) - points
    axis = -np.array(spot.matrix_world.col[2][:3])
    in_cone = (-(to_light / np.linalg.norm(to_light, axis=1)[:, None]) @ axis) > \
        np.cos(np.radians(30.0))
    lit = brightness[in_cone & ~blocked]
    dark = brightness[in_cone & blocked]
    assert len(dark) > 200 and len(lit) > 200
    assert dark.mean() < 0.15 * lit.mean(), (dark.mean(), lit.mean())
    assert np.mean(dark < 0.5 * np.median(lit)) > 0.9


def test_an_impossible_shadow_resolution_falls_back_and_says_so(pillar_field):
    scene, _ = pillar_field
    scene.csm.cascade_count = 4
    scene.csm.resolution = 8192
    scene.csm.equal_resolution = True          # 4 x 8192^2: an atlas past GL's size limit
    result = render_result(scene, 160, 120)
    images = result.images
    assert any("halving" in w for w in result.warnings), result.warnings
    assert (images["aux"][..., 0] < 0.5).mean() > 0.005, "shadows still render"


def test_frozen_cascades_keep_their_boxes_and_draw_them(pillar_field):
    scene, _ = pillar_field
    scene.csm.freeze_cascades = True
    frozen = [t.clip_from_world.copy() for t in render_result(scene, 240, 160).plan.tiles]
    scene.camera.location.x += 15.0
    result = render_result(scene, 240, 160)
    images = result.images
    moved = [t.clip_from_world for t in result.plan.tiles]
    assert all(np.array_equal(a, b) for a, b in zip(frozen, moved))
    color = images["combined"][..., :3]
    box_lines = (color[..., 0] > 0.9) & (color[..., 1] < 0.3) & (color[..., 2] < 0.3)
    assert box_lines.sum() > 50, "the first cascade's box is drawn in red"
    scene.csm.freeze_cascades = False
    unfrozen = render_result(scene, 240, 160).plan
    assert not np.array_equal(unfrozen.tiles[0].clip_from_world, frozen[0])


def test_front_face_culling_keeps_closed_casters_shadowing(pillar_field):
    scene, _ = pillar_field
    scene.csm.cull_front_faces = True
    images = render_scene(scene, 480, 320)
    to_light = -COURSE_SUN.normalized()
    rows, cols, points, normals = sun_facing_points(images, to_light)
    expected = ray_cast_shadowed(world_bvh(scene), points, normals, to_light)
    mismatch = np.mean((images["aux"][rows, cols, 0] < 0.5) != expected)
    assert mismatch < 0.02, f"{mismatch:.2%} disagree with back faces as casters"


def test_impossible_manual_splits_warn_and_fall_back(pillar_field):
    scene, _ = pillar_field
    scene.csm.split_scheme = 'MANUAL'
    scene.csm.manual_splits = (0.5, 0.2, 0.6)      # the second split lies before the first
    result = render_result(scene, 160, 120)
    images = result.images
    warnings = " ".join(result.warnings)
    assert "manual split" in warnings and "hybrid" in warnings, warnings
    assert (images["aux"][..., 0] < 0.5).mean() > 0.005, "shadows still render"


@pytest.fixture
def boxes_round_a_point_light(empty_scene):
    """Four boxes around a point light 2.5 units above the ground, one in each horizontal
    cube face (the ground near the light is in the -Z face), seen from above; no world
    light."""
    scene = empty_scene
    add_ground(40)
    for x, y in ((3.0, 0.0), (-3.0, 0.0), (0.0, 3.0), (0.0, -3.0)):
        add_box((x, y, 1.0), (0.5, 0.5, 1.0))
    bpy.ops.object.light_add(type='POINT', location=(0.0, 0.0, 2.5))
    light = bpy.context.object
    light.data.energy = 2000.0
    light.data.shadow_soft_size = 0.0
    add_camera(scene, (0.0, -0.5, 28.0), (0.0, 0.0, 0.0), lens=30.0)
    set_world_color(scene, (0.0, 0.0, 0.0))
    return scene, light


def lit_ground(scene, light_location, width=320, height=320):
    """The ground pixels of a CSM render (z = 0): their brightness, whether a ray cast from
    each to the light at ``light_location`` hits anything first, and their world points."""
    images = render_scene(scene, width, height)
    position = images["position"]
    brightness = images["combined"][..., :3].sum(axis=2)
    ground = (position[..., 3] > 0.5) & (np.abs(position[..., 2]) < 1e-3)
    rows, cols = np.nonzero(ground)
    points = position[rows, cols, :3]
    to_light = np.array(light_location) - points
    distance = np.linalg.norm(to_light, axis=1)
    bvh = world_bvh(scene)
    blocked = np.zeros(len(points), dtype=bool)
    for i, (p, d, dist) in enumerate(zip(points, to_light / distance[:, None], distance)):
        hit = bvh.ray_cast(Vector(p) + Vector((0, 0, 1e-3)), Vector(d))
        blocked[i] = hit[2] is not None and hit[3] < dist - 1e-2
    return brightness[rows, cols], blocked, points


def test_point_light_casts_shadows_in_every_direction(boxes_round_a_point_light):
    """A point light with Shadow on (Blender's default) casts shadows through its six cube
    faces, where a ray cast says, as in EEVEE and Cycles."""
    scene, light = boxes_round_a_point_light
    brightness, blocked, _points = lit_ground(scene, light.location)
    lit, dark = brightness[~blocked], brightness[blocked]
    assert len(dark) > 2000 and len(lit) > 2000
    assert dark.mean() < 0.05 * lit.mean(), (dark.mean(), lit.mean())
    # Pixels on the wrong side of an edge: the ray cast's verdict at the pixel centre.
    wrong = np.count_nonzero(blocked & (brightness > 0.5 * np.median(lit))) + \
        np.count_nonzero(~blocked & (brightness < 0.02 * np.median(lit)))
    assert wrong < 0.01 * len(brightness), wrong


def test_point_light_shadow_off_and_course_lights_cast_none(boxes_round_a_point_light):
    scene, light = boxes_round_a_point_light
    light.data.use_shadow = False
    brightness, blocked, _points = lit_ground(scene, light.location)
    lit = brightness[~blocked]
    assert brightness[blocked].mean() > 0.5 * np.median(lit), "no shadow with Shadow off"
    # The course's point lights cast no shadows (scene-format.md): imported with Shadow off.
    import os
    from csm_engine.blender import cli
    from csm_engine.core import paths
    course = cli.open_scene(os.path.join(paths.data_dir(), "scenes", "point_lights.json"))
    lights = [o.data for o in course.objects if o.type == 'LIGHT' and o.data.type == 'POINT']
    assert lights and not any(data.use_shadow for data in lights)


def test_a_point_lights_radius_softens_its_shadow_with_the_soft_filter(
        boxes_round_a_point_light):
    scene, light = boxes_round_a_point_light

    def penumbra_pixels(shadow_filter, radius):
        scene.csm.shadow_filter = shadow_filter
        light.data.shadow_soft_size = radius
        light.data.use_shadow = False
        off = render_scene(scene, 200, 200)["combined"][..., :3].sum(axis=2)
        light.data.use_shadow = True
        on = render_scene(scene, 200, 200)["combined"][..., :3].sum(axis=2)
        visibility = on / np.maximum(off, 1e-6)
        return np.count_nonzero((visibility > 0.05) & (visibility < 0.95) & (off > 1e-3))

    hard, soft = penumbra_pixels('SOFT', 0.0), penumbra_pixels('SOFT', 0.5)
    assert soft > 3 * hard, (hard, soft)
    assert penumbra_pixels('PCF', 0.5) < 2 * hard      # PCF ignores the light's Radius
