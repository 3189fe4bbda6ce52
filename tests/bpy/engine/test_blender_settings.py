"""Blender's own settings mean what they mean in EEVEE and Cycles, checked in pixels:
per-object ray visibility (Camera, Shadow), an environment texture as the World, and the
Output > Render Region with and without Crop to Render Region."""
import math

import bpy
import numpy as np
import pytest

from csm_engine.blender import engine
from csm_engine.blender.compat import enable_shading_nodes
from tests.bpy.bpy_helpers import load_png, render_scene
from tests.bpy.scenes import add_box, add_camera, add_ground, add_sun, set_world_color

WIDTH, HEIGHT = 160, 120


@pytest.fixture
def box_on_ground(empty_scene):
    """A box on lit ground seen from above; its shadow falls to +X of it."""
    scene = empty_scene
    add_ground(20)
    box = add_box((0, 0, 1), (1, 1, 1))
    add_sun((1.0, 0.0, -1.0)).data.energy = math.pi
    camera = add_camera(scene, (0, 0, 20), (0, 0, 0))
    camera.data.type = 'ORTHO'
    camera.data.ortho_scale = 12.0
    set_world_color(scene, (0.05, 0.05, 0.05))
    scene.csm.render_samples = 1
    scene.csm.fxaa = False
    return scene, box


def _pixel(x, y):
    """Image row and column of world point (x, y, 0) under the top camera above."""
    scale = WIDTH / 12.0
    return int(HEIGHT / 2 - y * scale), int(WIDTH / 2 + x * scale)


def test_an_object_hidden_from_the_camera_still_casts_its_shadow(box_on_ground):
    scene, box = box_on_ground
    images = render_scene(scene, WIDTH, HEIGHT)
    top = images["aux"][_pixel(0, 0)]
    shadow = images["aux"][_pixel(2.0, 0)]
    assert top[2] < 19.5 and shadow[0] < 0.5       # the box's top is seen; its shadow lies at +X

    box.visible_camera = False
    images = render_scene(scene, WIDTH, HEIGHT)
    under = images["aux"][_pixel(0, 0)]
    assert under[2] == pytest.approx(20.0, abs=0.05), "the ground is seen where the box was"
    assert images["aux"][_pixel(2.0, 0)][0] < 0.5, "the hidden box still shadows the ground"


def test_an_object_with_shadow_visibility_off_casts_no_shadow(box_on_ground):
    scene, box = box_on_ground
    box.visible_shadow = False
    images = render_scene(scene, WIDTH, HEIGHT)
    assert images["aux"][_pixel(0, 0)][2] < 19.5, "the box itself is still drawn"
    assert images["aux"][_pixel(2.0, 0)][0] == 1.0
    ground = images["aux"][..., 2] > 19.5
    # (Flat lit ground reads 0.99-1.0 with the default filter: see docs/shadow-acne.md.)
    assert images["aux"][..., 0][ground].min() > 0.98


def test_an_environment_texture_lights_by_the_irradiance_of_the_normal(empty_scene):
    """No lights: a diffuse plane facing up shows albedo x the irradiance / pi the
    environment sends it. Upper half red 2.0 and lower half blue 1.0 of an
    equirectangular map: the plane sees the red half only, (2.0, 0, 0) (the second band of
    the spherical harmonics gives a hemisphere's step exactly here), not the mean over the
    sphere (1.0, 0, 0.5); the background keeps the mean."""
    scene = empty_scene
    ground = add_ground(20)
    material = bpy.data.materials.new("diffuse")
    enable_shading_nodes(material)
    bsdf = next(n for n in material.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    next(bsdf.inputs[n] for n in ("Specular IOR Level", "Specular")
         if bsdf.inputs.get(n)).default_value = 0.0
    ground.data.materials.append(material)
    camera = add_camera(scene, (0, 0, 10), (0, 0, 0))
    camera.data.type = 'ORTHO'
    camera.data.ortho_scale = 4.0
    image = bpy.data.images.new("sky", 64, 32, float_buffer=True)
    pixels = np.zeros((32, 64, 4), dtype=np.float32)
    pixels[16:] = (2.0, 0.0, 0.0, 1.0)       # rows run bottom-up: 16.. is the upper half
    pixels[:16] = (0.0, 0.0, 1.0, 1.0)
    image.pixels.foreach_set(pixels.ravel())
    world = bpy.data.worlds.new("env")
    enable_shading_nodes(world)
    nodes = world.node_tree.nodes
    environment = nodes.new("ShaderNodeTexEnvironment")
    environment.image = image
    background = next(n for n in nodes if n.type == 'BACKGROUND')
    background.inputs[1].default_value = 0.5
    world.node_tree.links.new(environment.outputs["Color"], background.inputs["Color"])
    scene.world = world
    scene.csm.render_samples = 1
    color = render_scene(scene, 32, 32)["combined"][16, 16, :3]
    albedo = 0.8                              # the Principled BSDF's default base colour
    assert color == pytest.approx(np.array([2.0, 0.0, 0.0]) * 0.5 * albedo, abs=0.01)


@pytest.mark.parametrize("crop", [False, True])
def test_render_region_renders_the_region_of_the_full_image(box_on_ground, tmp_path, crop):
    scene, _box = box_on_ground
    render = scene.render
    render.resolution_x, render.resolution_y = WIDTH, HEIGHT
    render.image_settings.file_format = 'PNG'
    render.image_settings.color_mode = 'RGBA'
    render.film_transparent = True
    render.dither_intensity = 0.0     # exact 8-bit values in both files
    render.filepath = str(tmp_path / "full.png")
    assert engine.render_final(scene, write_still=True).error is None
    full = load_png(tmp_path / "full.png")

    render.use_border = True
    render.use_crop_to_border = crop
    render.border_min_x, render.border_max_x = 0.25, 0.75
    render.border_min_y, render.border_max_y = 0.5, 1.0
    render.filepath = str(tmp_path / "region.png")
    assert engine.render_final(scene, write_still=True).error is None
    region = load_png(tmp_path / "region.png")
    rows, cols = slice(0, HEIGHT // 2), slice(WIDTH // 4, 3 * WIDTH // 4)   # top rows first
    if crop:
        assert region.shape[:2] == (HEIGHT // 2, WIDTH // 2)
        assert np.abs(region - full[rows, cols]).max() < 1.5 / 255
    else:
        assert region.shape[:2] == (HEIGHT, WIDTH)
        assert np.abs(region[rows, cols] - full[rows, cols]).max() < 1.5 / 255
        outside = np.ones((HEIGHT, WIDTH), dtype=bool)
        outside[rows, cols] = False
        assert region[outside][:, 3].max() == 0.0, "nothing is drawn outside the region"
