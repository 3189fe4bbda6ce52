"""The same exposure as EEVEE: a scene switched between EEVEE and CSM keeps its brightness.

Each case renders one scene with both engines, shadows off on every light, one EEVEE
sample, no AO or bloom, the Standard view transform and an opaque film, and compares the
mean linear brightness of the pixels both engines light (CSM's coverage, eroded by a pixel
so anti-aliased edges do not count). EEVEE's float pixels come from its render result saved
as OpenEXR (linear, no view transform) and loaded back (``tests.bpy.scenes.render_eevee``).
Units and conventions: docs/lighting.md.
"""
import math
import os

import bpy
import numpy as np
import pytest

from csm_engine.core import paths
from tests.bpy.scenes import (add_box, add_camera, add_ground, add_light, add_sun, principled,
                              render_eevee, set_world_color)

WIDTH, HEIGHT = 160, 120
TOLERANCE = 0.03            # CSM's mean brightness within 3% of EEVEE's
LUMA = np.array([0.2126, 0.7152, 0.0722])


def _set_if_present(owner, name, value):
    if hasattr(owner, name):
        setattr(owner, name, value)


def _prepare(scene):
    render = scene.render
    render.resolution_x, render.resolution_y = WIDTH, HEIGHT
    render.resolution_percentage = 100
    render.film_transparent = False
    render.filter_size = 0.01       # box-like pixels: edges blur the same in both engines
    scene.view_settings.view_transform = 'Standard'
    scene.view_settings.look = 'None'
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    eevee = scene.eevee
    eevee.taa_render_samples = 1
    for name in ("use_gtao", "use_bloom", "use_ssr", "use_motion_blur", "use_volumetric_lights",
                 "use_raytracing", "use_fast_gi", "use_shadows"):
        _set_if_present(eevee, name, False)
    for obj in scene.objects:
        if obj.type == 'LIGHT':
            obj.data.use_shadow = False


def _luma(rgba):
    return rgba[..., :3] @ LUMA


def render_csm(scene):
    """CSM's linear combined pass and its coverage, rows bottom-up."""
    from csm_engine.blender import engine
    scene.render.engine = "CSM"
    result = engine.render_final(scene, keep_images=True)
    assert result.error is None, result.error
    return result.images["combined"], result.images["aux"][..., 3] > 0.5


def _eroded(mask):
    inner = mask.copy()
    inner[1:, :] &= mask[:-1, :]
    inner[:-1, :] &= mask[1:, :]
    inner[:, 1:] &= mask[:, :-1]
    inner[:, :-1] &= mask[:, 1:]
    return inner


def exposure_ratio(scene, folder):
    """Mean CSM brightness / mean EEVEE brightness over the pixels lit in both, and how
    many pixels that is."""
    _prepare(scene)
    csm, covered = render_csm(scene)
    eevee = render_eevee(scene, folder)
    assert csm.shape == eevee.shape, (csm.shape, eevee.shape)
    csm_luma, eevee_luma = _luma(csm), _luma(eevee)
    lit = _eroded(covered) & (csm_luma > 1e-4) & (eevee_luma > 1e-4)
    assert lit.sum() > 0.05 * lit.size, f"only {lit.sum()} pixels lit in both"
    ratio = float(csm_luma[lit].mean() / eevee_luma[lit].mean())
    print(f"exposure {scene.name}: CSM/EEVEE = {ratio:.3f} over {int(lit.sum())} pixels "
          f"(CSM {csm_luma[lit].mean():.4f}, EEVEE {eevee_luma[lit].mean():.4f})")
    return ratio, int(lit.sum())


def assert_same_exposure(scene, folder):
    ratio, _ = exposure_ratio(scene, folder)
    assert abs(ratio - 1.0) <= TOLERANCE, \
        f"CSM is {ratio:.3f}x EEVEE's brightness on lit pixels (allowed 1 +- {TOLERANCE})"
    return ratio


# ---- scenes ------------------------------------------------------------------------------

def _named(scene, name):
    scene.name = name
    return scene


def test_sun_only(empty_scene, tmp_path):
    scene = _named(empty_scene, "sun_only")
    set_world_color(scene, (0.0, 0.0, 0.0))
    add_ground(20)
    add_box((0, 0, 1), (1, 1, 1))
    bpy.ops.mesh.primitive_monkey_add(location=(3, 1, 1.2))
    sun = add_sun((0.3, 0.5, -1.0))
    sun.data.energy = 2.0                                   # W/m^2
    add_camera(scene, (9, -9, 7), (0, 0, 0.5))
    assert_same_exposure(scene, tmp_path)


@pytest.mark.parametrize("roughness", [1.0, 0.2])
def test_sun_on_white_principled(empty_scene, tmp_path, roughness):
    """A white surface, fully rough and glossy: the normalized specular lobe does not make
    CSM brighter than EEVEE."""
    scene = _named(empty_scene, f"sun_white_roughness_{roughness}")
    set_world_color(scene, (0.0, 0.0, 0.0))
    white = principled("white", (1.0, 1.0, 1.0), roughness)
    for obj in (add_ground(20), add_box((0, 0, 1), (1, 1, 1))):
        obj.data.materials.append(white)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(-3, 1, 1), segments=48,
                                         ring_count=24)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(white)
    add_sun((0.4, 0.3, -1.0))
    add_camera(scene, (8, -9, 7), (0, 0, 0.5))
    assert_same_exposure(scene, tmp_path)


def test_point_light_physical_falloff(empty_scene, tmp_path):
    scene = _named(empty_scene, "point_only")
    set_world_color(scene, (0.0, 0.0, 0.0))
    add_ground(20)
    add_box((1.5, 0.5, 0.5), (0.5, 0.5, 0.5))
    add_light('POINT', (0, 0, 2.5), 1000.0, shadow_soft_size=0.05)
    add_camera(scene, (7, -7, 6), (0, 0, 0))
    assert_same_exposure(scene, tmp_path)


def test_spot_light(empty_scene, tmp_path):
    scene = _named(empty_scene, "spot_only")
    set_world_color(scene, (0.0, 0.0, 0.0))
    add_ground(20)
    bpy.ops.mesh.primitive_monkey_add(location=(0, 0, 1))
    add_light('SPOT', (2, -2, 5), 2000.0, target=(0, 0, 0), spot_size=math.radians(60),
              spot_blend=0.2, shadow_soft_size=0.05)
    add_camera(scene, (7, -7, 6), (0, 0, 0))
    assert_same_exposure(scene, tmp_path)


def test_world_colour_as_ambient(empty_scene, tmp_path):
    """No lamps: a uniform World of radiance L lights a diffuse surface with L * albedo."""
    scene = _named(empty_scene, "world_only")
    set_world_color(scene, (0.3, 0.3, 0.3))
    add_ground(20)
    add_box((0, 0, 1), (1, 1, 1))
    add_camera(scene, (7, -7, 6), (0, 0, 0))
    assert_same_exposure(scene, tmp_path)


def _import_bundled(name):
    from csm_engine.blender import cli
    scene = cli.open_scene(os.path.join(paths.data_dir(), "scenes", f"{name}.json"))
    return _named(scene, f"bundled_{name}")


@pytest.mark.parametrize("name", ["default", "shadow_test"])
def test_bundled_scene(name, tmp_path):
    scene = _import_bundled(name)
    assert_same_exposure(scene, tmp_path)


def test_bundled_point_lights_scene_sun_and_sky(tmp_path):
    """The course's point lights fall off linearly to their radius in CSM (as the course
    draws them) and by the inverse square in EEVEE: a deliberate difference. The rest of the
    scene (its dim sun and the sky as ambient) is compared with them switched off, and the
    whole scene's ratio is printed for the record."""
    scene = _import_bundled("point_lights")
    points = [obj for obj in scene.objects if obj.type == 'LIGHT' and obj.data.type == 'POINT']
    assert len(points) == 6 and all("csm_radius" in obj.data for obj in points)
    exposure_ratio(scene, tmp_path)
    for obj in points:
        obj.hide_render = True
    assert_same_exposure(scene, tmp_path)


def test_operator_scene_monkey_plane_sun_and_point(empty_scene, tmp_path):
    scene = _named(empty_scene, "monkey_plane_sun_point")
    set_world_color(scene, (0.05, 0.05, 0.06))
    bpy.ops.mesh.primitive_plane_add(size=12)
    bpy.ops.mesh.primitive_monkey_add(location=(0, 0, 1.2))
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(principled("red", (0.8, 0.1, 0.05), 0.4))
    add_light('SUN', (0, 0, 10), 1.5, target=(-2, -3, 0))
    add_light('POINT', (2.5, -1.5, 2.0), 300.0, shadow_soft_size=0.05,
              color=(1.0, 0.8, 0.6))
    add_camera(scene, (5, -7, 4), (0, 0, 1))
    assert_same_exposure(scene, tmp_path)


def test_operator_scene_sphere_grid_spot_and_point(empty_scene, tmp_path):
    """A grid of UV spheres of several colours and roughnesses under a spot and a point
    light. The area light the scene also has is hidden from both renders: CSM does not draw
    area lights (nor does the course), so EEVEE alone would count it."""
    scene = _named(empty_scene, "sphere_grid")
    set_world_color(scene, (0.02, 0.02, 0.02))
    bpy.ops.mesh.primitive_plane_add(size=16)
    colours = [(0.8, 0.8, 0.8), (0.2, 0.5, 0.8), (0.8, 0.6, 0.1)]
    for i in range(3):
        for j in range(3):
            bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(2.2 * i - 2.2,
                                                                       2.2 * j - 2.2, 0.8))
            bpy.ops.object.shade_smooth()
            bpy.context.object.data.materials.append(
                principled(f"m{i}{j}", colours[i], (0.3, 0.6, 1.0)[j]))
    add_light('SPOT', (-3, -4, 6), 3000.0, target=(0, 0, 0), spot_size=math.radians(70),
              spot_blend=0.3, shadow_soft_size=0.05)
    add_light('POINT', (3, 3, 3), 800.0, shadow_soft_size=0.05, color=(0.7, 0.8, 1.0))
    area = add_light('AREA', (0, 0, 6), 500.0)
    area.hide_render = True
    add_camera(scene, (8, -10, 8), (0, 0, 0.5))
    assert_same_exposure(scene, tmp_path)


# ---- the units themselves ------------------------------------------------------------------

def test_point_light_falls_off_by_the_inverse_square_in_watts(empty_scene):
    """A physical point light of P watts is P / (4 pi) W/sr: a ground point at distance d
    under it, at angle theta, sends back albedo / pi * P / (4 pi d^2) * cos(theta)."""
    from tests.bpy.bpy_helpers import render_scene
    scene = empty_scene
    set_world_color(scene, (0.0, 0.0, 0.0))
    rough = principled("rough", (0.8, 0.8, 0.8), 1.0)      # no specular lobe in CSM
    add_ground(40).data.materials.append(rough)
    power = 400.0 * math.pi                                 # 100 W/sr
    add_light('POINT', (0, 0, 1.0), power, shadow_soft_size=0.01)
    add_camera(scene, (0, 0, 10), (0, 0, 0)).data.type = 'ORTHO'
    scene.camera.data.ortho_scale = 20.0
    images = render_scene(scene, 200, 200)
    brightness = images["combined"][100, 100:, 0]
    x = images["position"][100, 100:, 0]
    d = np.sqrt(x ** 2 + 1.0)
    radius = math.sqrt(power / 100.0 / scene.eevee.light_threshold)   # EEVEE's influence
    window = np.clip(1.0 - (d / radius) ** 4, 0.0, 1.0) ** 2
    expected = 0.8 / math.pi * power / (4.0 * math.pi * d ** 2) * (1.0 / d) * window
    assert np.allclose(brightness, expected, rtol=0.02, atol=1e-3), \
        np.c_[d, brightness, expected][::20]


def test_course_lights_fall_off_linearly_and_others_physically(empty_scene):
    """Per light (the default): a light the course importer made (custom property
    csm_radius) keeps the course's linear falloff; a light made in Blender is physical.
    The Light Falloff setting overrides both."""
    from csm_engine.blender import snapshot
    scene = empty_scene
    course = add_light('POINT', (0, 0, 3), 100.0)
    course.data["csm_radius"] = 30.0
    course.data.use_custom_distance = True
    course.data.cutoff_distance = 30.0
    add_light('SPOT', (2, 0, 3), 1000.0)
    add_light('POINT', (-2, 0, 3), 1000.0)
    add_camera(scene, (0, -8, 3), (0, 0, 0))
    assert scene.csm.light_falloff == 'PER_LIGHT'

    def falloffs():
        depsgraph = bpy.context.evaluated_depsgraph_get()
        camera = snapshot.camera_from_scene(scene, depsgraph, 64, 64)
        snap = snapshot.take(depsgraph, camera)
        return sorted((light.falloff, round(float(light.radius), 3))
                      for light in snap.points + snap.spots)

    threshold_radius = round(math.sqrt(10.0 / scene.eevee.light_threshold), 3)
    assert falloffs() == [('LINEAR_RADIUS', 30.0), ('PHYSICAL', threshold_radius),
                          ('PHYSICAL', threshold_radius)]
    scene.csm.light_falloff = 'PHYSICAL'
    assert falloffs() == [('PHYSICAL', 30.0), ('PHYSICAL', threshold_radius),
                          ('PHYSICAL', threshold_radius)]
    scene.csm.light_falloff = 'LINEAR_RADIUS'
    assert [f for f, _ in falloffs()] == ['LINEAR_RADIUS'] * 3
