"""The viewport's mesh cache uploads a mesh once and again only when its geometry changes.

``view_update`` hands ``depsgraph.updates`` to ``engine.apply_depsgraph_updates``; here a
depsgraph handler feeds it the same updates Blender produces when a user moves an object
or edits a mesh, and the upload counter shows what was sent to the GPU.
"""
import bpy
import numpy as np

from csm_engine.blender import engine, mesh_cache, snapshot
from tests.bpy.bpy_helpers import render_scene


def _make_scene(empty_scene):
    scene = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=10)
    plane = bpy.context.object
    bpy.ops.mesh.primitive_cube_add(location=(0, 0, 1))
    cube = bpy.context.object
    bpy.ops.object.light_add(type='SUN')
    bpy.ops.object.camera_add(location=(8, -8, 6), rotation=(np.radians(60), 0, np.radians(45)))
    scene.camera = bpy.context.object
    return scene, plane, cube


class ViewportStandIn:
    """What a viewport engine instance does per redraw, minus the window."""

    def __init__(self, scene):
        self.cache = mesh_cache.MeshCache()
        self.scene = scene
        self.handler = lambda scene, depsgraph: engine.apply_depsgraph_updates(
            self.cache, depsgraph.updates)
        bpy.app.handlers.depsgraph_update_post.append(self.handler)
        self.uploads = 0           # meshes uploaded by this viewport's syncs

    def redraw(self):
        depsgraph = bpy.context.evaluated_depsgraph_get()
        camera = snapshot.camera_from_scene(self.scene, depsgraph, 64, 64)
        snap = snapshot.take(depsgraph, camera, is_viewport=True)
        self.cache.sync(snap.mesh_sources)
        self.uploads += self.cache.last_sync["uploaded"]
        return snap

    def close(self):
        bpy.app.handlers.depsgraph_update_post.remove(self.handler)


def test_moving_an_object_uploads_nothing_and_editing_uploads_one(empty_scene):
    scene, plane, cube = _make_scene(empty_scene)
    render_scene(scene, 32, 32)            # a GPU context exists from here on
    view = ViewportStandIn(scene)
    try:
        view.redraw()
        assert set(view.cache.meshes) == {plane.name, cube.name}
        before = view.uploads

        for step in range(5):              # camera-only redraws
            view.redraw()
        assert view.uploads == before

        cube.location.x += 2.0             # a transform change
        bpy.context.view_layer.update()
        snap = view.redraw()
        assert view.uploads == before
        moved = [i for i in snap.instances if i.key == cube.name][0]
        assert moved.world_from_object[0, 3] == 2.0

        top = max(cube.data.vertices, key=lambda v: v.co.z)
        top.co.z += 1.0                     # a geometry change of one mesh: lift a corner
        cube.data.update()
        bpy.context.view_layer.update()
        view.redraw()
        assert view.uploads == before + 1
        assert view.cache.meshes[cube.name].aabb_max[2] > 1.5
    finally:
        view.close()
