"""Final renders keep the G-buffer (and the AO and visible depths made from it) when the
next render would draw the same: F12 again after changing a shadow or light setting
redraws only the shadows and the lighting. Never at the price of a stale image:

- whatever a user can change that reaches the G-buffer (camera, transform, geometry,
  material, visibility, resolution, samples) draws it again, and the pixels are those of
  a render that drew everything;
- what changes only shadows, lights or AO keeps it, and the pixels are still exactly those
  of a render that drew everything.
"""
import bpy
import numpy as np
import pytest

from csm_engine.blender import engine
from csm_engine.blender.compat import enable_shading_nodes
from csm_engine.render import pipeline
from tests.bpy.bpy_helpers import (
    cube_on_plane, pipeline_drawing, render_result, viewport_frame)

W, H = 96, 64


def _scene(empty_scene):
    scene = empty_scene
    cube, sun = cube_on_plane(scene)
    material = bpy.data.materials.new("cube")
    if material.node_tree is None:       # before 5.0 a new material has no nodes
        enable_shading_nodes(material)
    _set_colour(material, (0.8, 0.2, 0.2, 1.0))
    cube.data.materials.append(material)
    # A wall whose back faces the camera: gone when back faces are culled.
    bpy.ops.mesh.primitive_plane_add(size=3, location=(-2.5, 2.5, 1.5),
                                     rotation=(np.radians(90), 0, np.radians(225)))
    wall = bpy.context.object
    wall.data.materials.append(bpy.data.materials.new("wall"))
    scene.csm.ao_distance = 1.0          # AO visible where the cube meets the ground
    scene.world = bpy.data.worlds.new("sky")
    scene.world.color = (0.4, 0.4, 0.4)  # ambient light, which AO darkens
    return scene, cube, sun


def _set_colour(material, rgba):
    material.diffuse_color = rgba
    for node in (material.node_tree.nodes if material.node_tree else ()):
        if node.type == 'BSDF_PRINCIPLED':
            node.inputs["Base Color"].default_value = (*rgba[:3], 1.0)
            node.inputs["Alpha"].default_value = rgba[3]


def _render(scene):
    """(combined image, whether the G-buffer was kept)."""
    result = render_result(scene, W, H)
    return result.images["combined"].copy(), result.passes.gbuffers_kept > 0


def _render_everything(scene):
    """The same render with nothing kept from the render before: every shadow tile (once:
    jittered samples share them), every G-buffer and its AO drawn afresh."""
    engine.forget_final_render_passes()
    result = render_result(scene, W, H)
    passes = result.passes
    assert passes.shadow_tiles_drawn == len(result.plan.tiles) > 0
    assert passes.gbuffers_kept == passes.ao_kept == 0 and passes.gbuffers_drawn > 0
    return result.images["combined"].copy()


def test_unchanged_rerender_keeps_the_gbuffer_and_gives_the_same_pixels(empty_scene):
    scene, _cube, _sun = _scene(empty_scene)
    first, _ = _render(scene)
    again, kept = _render(scene)
    assert kept
    assert np.array_equal(first, again)


@pytest.mark.parametrize("edit", ["pcf radius", "shadow filter", "sun colour", "sun angle",
                                  "sun direction", "ao distance", "ao off", "debug view",
                                  "fit to visible off"])
def test_shadow_light_and_ao_settings_keep_the_gbuffer_and_show(empty_scene, edit):
    scene, _cube, sun = _scene(empty_scene)
    before, _ = _render(scene)
    _render(scene)
    change = {
        "pcf radius": lambda: setattr(scene.csm, "pcf_radius", 3),
        "shadow filter": lambda: setattr(scene.csm, "shadow_filter", 'HARD'),
        "sun colour": lambda: setattr(sun.data, "color", (0.2, 0.4, 1.0)),
        "sun angle": lambda: (setattr(scene.csm, "shadow_filter", 'SOFT'),
                              setattr(sun.data, "angle", np.radians(10))),
        "sun direction": lambda: setattr(sun, "rotation_euler",
                                         (np.radians(50), np.radians(-30), 0)),
        "ao distance": lambda: setattr(scene.csm, "ao_distance", 3.0),
        "ao off": lambda: setattr(scene.csm, "ambient_occlusion", False),
        "debug view": lambda: setattr(scene.csm, "debug_view", 'CASCADES'),
        "fit to visible off": lambda: setattr(scene.csm, "fit_to_visible", False),
    }[edit]
    change()
    after, kept = _render(scene)
    assert kept, edit
    assert np.abs(after - before).max() > 0.02, edit          # the edit shows
    assert np.array_equal(after, _render_everything(scene)), edit


@pytest.mark.parametrize("edit", ["camera", "transform", "hide", "vertex", "colour",
                                  "alpha blend", "backface culling", "resolution",
                                  "samples", "new object"])
def test_edits_that_reach_the_gbuffer_draw_it_again(empty_scene, edit):
    scene, cube, _sun = _scene(empty_scene)
    before, _ = _render(scene)
    _render(scene)
    material = cube.data.materials[0]

    def vertex():
        top = max(cube.data.vertices, key=lambda v: v.co.z)
        top.co.z += 1.5
        cube.data.update()

    def new_object():
        bpy.ops.mesh.primitive_uv_sphere_add(location=(-2.0, 2.0, 1.0))

    change = {
        "camera": lambda: setattr(scene.camera, "location", (8, -6, 5)),
        "transform": lambda: setattr(cube, "location", (1.0, 0.5, 1.2)),
        "hide": lambda: setattr(cube, "hide_render", True),
        "vertex": vertex,
        "colour": lambda: _set_colour(material, (0.1, 0.3, 0.9, 1.0)),
        "alpha blend": lambda: (_set_colour(material, (0.8, 0.2, 0.2, 0.2)),
                                setattr(material, "blend_method", 'CLIP')
                                if hasattr(material, "blend_method") else None,
                                setattr(material, "surface_render_method", 'DITHERED')
                                if hasattr(material, "surface_render_method") else None),
        "backface culling": lambda: setattr(bpy.data.materials["wall"],
                                            "use_backface_culling", True),
        "resolution": lambda: None,
        "samples": lambda: setattr(scene.csm, "render_samples", 4),
        "new object": new_object,
    }[edit]
    change()
    if edit == "resolution":
        result = render_result(scene, W + 8, H)
        assert result.passes.gbuffers_kept == 0
        assert result.images["combined"].shape[1] == W + 8
        return
    after, kept = _render(scene)
    # More samples: the first (unjittered) sample's G-buffer is the one held; the others
    # are drawn.
    assert kept == (edit == "samples"), edit
    if edit != "samples":
        assert np.abs(after - before).max() > 0.02, edit
    assert np.array_equal(after, _render_everything(scene)), edit


def test_a_shadow_terminator_offset_edit_draws_the_gbuffer_again(empty_scene):
    """The G-buffer's facet target carries each object's Shadow Terminator Geometry
    Offset, so changing it on a smooth low-poly sphere (stepped terminator at 0, lit band
    above) draws the G-buffer again and shows, as a render that drew everything does."""
    scene, _cube, _sun = _scene(empty_scene)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=8, ring_count=4, radius=1.2,
                                         location=(-2.5, -2.5, 1.3))
    bpy.ops.object.shade_smooth()
    sphere = bpy.context.object
    owner = sphere if hasattr(sphere, "shadow_terminator_geometry_offset") else sphere.cycles
    owner.shadow_terminator_geometry_offset = 0.1
    before, _ = _render(scene)
    _render(scene)
    owner.shadow_terminator_geometry_offset = 0.0
    after, kept = _render(scene)
    assert not kept
    assert np.abs(after - before).max() > 0.02
    assert np.array_equal(after, _render_everything(scene))


def test_ao_is_not_kept_across_a_redrawn_gbuffer(empty_scene):
    """AO off while the G-buffer changes, then on again with the G-buffer kept: the AO is
    made from the G-buffer now, not the one it was last made from."""
    scene, cube, _sun = _scene(empty_scene)
    _render(scene)
    scene.csm.ambient_occlusion = False
    cube.location.x += 2.0
    _render(scene)
    scene.csm.ambient_occlusion = True
    after, kept = _render(scene)
    assert kept
    assert np.array_equal(after, _render_everything(scene))


def test_textured_materials_never_keep_the_gbuffer(empty_scene):
    """An image can be painted or reloaded in place (same name, same texture), so a frame
    that draws one redraws the G-buffer; editing its pixels shows."""
    scene, cube, _sun = _scene(empty_scene)
    image = bpy.data.images.new("paint", 4, 4)
    image.pixels.foreach_set(np.tile([1.0, 1.0, 0.0, 1.0], 16).astype(np.float32))
    material = cube.data.materials[0]
    nodes = material.node_tree.nodes
    texture = nodes.new("ShaderNodeTexImage")
    texture.image = image
    bsdf = next(n for n in nodes if n.type == 'BSDF_PRINCIPLED')
    material.node_tree.links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])
    yellow, _ = _render(scene)
    image.pixels.foreach_set(np.tile([0.0, 0.2, 1.0, 1.0], 16).astype(np.float32))
    image.update()
    blue, kept = _render(scene)
    assert not kept
    assert np.abs(blue - yellow).max() > 0.1


def _viewport_frame(scene, renderer, cache):
    return viewport_frame(scene, renderer, cache, W, H)


def test_viewport_keeps_the_gbuffer_while_shadows_are_tuned(empty_scene):
    """In the viewport too: the second redraw of an unmoved view records the G-buffer, a
    PCF or sun change then keeps it and shows; a moved object draws it again. Every frame
    equals a fresh pipeline's with the same shadow plan."""
    from csm_engine.blender import mesh_cache
    scene, cube, sun = _scene(empty_scene)
    _render(scene)                        # a GPU context exists from here on
    cache = mesh_cache.MeshCache()
    handler = lambda _scene, depsgraph: engine.apply_depsgraph_updates(  # noqa: E731
        cache, depsgraph.updates)
    bpy.app.handlers.depsgraph_update_post.append(handler)
    renderer = pipeline.Pipeline()
    try:
        def fresh():
            return _viewport_frame(scene, pipeline_drawing(renderer.last_plan),
                                   mesh_cache.MeshCache())

        _viewport_frame(scene, renderer, cache)
        before = _viewport_frame(scene, renderer, cache)
        for edit, keeps in ((lambda: setattr(scene.csm, "pcf_radius", 3), True),
                            (lambda: setattr(sun, "rotation_euler",
                                             (np.radians(50), np.radians(-30), 0)), True),
                            (lambda: setattr(cube, "location", (1.5, 0.5, 1.2)), False)):
            edit()
            bpy.context.view_layer.update()
            after = _viewport_frame(scene, renderer, cache)
            assert (renderer.last_frame.gbuffers_kept > 0) == keeps
            assert np.abs(after - before).max() > 0.02
            assert np.array_equal(after, fresh())
            before = after
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
