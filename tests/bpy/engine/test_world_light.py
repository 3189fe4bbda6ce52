"""The World's light per normal: an environment image lights each side of an object by its
own irradiance, not by one average colour.

A float environment image (made in numpy, linear) whose radiance varies with the direction,
0.5 + 0.15 x + 0.3 z + 0.05 z^2 in red and other mixes in green and blue, feeds the World's
Background through an Environment Texture; a white diffuse sphere (Specular IOR Level 0)
under no lamp, AO off, is seen from the side by an orthographic camera. Each pixel of the
sphere must show albedo x E(n) / pi, E the irradiance of its normal integrated over the
image's pixels in numpy (the reference, independent of the spherical harmonics CSM uses),
within 2 %. The average colour (what a uniform World gives) misses by 20 % or more.
"""
import bpy
import numpy as np

from csm_engine.blender.compat import enable_shading_nodes
from tests.bpy.bpy_helpers import render_scene
from tests.bpy.scenes import add_camera

HEIGHT, WIDTH = 64, 128


def _directions():
    """World directions of the image's pixel centres, row 0 at the bottom, with Blender's
    Environment Texture mapping (u = atan2(y, -x) / 2pi + 0.5, v = latitude / pi + 0.5)."""
    u = (np.arange(WIDTH) + 0.5) / WIDTH
    v = (np.arange(HEIGHT) + 0.5) / HEIGHT
    theta, latitude = 2 * np.pi * (u - 0.5), np.pi * (v - 0.5)
    cos_lat = np.cos(latitude)[:, None]
    return np.stack([-np.cos(theta)[None] * cos_lat, np.sin(theta)[None] * cos_lat,
                     np.broadcast_to(np.sin(latitude)[:, None], (HEIGHT, WIDTH))], -1)


def _radiance(d):
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([0.5 + 0.15 * x + 0.3 * z + 0.05 * z * z,
                     0.4 - 0.2 * y + 0.1 * x,
                     0.3 + 0.25 * z * z - 0.1 * x], -1)


def _irradiance(normals, d, radiance):
    latitude = np.pi * ((np.arange(HEIGHT) + 0.5) / HEIGHT - 0.5)
    solid_angle = np.broadcast_to((2 * np.pi / WIDTH) * (np.pi / HEIGHT) *
                                  np.cos(latitude)[:, None], (HEIGHT, WIDTH))
    cos = np.clip(normals.reshape(-1, 3) @ d.reshape(-1, 3).T, 0.0, None)
    return cos @ (radiance.reshape(-1, 3) * solid_angle.reshape(-1, 1))


def test_environment_lights_each_normal_by_its_irradiance(empty_scene):
    scene = empty_scene
    d = _directions()
    radiance = _radiance(d)
    image = bpy.data.images.new("sky", WIDTH, HEIGHT, float_buffer=True)
    rgba = np.concatenate([radiance, np.ones((HEIGHT, WIDTH, 1))], -1)
    image.pixels.foreach_set(rgba.astype(np.float32).ravel())
    world = bpy.data.worlds.new("World")
    scene.world = world
    enable_shading_nodes(world)
    tree = world.node_tree
    environment = tree.nodes.new('ShaderNodeTexEnvironment')
    environment.image = image
    background = next(n for n in tree.nodes if n.type == 'BACKGROUND')
    tree.links.new(environment.outputs["Color"], background.inputs["Color"])
    material = bpy.data.materials.new("white diffuse")
    enable_shading_nodes(material)
    bsdf = next(n for n in material.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    next(bsdf.inputs[n] for n in ("Specular IOR Level", "Specular")
         if bsdf.inputs.get(n)).default_value = 0.0
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(material)
    camera = add_camera(scene, (6.0, -3.0, 2.0), (0.0, 0.0, 0.0))
    camera.data.type = 'ORTHO'
    camera.data.ortho_scale = 2.5
    scene.csm.ambient_occlusion = False
    images = render_scene(scene, 64, 64)
    covered = images["aux"][..., 3] > 0.5
    inner = covered.copy()
    inner[1:-1, 1:-1] &= covered[:-2, 1:-1] & covered[2:, 1:-1] & covered[1:-1, :-2] & \
        covered[1:-1, 2:]
    normals = images["normal"][..., :3][inner].astype(np.float64)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    expected = 0.8 * _irradiance(normals, d, radiance) / np.pi
    shown = images["combined"][..., :3][inner]
    relative = np.abs(shown - expected) / expected
    average = 0.8 * (radiance * np.cos(np.pi * ((np.arange(HEIGHT) + 0.5) / HEIGHT - 0.5))
                     [:, None, None]).sum((0, 1)) / (np.cos(np.pi * ((np.arange(HEIGHT) + 0.5)
                                                               / HEIGHT - 0.5)).sum() * WIDTH)
    uniform_error = np.abs(average - expected) / expected
    print(f"{inner.sum()} pixels: relative error max {relative.max():.4f}, mean "
          f"{relative.mean():.4f}; a uniform World's max {uniform_error.max():.3f}")
    assert inner.sum() > 500
    assert uniform_error.max() > 0.2
    assert relative.max() < 0.02, relative.max()
