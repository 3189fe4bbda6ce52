"""A viewport redraw keeps what did not change from the last redraw (per-instance arrays,
draw lists, caster signatures, the settings' definitions, the camera's inverses), and an
edit shows in the very next redraw.

One long-lived pipeline and mesh cache (fed the depsgraph's updates, as ``view_update``
does) redraw after each edit; every frame must equal a fresh pipeline's and fresh cache's
frame of the same scene with the same shadow plan, and the edit must have changed the
picture.
"""
import bpy
import numpy as np

from csm_engine.blender import engine, mesh_cache
from csm_engine.blender.compat import enable_shading_nodes
from csm_engine.render import pipeline
from tests.bpy.bpy_helpers import pipeline_drawing, render_scene, viewport_frame

W, H = 96, 64


def _scene(empty_scene):
    scene = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=30)
    ground = bpy.context.object
    cubes = []
    for x in range(-2, 3):
        bpy.ops.mesh.primitive_cube_add(location=(2.5 * x, 1.5 * x, 1))
        cubes.append(bpy.context.object)
    cube = cubes[-1]
    # The ground reads its colour from an image, so an edit of the image's pixels shows.
    image = bpy.data.images.new("checker", 4, 4)
    image.pixels.foreach_set(np.full(4 * 4 * 4, 0.8, dtype=np.float32))
    material = bpy.data.materials.new("ground")
    enable_shading_nodes(material)
    nodes = material.node_tree.nodes
    texture = nodes.new("ShaderNodeTexImage")
    texture.image = image
    material.node_tree.links.new(texture.outputs["Color"],
                                 nodes["Principled BSDF"].inputs["Base Color"])
    ground.data.materials.append(material)
    cube_material = bpy.data.materials.new("cube")
    cube.data.materials.append(cube_material)
    # Two objects share one material: the G-buffer binds it once for both.
    cubes[0].data.materials.append(cube_material)
    bpy.ops.object.light_add(type='SUN', rotation=(np.radians(40), np.radians(20), 0.3))
    bpy.ops.object.camera_add(location=(0, -14, 7), rotation=(np.radians(65), 0, 0))
    scene.camera = bpy.context.object
    scene.world = bpy.data.worlds.new("sky")     # ambient light, so its strength shows
    scene.world.color = (0.3, 0.3, 0.3)
    return scene, cubes, cube_material, image


class _Viewport:
    """What a viewport engine instance keeps from one redraw to the next."""

    def __init__(self):
        self.cache = mesh_cache.MeshCache()
        self.pipeline = pipeline.Pipeline()
        self.handler = lambda _scene, depsgraph: engine.apply_depsgraph_updates(
            self.cache, depsgraph.updates)
        bpy.app.handlers.depsgraph_update_post.append(self.handler)

    def close(self):
        bpy.app.handlers.depsgraph_update_post.remove(self.handler)


def _frame(scene, renderer, cache):
    return viewport_frame(scene, renderer, cache, W, H)


def test_every_edit_shows_in_the_next_redraw(empty_scene):
    scene, cubes, cube_material, image = _scene(empty_scene)
    cube = cubes[-1]
    render_scene(scene, 32, 32)              # a GPU context exists from here on
    view = _Viewport()
    try:
        before = _frame(scene, view.pipeline, view.cache)
        _frame(scene, view.pipeline, view.cache)     # a redraw from what was kept

        def edit(name, change):
            nonlocal before
            change()
            bpy.context.view_layer.update()
            kept = _frame(scene, view.pipeline, view.cache)
            fresh = _frame(scene, pipeline_drawing(view.pipeline.last_plan),
                           mesh_cache.MeshCache())
            assert np.abs(kept - fresh).max() < 1e-5, f"{name}: the kept frame is stale"
            assert np.abs(kept - before).max() > 1e-3, f"{name}: the edit does not show"
            before = kept

        edit("move", lambda: setattr(cube, "location", (cube.location.x + 1.0,
                                                         cube.location.y, 1.5)))

        def lift():
            for vertex in cube.data.vertices:
                vertex.co.z += 0.5
            cube.data.update()
        edit("mesh edit", lift)

        def recolour():
            cube_material.diffuse_color = (1.0, 0.1, 0.1, 1.0)
            if cube_material.node_tree is not None:     # new materials use nodes in 5.0
                bsdf = cube_material.node_tree.nodes["Principled BSDF"]
                bsdf.inputs["Base Color"].default_value = (1.0, 0.1, 0.1, 1.0)
        edit("material colour", recolour)

        def paint():
            image.pixels.foreach_set(np.tile([0.1, 0.2, 0.9, 1.0], 16).astype(np.float32))
            image.update()
            image.update_tag()      # as painting does: the depsgraph reports the image
        edit("image pixels", paint)
        edit("setting", lambda: setattr(scene.csm, "ambient_strength", 3.0))
        edit("no shadow", lambda: setattr(cube, "visible_shadow", False))
        edit("hidden from the camera", lambda: setattr(cubes[0], "visible_camera", False))
        edit("delete", lambda: bpy.data.objects.remove(cube))
        # The view's inverse is formed in closed form (core/matrices.py) each frame.
        edit("camera turned", lambda: setattr(scene.camera, "rotation_euler",
                                              (np.radians(62), 0.0, np.radians(6))))
    finally:
        view.close()
