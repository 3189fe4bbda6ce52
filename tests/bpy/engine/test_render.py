"""The deferred renderer as a user sees it: materials, lights, camera and output options."""
import math
import resource

import bpy
import numpy as np
import pytest

from csm_engine.blender.compat import enable_shading_nodes
from tests.bpy.bpy_helpers import render_scene
from tests.bpy.scenes import add_box, add_camera, add_ground, add_sun, set_world_color


def _principled(material):
    enable_shading_nodes(material)
    return next(n for n in material.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')


def _checker_image(name, alpha_holes=False, size=64):
    """Left half red, right half blue; with alpha_holes the right half is transparent."""
    image = bpy.data.images.new(name, size, size, alpha=True)
    pixels = np.zeros((size, size, 4), dtype=np.float32)
    pixels[:, : size // 2] = (1.0, 0.0, 0.0, 1.0)
    pixels[:, size // 2:] = (0.0, 0.0, 1.0, 0.0 if alpha_holes else 1.0)
    image.pixels.foreach_set(pixels.ravel())
    image.pack()
    return image


def _textured_plane(image, cutoff=None, location=(0, 0, 0), size=4.0):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    plane = bpy.context.object
    material = bpy.data.materials.new(image.name)
    bsdf = _principled(material)
    node = material.node_tree.nodes.new('ShaderNodeTexImage')
    node.image = image
    material.node_tree.links.new(node.outputs["Color"], bsdf.inputs["Base Color"])
    if cutoff is not None:
        material.node_tree.links.new(node.outputs["Alpha"], bsdf.inputs["Alpha"])
        if hasattr(material, "blend_method"):
            material.blend_method = 'CLIP'
        if hasattr(material, "alpha_threshold"):
            material.alpha_threshold = cutoff
    plane.data.materials.append(material)
    return plane


def _top_camera(scene, height=10.0, ortho_scale=None):
    camera = add_camera(scene, (0, 0, height), (0, 0, 0))
    if ortho_scale:
        camera.data.type = 'ORTHO'
        camera.data.ortho_scale = ortho_scale
    return camera


def test_base_colour_texture_is_sampled(empty_scene):
    scene = empty_scene
    _textured_plane(_checker_image("checker"))
    # pi W/m^2: the Lambert surface sends back albedo x cos (docs/lighting.md).
    add_sun((0, 0, -1)).data.energy = math.pi
    _top_camera(scene, ortho_scale=4.0)
    color = render_scene(scene, 64, 64)["combined"]
    left, right = color[32, 8, :3], color[32, 56, :3]
    # A white specular highlight adds equally to every channel; the texture decides the rest.
    assert left[0] > left[2] + 0.5, f"left half shows the red texels, got {left}"
    assert right[2] > right[0] + 0.5, f"right half shows the blue texels, got {right}"


def test_alpha_masked_material_is_cut_out_of_image_and_shadow(empty_scene):
    scene = empty_scene
    set_world_color(scene, (0.0, 0.0, 0.0))
    add_ground(40)
    _textured_plane(_checker_image("leaf", alpha_holes=True), cutoff=0.5,
                    location=(0, 0, 2.0), size=4.0)
    add_sun((0, 0, -1))
    _top_camera(scene, height=20.0, ortho_scale=8.0)
    images = render_scene(scene, 128, 128)
    height = images["position"][..., 2]
    # Left half of the leaf is opaque (z = 2); through the right half we see the ground.
    assert abs(height[64, 40] - 2.0) < 1e-3
    assert abs(height[64, 88]) < 1e-3
    # The ground under the opaque half is shadowed; under the holes it is lit.
    bpy.data.objects["Plane.001"].hide_render = False
    visibility = images["aux"][..., 0]
    ground_shadow = images["combined"][..., :3].sum(axis=2)
    assert visibility[64, 88] > 0.99
    assert ground_shadow[64, 88] > 0.3


def test_point_light_falls_off_linearly_to_its_radius(empty_scene):
    scene = empty_scene
    add_ground(40)
    bpy.ops.object.light_add(type='POINT', location=(0, 0, 1.0))
    light = bpy.context.object.data
    light.energy = 100.0                      # intensity multiplier 1 (power / 100 W)
    light.use_custom_distance = True
    light.cutoff_distance = 6.0
    scene.csm.light_falloff = 'LINEAR_RADIUS'  # the course's falloff (docs/lighting.md)
    set_world_color(scene, (0.0, 0.0, 0.0))
    _top_camera(scene, height=10.0, ortho_scale=20.0)
    images = render_scene(scene, 200, 200)
    brightness = images["combined"][100, 100:, 0]      # from the light outwards along +x
    x = images["position"][100, 100:, 0]
    distance = np.sqrt(x ** 2 + 1.0)
    inside, outside = distance < 5.5, distance > 6.05
    assert np.all(brightness[outside] == 0.0), "nothing beyond the radius"
    assert np.all(np.diff(brightness[inside]) <= 1e-4), "monotonic falloff"
    # Blinn-Phong diffuse: albedo 0.8 * cos * (1 - d/r) plus a small specular lobe.
    expected = 0.8 * (1.0 / distance) * (1.0 - distance / 6.0)
    assert np.allclose(brightness[inside & (distance > 2.0)],
                       expected[inside & (distance > 2.0)], atol=0.03)


def test_film_transparent_background_has_zero_alpha(empty_scene):
    scene = empty_scene
    add_box((0, 0, 0), (1, 1, 1))
    add_sun((0.3, 0.2, -1))
    add_camera(scene, (6, -6, 4), (0, 0, 0))
    scene.render.film_transparent = True
    color = render_scene(scene, 64, 64)["combined"]
    assert color[0, 0, 3] == 0.0 and color[32, 32, 3] == 1.0
    scene.render.film_transparent = False
    assert render_scene(scene, 64, 64)["combined"][0, 0, 3] == 1.0


def test_world_colour_is_background_and_ambient(empty_scene):
    scene = empty_scene
    ground = add_ground(20)
    diffuse = bpy.data.materials.new("diffuse")
    enable_shading_nodes(diffuse)
    bsdf = next(n for n in diffuse.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    next(bsdf.inputs[n] for n in ("Specular IOR Level", "Specular")
         if bsdf.inputs.get(n)).default_value = 0.0
    ground.data.materials.append(diffuse)
    set_world_color(scene, (0.2, 0.1, 0.05))
    add_camera(scene, (0, -8, 3), (0, 0, 0))
    images = render_scene(scene, 64, 64)
    color, covered = images["combined"], images["aux"][..., 3] > 0.5
    assert not covered[0, 0] and covered[63, 32]
    assert np.allclose(color[0, 0, :3], (0.2, 0.1, 0.05), atol=1e-4)    # sky
    # No lamp: the diffuse ground (Specular IOR Level 0) shows only ambient = World
    # colour x albedo 0.8.
    assert np.allclose(color[63, 32, :3], np.array((0.2, 0.1, 0.05)) * 0.8, atol=1e-3)


def test_orthographic_camera_and_resolution_percentage(empty_scene):
    scene = empty_scene
    add_ground(10)
    add_sun((0, 0, -1))
    _top_camera(scene, ortho_scale=20.0)       # the 10 m ground fills the middle half
    scene.render.resolution_percentage = 50
    scene.render.resolution_x, scene.render.resolution_y = 200, 200
    from csm_engine.blender import engine
    result = engine.render_final(scene, keep_images=True)
    covered = result.images["aux"][..., 3] > 0.5
    assert covered.shape == (100, 100)
    rows, cols = np.nonzero(covered)
    assert abs(rows.min() - 25) <= 1 and abs(rows.max() - 74) <= 1
    assert abs(cols.min() - 25) <= 1 and abs(cols.max() - 74) <= 1


def test_render_result_has_depth_normal_shadow_and_cascade_passes(empty_scene, tmp_path):
    scene = empty_scene
    add_ground(20)
    add_box((0, 0, 1), (1, 1, 1))
    add_sun((0.5, 0.3, -1))
    add_camera(scene, (0, -10, 6), (0, 0, 0))
    layer = scene.view_layers[0]
    layer.use_pass_z = True
    layer.use_pass_normal = True
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    bpy.ops.render.render()
    path = str(tmp_path / "passes.exr")
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):          # 5.0+: multilayer is a media type
        settings.media_type = 'MULTI_LAYER_IMAGE'
    settings.file_format = 'OPEN_EXR_MULTILAYER'
    bpy.data.images["Render Result"].save_render(filepath=path, scene=scene)
    with open(path, "rb") as handle:
        header = handle.read(4096)
    for name in (b"Depth", b"Normal", b"Shadow", b"Cascade", b"Combined"):
        assert name in header, f"pass {name!r} missing from the multilayer EXR"


def test_no_leak_over_500_renders(empty_scene):
    scene = empty_scene
    add_ground(10)
    add_box((0, 0, 1), (1, 1, 1))
    add_sun((0.5, 0.3, -1))
    add_camera(scene, (0, -10, 6), (0, 0, 0))
    scene.render.resolution_x, scene.render.resolution_y = 16, 16
    scene.csm.resolution = 256
    for _ in range(20):
        bpy.ops.render.render()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    for _ in range(500):
        bpy.ops.render.render()
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert grown_mb < 40, f"peak memory grew {grown_mb:.0f} MB over 500 renders"


@pytest.mark.parametrize("how", ["negative scale", "mirror modifier"])
def test_a_mirrored_object_is_lit_like_its_original(empty_scene, how):
    """Two boxes side by side, one an unmirrored original and one mirrored (negative X
    scale, or Blender's Mirror modifier applied on an object that is itself mirrored): the
    sunlit tops and sides of both show the same brightness, not ambient only."""
    scene = empty_scene
    set_world_color(scene, (0.02, 0.02, 0.02))
    # pi W/m^2: the Lambert surface sends back albedo x cos (docs/lighting.md).
    add_sun((0.3, 0.5, -1.0)).data.energy = math.pi
    add_box((-2, 0, 1), (1, 1, 1))                 # the original
    mirrored = add_box((2, 0, 1), (1, 1, 1))
    if how == "negative scale":
        mirrored.scale = (-1, 1, 1)
    else:
        mirrored.scale = (1, -1, 1)
        mirrored.modifiers.new("mirror", 'MIRROR')
    _top_camera(scene, height=20.0, ortho_scale=10.0)
    color = render_scene(scene, 200, 200)["combined"][..., :3].mean(axis=-1)
    left, right = color[90:110, 50:70], color[90:110, 130:150]     # the two box tops
    assert left.mean() > 0.3, f"the original's top is sunlit ({left.mean():.3f})"
    assert abs(right.mean() - left.mean()) < 0.02 * left.mean() + 0.005, \
        (left.mean(), right.mean())


def test_programs_dropped_outside_a_render_do_not_break_the_next_one(empty_scene, monkeypatch):
    """Regression: a shader library dropped (or replaced by F5) outside any render freed its
    GPU programs with Blender's own context current; the render context then ran its next
    full-screen draw with no vertex shader and the process segfaulted in llvmpipe (pip bpy
    5.0.1). Programs are now freed by the next draw, inside the render context."""
    import gc
    from csm_engine.core import paths
    from csm_engine.render import shaders

    for _ in range(3):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scene.render.engine = "CSM"
        add_ground(4)
        add_sun((0.5, 0.3, -1))
        add_camera(scene, (0, -6, 4), (0, 0, 0))
        temporary = shaders.ShaderLibrary(directory=paths.shaders_dir())
        monkeypatch.setattr(shaders, "LIBRARY", temporary)
        render_scene(scene, 48, 32)              # the temporary programs draw in the render
        monkeypatch.undo()
        render_scene(scene, 16, 16)              # ... then the shared ones do
        del temporary
        gc.collect()                             # dropped outside any render
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scene.render.engine = "CSM"
        add_camera(scene, (0, -6, 4), (0, 0, 0))
        image = render_scene(scene, 16, 16)["combined"]   # one full-screen lighting draw
        assert np.isfinite(image).all()
