"""The viewport redraws only the shadow tiles whose contents would change.

A camera-only redraw keeps every tile whose light matrix and casters are the ones it holds
(stabilized far cascades often stay put); lighting-only settings (PCF radius, debug view,
light colour) redraw none. Tiles that are kept must give the same pixels as a pipeline
that draws every tile afresh with the same shadow plan.
"""
import bpy
import gpu
import numpy as np

from csm_engine.blender import mesh_cache, snapshot
from csm_engine.render import pipeline
from tests.bpy.bpy_helpers import render_scene

W, H = 96, 64


def _scene(empty_scene):
    scene = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=60)
    for x in range(-3, 4):
        bpy.ops.mesh.primitive_cube_add(location=(3.0 * x, 2.0 * x, 1))
    bpy.ops.object.light_add(type='SUN', rotation=(np.radians(40), np.radians(20), 0.3))
    bpy.ops.object.camera_add(location=(0, -14, 6), rotation=(np.radians(70), 0, 0))
    scene.camera = bpy.context.object
    return scene


def _draw(renderer, cache, scene, world_from_view=None, plan=None):
    """(RGBA pixels, camera, shadow plan) of one viewport redraw; ``plan``: draw with this
    shadow plan instead of planning."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    camera = snapshot.camera_from_scene(scene, depsgraph, W, H)
    if world_from_view is not None:
        camera.world_from_view = world_from_view
    snap = snapshot.take(depsgraph, camera, is_viewport=True)
    cache.sync(snap.mesh_sources)
    offscreen = gpu.types.GPUOffScreen(W, H, format='RGBA32F')
    try:
        with offscreen.bind():
            fb = gpu.state.active_framebuffer_get()
            fb.clear(color=(0, 0, 0, 0))
            plan = renderer.draw(snap, cache, None, W, H, plan=plan)
            buffer = gpu.types.Buffer('FLOAT', W * H * 4)
            fb.read_color(0, 0, W, H, 4, 0, 'FLOAT', data=buffer)
    finally:
        offscreen.free()
    return np.frombuffer(buffer, np.float32).reshape(H, W, 4).copy(), camera, plan


def test_camera_only_and_lighting_only_redraws_keep_shadow_tiles(empty_scene):
    scene = _scene(empty_scene)
    render_scene(scene, 32, 32)              # a GPU context exists from here on
    cache = mesh_cache.MeshCache()
    renderer = pipeline.Pipeline()
    _, camera, _ = _draw(renderer, cache, scene)
    assert renderer.last_frame.shadow_tiles_drawn == 3
    _draw(renderer, cache, scene)
    assert (renderer.last_frame.shadow_tiles_drawn, renderer.last_frame.shadow_tiles_kept) \
        == (0, 3)

    # Lighting-only settings and the light's colour redraw no shadow tile.
    scene.csm.pcf_radius = 0
    scene.objects["Sun"].data.color = (1.0, 0.5, 0.2)
    _draw(renderer, cache, scene)
    assert (renderer.last_frame.shadow_tiles_drawn, renderer.last_frame.shadow_tiles_kept) \
        == (0, 3)

    # A small camera move keeps the far cascades (Fit to Visible Depth, the default, holds
    # every cascade's rectangle and depth while the receivers fit in it: a rectangle is
    # rounded up to 1/32 of its power of two, so a move within that slack keeps it; the
    # plain fit redraws the near cascade); any tile kept must match a fresh draw.
    moved = camera.world_from_view.copy()
    moved[:3, 3] += (0.01, 0.005, 0.0)
    kept, _, plan = _draw(renderer, cache, scene, moved)
    assert renderer.last_frame.shadow_tiles_kept >= 2
    # The reference is a new pipeline (its own textures, tile records and planning state)
    # given the plan the kept frame used: the plan of a moved view depends on the views
    # before it (cascades held while the receivers fit), which a new view has not seen.
    # So it compares kept tiles with tiles drawn afresh, for the same cascades.
    fresh_renderer = pipeline.Pipeline()
    fresh, _, _ = _draw(fresh_renderer, mesh_cache.MeshCache(), scene, moved, plan=plan)
    assert fresh_renderer.last_frame.shadow_tiles_kept == 0
    assert np.abs(kept - fresh).max() < 1e-5

    # Moving a caster redraws the tiles that see it (the cube in the middle of the view:
    # those at the sides may lie outside every cascade's receivers).
    scene.objects["Cube.003"].location.z += 1.0
    bpy.context.view_layer.update()
    _draw(renderer, cache, scene, moved)
    assert renderer.last_frame.shadow_tiles_drawn >= 1
