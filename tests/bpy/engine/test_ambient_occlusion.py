"""Screen-space ambient occlusion, checked in pixels: where it darkens, by how much, and
that it darkens only the ambient (World) light.

Scenes are a box on a floor under a grey World (built with plain Blender operators). Floor
pixels are picked by their world position (the G-buffer's, as the lighting pass saw them),
so each check reads as "the floor 10 cm from the box" or "the floor 4 m away". The last
test compares with Cycles: with a white World, white diffuse materials and no bounces,
Cycles' image is the cosine-weighted sky visibility, which is CSM's AO with a distance
larger than the scene.
"""
import os

import bpy
import numpy as np
import pytest

from tests.bpy.bpy_helpers import render_result
from tests.bpy.scenes import (add_box, add_camera, add_ground, add_sun, blender_render,
                              principled, set_world_color)

WORLD = 0.5
ALBEDO = 0.8                 # Blender's default material base colour


@pytest.fixture
def box_on_floor(empty_scene):
    """A 2 m box on a 30 m floor, both diffuse (Specular IOR Level 0: their World light is
    exactly World x albedo from every view), a grey World and no lamp; AO on, distance
    1 m."""
    scene = empty_scene
    set_world_color(scene, (WORLD, WORLD, WORLD))
    floor = principled("diffuse", (ALBEDO, ALBEDO, ALBEDO), 0.5)
    bsdf = next(n for n in floor.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    next(bsdf.inputs[n] for n in ("Specular IOR Level", "Specular")
         if bsdf.inputs.get(n)).default_value = 0.0
    add_ground(30).data.materials.append(floor)
    add_box((0, 0, 1), (1, 1, 1)).data.materials.append(floor)
    add_camera(scene, (6, -7, 5), (0, 0, 0.3))
    scene.csm.ambient_occlusion = True
    scene.csm.ao_distance = 1.0
    scene.csm.ao_strength = 1.0
    scene.csm.fxaa = False          # exact per-pixel relations between renders
    return scene


def floor_gap(images):
    """Per pixel: the distance (m) from the box's footprint on the floor, NaN off the floor."""
    position = images["position"]
    normal = images["normal"][..., :3]
    on_floor = (position[..., 3] > 0.5) & (np.abs(position[..., 2]) < 1e-3) & \
        (normal[..., 2] > 0.99)
    gap = np.maximum(np.abs(position[..., 0]), np.abs(position[..., 1])) - 1.0
    return np.where(on_floor & (gap > 0.0), gap, np.nan)


def luma(images):
    return images["combined"][..., :3].mean(axis=2)


def test_floor_darker_at_the_contact_with_ao_and_even_without(box_on_floor):
    scene = box_on_floor
    images = render_result(scene, 320, 240).images
    gap = floor_gap(images)
    near = (gap > 0.02) & (gap < 0.15)
    far = (gap > 3.0) & (gap < 6.0)
    assert near.sum() > 50 and far.sum() > 500
    brightness = luma(images)
    assert brightness[far].mean() == pytest.approx(WORLD * ALBEDO, rel=0.02)
    assert brightness[near].mean() < 0.8 * brightness[far].mean()

    scene.csm.ambient_occlusion = False
    images = render_result(scene, 320, 240).images
    brightness = luma(images)
    assert np.allclose(brightness[near | far], WORLD * ALBEDO, rtol=1e-3)


@pytest.mark.parametrize("height, target", [(12.0, (0, 0, 0)), (0.6, (0, 30, 0))])
def test_open_flat_ground_is_not_occluded(empty_scene, height, target):
    """A plane occludes nothing of its own hemisphere, seen from above or grazing."""
    scene = empty_scene
    set_world_color(scene, (WORLD, WORLD, WORLD))
    add_ground(400)
    add_camera(scene, (0, -10, height), target)
    scene.csm.ambient_occlusion = True
    scene.csm.ao_distance = 1.0
    scene.csm.debug_view = 'AMBIENT_OCCLUSION'
    images = render_result(scene, 320, 240).images
    covered = images["aux"][..., 3] > 0.5
    assert covered.sum() > 0.3 * covered.size
    ao = images["combined"][..., 0][covered]
    print(f"open ground, camera height {height}: AO min {ao.min():.4f}, mean {ao.mean():.5f}")
    assert ao.mean() > 0.995 and np.percentile(ao, 1) > 0.97


def test_pixels_whose_distance_is_inside_them_are_open(box_on_floor):
    """A distance spanning a pixel or two on the far floor and a few pixels at the box:
    the far floor stays open (no speckles where the search's steps are a pixel apart, nor
    at the image border, where they are clamped onto the screen), the contact darkens.
    A distance inside every pixel: nothing is searched, and every pixel is exactly 1."""
    scene = box_on_floor
    scene.csm.ao_distance = 0.08
    scene.csm.debug_view = 'AMBIENT_OCCLUSION'
    images = render_result(scene, 320, 240).images
    gap = floor_gap(images)
    ao = images["combined"][..., 0]
    far = (gap > 8.0) & (gap < 12.0)
    near = gap < 0.03
    assert far.sum() > 500 and near.sum() > 20
    print(f"distance 0.08: far floor AO min {ao[far].min():.6f}, at the box mean "
          f"{ao[near].mean():.3f}")
    assert ao[far].min() > 0.999
    assert ao[near].mean() < 0.9
    scene.csm.ao_distance = 0.001                  # inside every pixel
    images = render_result(scene, 320, 240).images
    covered = images["aux"][..., 3] > 0.5
    assert np.all(images["combined"][..., 0][covered] == 1.0)


def test_strength_zero_has_no_effect(box_on_floor):
    scene = box_on_floor
    scene.csm.ao_strength = 0.0
    with_zero = render_result(scene, 160, 120).images["combined"]
    scene.csm.ambient_occlusion = False
    off = render_result(scene, 160, 120).images["combined"]
    assert np.array_equal(with_zero, off)
    scene.csm.ambient_occlusion = True
    scene.csm.ao_strength = 0.5
    half = luma(render_result(scene, 160, 120).images)
    scene.csm.ao_strength = 1.0
    full = luma(render_result(scene, 160, 120).images)
    darkened = full < luma({"combined": off}) - 0.02
    assert darkened.sum() > 50
    # Strength blends: half strength darkens half as much.
    assert np.allclose((luma({"combined": off}) - half)[darkened],
                       0.5 * (luma({"combined": off}) - full)[darkened], atol=2e-3)


def band_width(scene, distance):
    """How far from the box (m) the floor's AO stays below 0.97, along the floor."""
    scene.csm.ao_distance = distance
    scene.csm.debug_view = 'AMBIENT_OCCLUSION'
    images = render_result(scene, 320, 240).images
    gap = floor_gap(images)
    ao = images["combined"][..., 0]
    bins = np.arange(0.0, 3.0, 0.05)
    means = [ao[(gap >= b) & (gap < b + 0.05)].mean() for b in bins]
    below = [b for b, m in zip(bins, means) if m < 0.97]
    return max(below) + 0.05 if below else 0.0


def test_distance_scales_the_darkened_band(box_on_floor):
    narrow = band_width(box_on_floor, 0.5)
    wide = band_width(box_on_floor, 1.0)
    print(f"band below AO 0.97: distance 0.5 -> {narrow:.2f} m, 1.0 -> {wide:.2f} m")
    assert 0.15 < narrow < 0.5 and 0.3 < wide < 1.0
    assert 1.5 < wide / narrow < 2.5


def test_ao_darkens_only_the_ambient_light(box_on_floor):
    """Sun and World together: what AO takes away is exactly what it takes from the World
    alone, so the sun's direct light is unchanged (also where the sun lights the floor)."""
    scene = box_on_floor
    add_sun((0.5, 0.3, -1.0))

    def difference():
        scene.csm.ambient_occlusion = True
        on = render_result(scene, 160, 120).images
        scene.csm.ambient_occlusion = False
        off = render_result(scene, 160, 120).images
        return luma(on) - luma(off), on

    both, images = difference()
    sun_lit = images["aux"][..., 0] > 0.99
    set_world_color(scene, (0.0, 0.0, 0.0))
    sun_only, _ = difference()
    assert np.abs(sun_only).max() < 1e-4, "no ambient light: AO changes nothing"
    set_world_color(scene, (WORLD, WORLD, WORLD))
    scene.objects["Sun"].hide_render = True
    world_only, _ = difference()
    assert (world_only < -0.02).sum() > 30
    assert (sun_lit & (world_only < -0.02)).sum() > 10, "some sun-lit pixels are occluded"
    assert np.allclose(both, world_only, atol=2e-3)


def test_debug_view_shows_the_ambient_factor(box_on_floor):
    scene = box_on_floor
    lit = luma(render_result(scene, 160, 120).images)
    scene.csm.debug_view = 'AMBIENT_OCCLUSION'
    images = render_result(scene, 160, 120).images
    shown = images["combined"][..., :3]
    covered = images["aux"][..., 3] > 0.5
    assert np.allclose(shown[..., 0], shown[..., 1]) and np.allclose(shown[..., 0], shown[..., 2])
    ao = shown[..., 0]
    assert ao[covered].min() < 0.6 and np.percentile(ao[covered], 50) > 0.97
    # The lit image is the World times albedo times the factor shown.
    assert np.allclose(lit[covered], (WORLD * ALBEDO * ao)[covered], atol=2e-3)
    scene.csm.ambient_occlusion = False
    images = render_result(scene, 160, 120).images
    assert np.allclose(images["combined"][..., 0][covered], 1.0)


# Mean absolute error of CSM's AO against Cycles' sky visibility on the scene below, at
# 160x120: measured 0.053 (pip bpy 5.0.1, llvmpipe; Cycles 256 samples): the 7x7
# half-resolution blur is a tenth of this small image wide and softens the contacts.
CYCLES_MAE_BOUND = 0.06


def test_error_against_cycles_on_a_small_scene(empty_scene, tmp_path):
    from csm_engine.blender import engine
    scene = empty_scene
    set_world_color(scene, (1.0, 1.0, 1.0))
    white = principled("white", (1.0, 1.0, 1.0), 1.0)
    bsdf = white.node_tree.nodes["Principled BSDF"]
    for name in ("Specular IOR Level", "Specular"):
        if name in bsdf.inputs:
            bsdf.inputs[name].default_value = 0.0
    for obj in (add_ground(6), add_box((0, 0, 0.6), (0.6, 0.6, 0.6))):
        obj.data.materials.append(white)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(1.4, -0.6, 0.5))
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(white)
    add_camera(scene, (4.5, -5.5, 4.0), (0.3, -0.2, 0.3))
    scene.render.resolution_x, scene.render.resolution_y = 160, 120
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    # CSM: AO with a distance beyond the whole scene, shown through the debug view.
    scene.csm.ambient_occlusion = True
    scene.csm.ao_distance = 50.0
    scene.csm.debug_view = 'AMBIENT_OCCLUSION'
    result = engine.render_final(scene, keep_images=True)
    assert result.error is None, result.error
    csm_ao = result.images["combined"][..., 0]
    covered = result.images["aux"][..., 3] > 0.5
    # Cycles: white World, white diffuse, direct light only = cosine-weighted visibility.
    cycles = scene.cycles
    cycles.device, cycles.samples, cycles.max_bounces = 'CPU', 256, 0
    cycles.use_denoising = False
    cycles.use_adaptive_sampling = False
    cycles.pixel_filter_type, cycles.filter_width = 'GAUSSIAN', 0.01  # box: 1 px always
    reference = blender_render(scene, 'CYCLES', os.path.join(str(tmp_path), "cycles.exr"))
    reference = reference[..., 0]
    inner = covered.copy()
    for axis in (0, 1):
        for shift in (1, -1):
            inner &= np.roll(covered, shift, axis=axis)
    error = np.abs(csm_ao - reference)[inner]
    print(f"AO against Cycles: mean abs. error {error.mean():.4f}, "
          f"95th percentile {np.percentile(error, 95):.3f} over {inner.sum()} pixels")
    assert inner.sum() > 0.3 * inner.size
    assert error.mean() < CYCLES_MAE_BOUND

