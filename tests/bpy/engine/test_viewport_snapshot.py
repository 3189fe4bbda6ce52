"""The viewport reads the scene again only after a depsgraph update (``view_update``);
a redraw that only moves the view draws the last snapshot with the new view. Every kind of
edit a user makes between redraws reaches Blender's depsgraph, so it is read again and
shows; a moved view reads nothing."""
import bpy
import numpy as np
import pytest

from csm_engine.blender import engine, mesh_cache, snapshot
from tests.bpy.bpy_helpers import cube_on_plane, render_scene

W, H = 64, 48


def _scene(empty_scene):
    cube, sun = cube_on_plane(empty_scene)
    return empty_scene, cube, sun


@pytest.fixture
def viewport(empty_scene):
    """(scene, cube, sun, snapshots, cache, frame()) with view_update's bookkeeping."""
    scene, cube, sun = _scene(empty_scene)
    render_scene(scene, 16, 16)              # a GPU context exists from here on
    cache = mesh_cache.MeshCache()
    snapshots = engine.ViewportSnapshots()

    def handler(_scene, depsgraph):          # what view_update does
        snapshots.scene_updated(cache, depsgraph.updates)
    bpy.app.handlers.depsgraph_update_post.append(handler)

    def frame():
        depsgraph = bpy.context.evaluated_depsgraph_get()
        camera = snapshot.camera_from_scene(scene, depsgraph, W, H)
        return snapshots.frame(depsgraph, camera, cache)
    try:
        yield scene, cube, sun, snapshots, cache, frame
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)


def test_a_moved_view_reuses_the_snapshot(viewport):
    scene, _cube, _sun, snapshots, _cache, frame = viewport
    first = frame()
    scene.camera.location.x += 1.0          # the scene camera is an object: an update
    moved = frame()
    assert moved.instances is not first.instances
    again = frame()                         # nothing changed: the same scene data
    assert again.instances is moved.instances and again.settings is moved.settings
    assert not np.allclose(first.camera.world_from_view, moved.camera.world_from_view)


@pytest.mark.parametrize("edit", ["transform", "light energy", "csm setting", "world",
                                  "hide", "frame", "material"])
def test_every_edit_is_read_again(viewport, edit):
    scene, cube, sun, _snapshots, _cache, frame = viewport
    before = frame()
    frame()
    cube.keyframe_insert("location", frame=1)
    if edit == "frame":
        cube.location.z = 3.0
        cube.keyframe_insert("location", frame=5)
        scene.frame_set(1)
        before = frame()
    change = {
        "transform": lambda: setattr(cube, "location", (1.0, 0.0, 1.0)),
        "light energy": lambda: setattr(sun.data, "energy", 7.0),
        "csm setting": lambda: setattr(scene.csm, "pcf_radius", 3),
        "world": lambda: setattr(scene, "world", bpy.data.worlds.new("w")),
        "hide": lambda: cube.hide_set(True),
        "frame": lambda: scene.frame_set(5),
        "material": lambda: cube.data.materials.append(bpy.data.materials.new("m")),
    }[edit]
    change()
    after = frame()
    assert after.instances is not before.instances, edit
    if edit == "light energy":
        assert not np.allclose(after.sun.color, before.sun.color)
    if edit == "csm setting":
        assert after.settings.pcf_radius == 3
    if edit == "hide":
        assert len(after.instances) == len(before.instances) - 1
