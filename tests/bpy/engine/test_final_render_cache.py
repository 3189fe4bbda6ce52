"""Final renders keep their GPU meshes: a re-render uploads only what changed, and never
shows stale geometry.

Each render gets a new depsgraph, so the final-render mesh cache (``engine``'s
``_FINAL_RENDER_MESHES``) decides from the meshes themselves: an unchanged object is not
even read (``mesh_cache.recipe``), a changed one is read, hashed and uploaded when its
contents are new. Every edit a user makes between two F12s must change the pixels as it
should; an unchanged re-render uploads nothing.
"""
import bpy
import numpy as np

from csm_engine.blender import engine
from tests.bpy.bpy_helpers import cube_on_plane, render_result
from tests.bpy.scenes import blender_render

W, H = 96, 64


def _scene(empty_scene):
    scene = empty_scene
    cube, _sun = cube_on_plane(scene)
    subsurf = cube.modifiers.new("subdivide", 'SUBSURF')
    subsurf.levels = subsurf.render_levels = 1
    material = bpy.data.materials.new("cube")
    _set_colour(material, (0.8, 0.2, 0.2))
    cube.data.materials.append(material)
    return scene, cube


def _set_colour(material, rgb):
    material.diffuse_color = (*rgb, 1.0)
    for node in (material.node_tree.nodes if material.node_tree else ()):
        if node.type == 'BSDF_PRINCIPLED':
            node.inputs["Base Color"].default_value = (*rgb, 1.0)


def _render(scene):
    result = render_result(scene, W, H)
    return result.images["combined"].copy(), result.mesh_uploads


def _changed(a, b):
    return float(np.abs(a - b).max())


def test_blender_gets_each_renders_own_pixels(empty_scene, tmp_path):
    """The engine reads back and hands Blender its passes through memory kept between
    renders: Blender's result of each render (through a 32-bit EXR) is that render's own
    image, the one a render that keeps its images reads back, as the camera moves away and
    back, FXAA on."""
    scene, _cube = _scene(empty_scene)
    scene.render.resolution_percentage = 100
    scene.csm.fxaa = True
    start = scene.camera.location.x
    images = []
    for index, shift in enumerate((0.0, 0.7, 0.0)):
        scene.camera.location.x = start + shift
        kept = render_result(scene, W, H).images["combined"][::-1]
        handed = blender_render(scene, "CSM", tmp_path / f"render_{index}.exr")
        assert np.abs(handed - kept).max() < 1e-6, f"render {index}"
        images.append(handed)
    assert np.abs(images[1] - images[0]).max() > 0.1, "the camera's move shows"
    assert np.array_equal(images[2], images[0])


def test_unchanged_rerender_uploads_nothing_and_draws_no_shadow_tile(empty_scene):
    scene, cube = _scene(empty_scene)
    first, _ = _render(scene)
    result = render_result(scene, W, H)
    again, uploads = result.images["combined"].copy(), result.mesh_uploads
    assert uploads == 0
    assert result.passes.shadow_tiles_drawn == 0
    assert result.passes.shadow_tiles_kept > 0
    assert _changed(first, again) == 0.0
    cache = engine._final_mesh_cache()
    assert cache.last_sync["read"] == 0 and cache.last_sync["uploaded"] == 0


def test_moving_a_vertex_changes_the_pixels(empty_scene):
    scene, cube = _scene(empty_scene)
    before, _ = _render(scene)
    top = max(cube.data.vertices, key=lambda v: v.co.z)
    top.co.z += 1.5
    cube.data.update()
    after, uploads = _render(scene)
    assert uploads == 1
    assert _changed(before, after) > 0.1


def test_modifier_edits_change_the_pixels(empty_scene):
    scene, cube = _scene(empty_scene)
    level1, _ = _render(scene)
    cube.modifiers["subdivide"].render_levels = 3
    level3, uploads = _render(scene)
    assert uploads == 1 and _changed(level1, level3) > 0.02
    array = cube.modifiers.new("array", 'ARRAY')
    array.relative_offset_displace = (1.5, 0, 0)
    arrayed, uploads = _render(scene)
    assert uploads == 1 and _changed(level3, arrayed) > 0.1
    array.show_render = False
    hidden, uploads = _render(scene)
    assert uploads == 0                      # the level-3 mesh is still on the GPU
    assert _changed(level3, hidden) == 0.0


def test_material_colour_and_transform_change_the_pixels_without_uploads(empty_scene):
    scene, cube = _scene(empty_scene)
    red, _ = _render(scene)
    _set_colour(cube.data.materials[0], (0.1, 0.2, 0.9))
    blue, uploads = _render(scene)
    assert uploads == 0
    assert _changed(red, blue) > 0.1
    cube.location.x += 1.0
    moved, uploads = _render(scene)
    assert uploads == 0
    assert _changed(blue, moved) > 0.1


def test_animated_shape_key_changes_the_pixels_per_frame(empty_scene):
    scene, cube = _scene(empty_scene)
    cube.shape_key_add(name="Basis")
    tall = cube.shape_key_add(name="tall")
    for point in tall.data:
        if point.co.z > 0:
            point.co.z += 2.0
    tall.value = 0.0
    tall.keyframe_insert("value", frame=1)
    tall.value = 1.0
    tall.keyframe_insert("value", frame=10)
    images = []
    for frame in (1, 10, 1):
        scene.frame_set(frame)
        images.append(_render(scene))
    assert _changed(images[0][0], images[1][0]) > 0.1
    assert _changed(images[0][0], images[2][0]) == 0.0
    assert images[2][1] == 0                 # frame 1's mesh is hashed, not uploaded again


def test_animation_render_draws_each_frame(empty_scene, tmp_path, monkeypatch):
    """bpy.ops.render.render(animation=True), with one object moving by keyframes."""
    scene, cube = _scene(empty_scene)
    cube.location = (0, 0, 1.2)
    cube.keyframe_insert("location", frame=1)
    cube.location = (0, 0, 4.0)
    cube.keyframe_insert("location", frame=3)
    scene.frame_start, scene.frame_end = 1, 3
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.render.filepath = str(tmp_path / "frame_")
    scene.render.image_settings.file_format = 'PNG'
    # Each frame's RenderResult says what it uploaded (the operator returns none).
    results = []
    render = engine.CSMRenderEngine._render

    def recorded(self, depsgraph, request):
        results.append(render(self, depsgraph, request))
        return results[-1]
    monkeypatch.setattr(engine.CSMRenderEngine, "_render", recorded)
    bpy.ops.render.render(animation=True)
    from tests.bpy.bpy_helpers import load_png
    frames = [load_png(tmp_path / f"frame_{n:04d}.png") for n in (1, 2, 3)]
    assert _changed(frames[0], frames[1]) > 0.05 and _changed(frames[1], frames[2]) > 0.05
    assert len(results) == 3
    assert sum(r.mesh_uploads for r in results) <= 2     # plane and cube, once


def _camera_flight(scene, frames, turn=0.1):
    """The scene camera keyed to move 2 cm and turn ``turn`` degrees further each frame."""
    camera = scene.camera
    for frame in range(1, frames + 1):
        camera.keyframe_insert("location", frame=frame)
        camera.keyframe_insert("rotation_euler", frame=frame)
        camera.location.x += 0.02
        camera.rotation_euler.z += np.radians(turn)


def test_a_camera_animation_keeps_shadow_maps_and_each_frame_is_its_own(empty_scene):
    """Each frame of a slow camera move (a new frame number, as -a renders it) draws few
    shadow maps, the others kept from the frame before, and yet a frame's pixels are the
    same whichever frame was rendered before it (a farm's worker renders it as -a does).
    Fit to Visible Depth (the default) fits the boxes to what each frame sees."""
    scene, _cube = _scene(empty_scene)
    _camera_flight(scene, 6)
    drawn, kept, images = [], [], {}
    for frame in range(1, 7):
        scene.frame_set(frame)
        result = render_result(scene, W, H)
        images[frame] = result.images["combined"].copy()
        drawn.append(result.passes.shadow_tiles_drawn)
        kept.append(result.passes.shadow_tiles_kept)
    assert sum(kept[1:]) > sum(drawn[1:]), (drawn, kept)
    assert _changed(images[1], images[6]) > 0.0, "the camera's move shows"
    # Frame 9: the camera a metre further and turned 10 degrees more.
    scene.camera.location.x += 1.0
    scene.camera.rotation_euler.z += np.radians(10.0)
    scene.camera.keyframe_insert("location", frame=9)
    scene.camera.keyframe_insert("rotation_euler", frame=9)
    for before, frame in ((9, 3), (9, 1), (5, 2)):
        scene.frame_set(before)
        render_result(scene, W, H)
        scene.frame_set(frame)
        assert np.array_equal(render_result(scene, W, H).images["combined"], images[frame])


def test_objects_sharing_a_mesh_upload_it_once(empty_scene):
    scene, cube = _scene(empty_scene)
    for index in range(5):
        twin = cube.copy()                   # same mesh, same modifiers
        twin.location.x = -4.0 + 2.0 * index
        twin.location.y = 3.0
        scene.collection.objects.link(twin)
    engine._final_mesh_cache().clear()
    _, uploads = _render(scene)
    assert uploads == 2                      # the plane and one subdivided cube
    assert engine._final_mesh_cache().last_sync["read"] == 2


def _copies(scene, cube, count):
    """``count`` Shift+D-style copies of the cube: each its own copy of the mesh."""
    copies = []
    for index in range(count):
        twin = cube.copy()
        twin.data = cube.data.copy()
        twin.location = (-3.0 + 3.0 * index, 3.5, 1.2)
        scene.collection.objects.link(twin)
        copies.append(twin)
    return copies


def test_copies_of_one_mesh_are_read_once_and_an_edited_copy_on_its_own(empty_scene):
    """Copies with the same contents and modifiers evaluate to one mesh, so a first render
    reads (and Blender subdivides) it once; a copy that differs in anything that shapes it
    (subdivision level, an edge crease, flat shading, a moved vertex) is read by itself,
    in that render and in the next, and its pixels change."""
    scene, cube = _scene(empty_scene)
    copies = _copies(scene, cube, 3)
    engine._final_mesh_cache().clear()
    base, uploads = _render(scene)
    cache = engine._final_mesh_cache()
    assert cache.last_sync["read"] == 2 and uploads == 2        # plane + one cube
    assert cache.last_sync["unread"] == 3

    edits = [lambda: setattr(copies[0].modifiers["subdivide"], "render_levels", 3),
             lambda: copies[1].data.polygons.foreach_set(
                 "use_smooth", [not copies[1].data.polygons[0].use_smooth] *
                 len(copies[1].data.polygons))]
    if bpy.app.version >= (4, 0, 0):          # creases became an edge attribute in 4.0
        def crease():
            mesh = copies[2].data
            layer = mesh.attributes.get("crease_edge") or \
                mesh.attributes.new("crease_edge", 'FLOAT', 'EDGE')
            layer.data.foreach_set("value", [1.0] * len(mesh.edges))
            mesh.update()
        edits.append(crease)
    previous = base
    for edit in edits:
        edit()
        after, uploads = _render(scene)
        assert uploads == 1, edit
        assert _changed(previous, after) > 0.02
        again, uploads = _render(scene)
        assert uploads == 0 and _changed(after, again) == 0.0
        assert cache.last_sync["read"] == 0
        previous = after
    # Moving a vertex of the original (the copies keep theirs) re-reads only the original.
    top = max(cube.data.vertices, key=lambda v: v.co.z)
    top.co.z += 1.5
    cube.data.update()
    moved, uploads = _render(scene)
    assert uploads == 1 and _changed(previous, moved) > 0.1


def test_a_moving_object_is_not_read_again_but_an_animated_modifier_is(empty_scene):
    """Keys on the transform move the object without changing its mesh, so its Subdivision
    is not redone per frame; a keyed modifier setting changes the mesh, so it is read."""
    scene, cube = _scene(empty_scene)
    cube.location.z = 1.2
    cube.keyframe_insert("location", frame=1)
    cube.location.z = 3.0
    cube.keyframe_insert("location", frame=5)
    scene.frame_set(1)
    low, _ = _render(scene)
    scene.frame_set(5)
    high, uploads = _render(scene)
    cache = engine._final_mesh_cache()
    assert uploads == 0 and cache.last_sync["read"] == 0
    assert _changed(low, high) > 0.1
    subsurf = cube.modifiers["subdivide"]
    subsurf.render_levels = 0
    subsurf.keyframe_insert("render_levels", frame=1)
    subsurf.render_levels = 3
    subsurf.keyframe_insert("render_levels", frame=5)
    scene.frame_set(1)
    coarse, _ = _render(scene)
    scene.frame_set(5)
    fine, uploads = _render(scene)
    assert cache.last_sync["read"] >= 1 and uploads == 1
    assert _changed(high, fine) > 0.02
