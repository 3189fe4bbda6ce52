"""Anti-aliasing as a user sees it: straight edges without stair steps.

The scene is a white quad whose edge crosses an orthographic top view at a shallow angle,
lit from straight above on a black World. Summing each pixel column's brightness gives
where the edge crosses that column (in pixels, with sub-pixel precision when edge pixels
are partly covered). A stair-stepped edge makes those crossings a staircase around the
true straight line: the RMS distance from the best-fitting line is ~0.29 px for a hard,
aliased edge (a uniform rounding error) and near 0 for a well anti-aliased one.
"""
import math

import bpy
import gpu
import numpy as np
import pytest

from csm_engine.blender import snapshot
from csm_engine.render import pipeline
from tests.bpy.bpy_helpers import render_result, render_scene
from tests.bpy.scenes import add_sun, set_world_color

WIDTH, HEIGHT = 160, 120
EDGE_ANGLE_DEG = 7.0
ALBEDO = 0.8


def _edge_scene(scene):
    """A white quad filling the image below a line through its centre, tilted by
    EDGE_ANGLE_DEG, under a sun straight above (Strength pi: lit albedo = 0.8)."""
    mesh = bpy.data.meshes.new("half")
    mesh.from_pydata([(-50, -100, 0), (50, -100, 0), (50, 0, 0), (-50, 0, 0)], [],
                     [(0, 1, 2, 3)])
    quad = bpy.data.objects.new("half", mesh)
    scene.collection.objects.link(quad)
    quad.rotation_euler = (0.0, 0.0, math.radians(EDGE_ANGLE_DEG))
    material = bpy.data.materials.new("white")
    material.diffuse_color = (ALBEDO, ALBEDO, ALBEDO, 1.0)
    if bpy.app.version < (5, 0, 0):
        # The viewport colour renders. 5.0 always renders nodes: its new material's
        # Principled BSDF has the same 0.8 base colour.
        material.use_nodes = False
    mesh.materials.append(material)
    sun = add_sun((0.0, 0.0, -1.0))
    sun.data.energy = math.pi
    bpy.ops.object.camera_add(location=(0.0, 0.0, 10.0))
    camera = bpy.context.object
    camera.data.type = 'ORTHO'
    camera.data.ortho_scale = 8.0
    scene.camera = camera
    set_world_color(scene, (0.0, 0.0, 0.0))
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    return scene


def stair_step_error(image, margin=20):
    """RMS distance (pixels) of each column's edge crossing from the best straight line;
    ``image``: (H, W, >=3), top row first, lit quad below the edge."""
    lum = image[..., :3].mean(axis=-1)
    lum = lum / np.median(lum[-5:])                 # the lit quad's brightness is 1
    columns = np.arange(margin, image.shape[1] - margin)
    crossing = lum[:, columns].sum(axis=0)          # covered pixels in each column
    fit = np.polyfit(columns, crossing, 1)
    residual = crossing - np.polyval(fit, columns)
    slope = fit[0]
    return float(np.sqrt(np.mean(residual ** 2))), float(slope)


@pytest.fixture
def edge_scene(empty_scene):
    return _edge_scene(empty_scene)


def _render(scene, samples, fxaa):
    scene.csm.render_samples = samples
    scene.csm.fxaa = fxaa
    return render_scene(scene, WIDTH, HEIGHT)


def test_without_anti_aliasing_the_edge_is_a_staircase(edge_scene):
    image = _render(edge_scene, 1, False)["combined"]
    error, slope = stair_step_error(image)
    # Sanity of the set-up: the edge has the quad's slope, and pixels are 0 or lit.
    assert slope == pytest.approx(math.tan(math.radians(EDGE_ANGLE_DEG)), abs=0.01)
    lum = image[..., :3].mean(axis=-1)
    lum = lum / np.median(lum[-5:])
    assert np.isin(np.round(lum, 3), [0.0, 1.0]).mean() > 0.999
    assert error > 0.2, error


def test_render_samples_turn_the_staircase_into_a_straight_edge(edge_scene):
    aliased, _ = stair_step_error(_render(edge_scene, 1, False)["combined"])
    smooth, slope = stair_step_error(_render(edge_scene, 16, False)["combined"])
    assert slope == pytest.approx(math.tan(math.radians(EDGE_ANGLE_DEG)), abs=0.01)
    # Measured: 0.28 px aliased; 8 samples 0.086, 16 samples 0.043, 64 samples 0.018.
    assert smooth < 0.25 * aliased, (smooth, aliased)
    # Eight samples already remove most of it.
    default, _ = stair_step_error(_render(edge_scene, 8, False)["combined"])
    assert default < 0.45 * aliased, (default, aliased)


def test_fxaa_smooths_a_one_sample_render(edge_scene):
    aliased, _ = stair_step_error(_render(edge_scene, 1, False)["combined"])
    fxaa, slope = stair_step_error(_render(edge_scene, 1, True)["combined"])
    assert slope == pytest.approx(math.tan(math.radians(EDGE_ANGLE_DEG)), abs=0.01)
    # Measured: 0.28 px aliased, 0.045 px with FXAA.
    assert fxaa < 0.4 * aliased, (fxaa, aliased)


def test_anti_aliasing_keeps_flat_areas_and_the_aux_passes(edge_scene):
    """Away from edges the image is unchanged; the Shadow/Depth passes come from the
    unjittered first sample, so they are the plain render's exactly."""
    plain = _render(edge_scene, 1, False)
    smooth = _render(edge_scene, 8, True)
    lum_plain = plain["combined"][..., :3].mean(axis=-1)
    lum_smooth = smooth["combined"][..., :3].mean(axis=-1)
    interior = (lum_plain > 0.5) & (np.abs(np.gradient(lum_plain)[0]) < 1e-5) & \
        (np.abs(np.gradient(lum_plain)[1]) < 1e-5)
    interior[:3] = interior[-3:] = False
    assert interior.mean() > 0.25
    assert np.abs(lum_smooth - lum_plain)[interior].max() < 1e-4
    assert np.array_equal(plain["aux"], smooth["aux"])


def test_render_samples_draw_the_shadow_maps_once(edge_scene):
    edge_scene.csm.render_samples = 8
    result = render_result(edge_scene, WIDTH, HEIGHT)
    cascades = result.plan.cascade_count
    tiles = result.passes
    assert tiles.shadow_tiles_drawn <= cascades
    assert tiles.shadow_tiles_drawn + tiles.shadow_tiles_kept == 8 * cascades


def _viewport_frame(scene, fxaa):
    """What view_draw puts on screen, drawn into an offscreen buffer the same way
    (``Pipeline.draw_viewport`` into the bound framebuffer)."""
    from csm_engine.blender import mesh_cache
    depsgraph = bpy.context.evaluated_depsgraph_get()
    camera = snapshot.camera_from_scene(scene, depsgraph, WIDTH, HEIGHT)
    snap = snapshot.take(depsgraph, camera, is_viewport=True)
    cache = mesh_cache.MeshCache()
    cache.sync(snap.mesh_sources)
    color = gpu.types.GPUTexture((WIDTH, HEIGHT), format='RGBA32F')
    target = gpu.types.GPUFrameBuffer(color_slots=(color,))
    renderer = pipeline.Pipeline()
    with target.bind():
        target.clear(color=(0.0, 0.0, 0.0, 0.0))
        renderer.draw_viewport(snap, cache, WIDTH, HEIGHT, fxaa=fxaa)
        buffer = gpu.types.Buffer('FLOAT', WIDTH * HEIGHT * 4)
        target.read_color(0, 0, WIDTH, HEIGHT, 4, 0, 'FLOAT', data=buffer)
    cache.clear()
    return np.frombuffer(buffer, dtype=np.float32).reshape(HEIGHT, WIDTH, 4)[::-1]


def test_viewport_fxaa_smooths_edges(edge_scene):
    render_scene(edge_scene, 32, 32)          # a GPU context exists from here on
    aliased, _ = stair_step_error(_viewport_frame(edge_scene, fxaa=False))
    smooth, slope = stair_step_error(_viewport_frame(edge_scene, fxaa=True))
    assert aliased > 0.2, aliased
    assert slope == pytest.approx(math.tan(math.radians(EDGE_ANGLE_DEG)), abs=0.01)
    assert smooth < 0.4 * aliased, (smooth, aliased)
