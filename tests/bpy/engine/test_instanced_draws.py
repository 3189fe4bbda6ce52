"""Copies of one mesh: a scene file's many references to one mesh file import as one
copies object (Geometry Nodes instances), and the passes draw every copy of a mesh in one
instanced draw; the pixels are those of one draw per object."""
import json
import os

import bpy
import numpy as np
import pytest

from csm_engine.blender import engine, scene_builder
from csm_engine.core import conventions
from csm_engine.render import draw_lists, instancing


def _write_wedge_obj(path):
    """An asymmetric closed wedge (a mirrored copy looks different), base on y = 0."""
    vertices = [(0, 0, 0), (1.2, 0, 0), (0, 0, 0.6), (1.2, 0, 0.6), (0, 1.5, 0), (0, 1.5, 0.6)]
    faces = [(1, 2, 4, 3), (1, 3, 6, 5), (2, 5, 6, 4), (1, 5, 2), (3, 4, 6)]
    with open(path, "w") as stream:
        stream.writelines(f"v {x} {y} {z}\n" for x, y, z in vertices)
        stream.writelines("f " + " ".join(map(str, face)) + "\n" for face in faces)


def _write_scene(folder, count=48):
    _write_wedge_obj(os.path.join(folder, "wedge.obj"))
    with open(os.path.join(folder, "ground.obj"), "w") as stream:
        stream.write("v -12 0 -12\nv 12 0 -12\nv 12 0 12\nv -12 0 12\nf 1 4 3 2\n")
    rng = np.random.default_rng(7)
    objects = [{"mesh": "ground.obj"}]
    for i in range(count):
        objects.append({
            "mesh": "wedge.obj",
            "translate": {"x": -9.0 + 3.0 * (i % 7), "y": 0.0, "z": -9.0 + 3.0 * (i // 7)},
            "rotate": {"x": 0.0, "y": float(rng.uniform(0, 360)), "z": 0.0},
            # every third one mirrored, scales uneven
            "scale": {"x": -1.0 if i % 3 == 1 else 1.0, "y": float(rng.uniform(0.6, 1.6)),
                      "z": float(rng.uniform(0.8, 1.3))}})
    path = os.path.join(folder, "copies.json")
    with open(path, "w") as stream:
        json.dump({"camera": {"translate": {"x": 0, "y": 14, "z": 18},
                              "rotate": {"x": 38, "y": 0, "z": 0},
                              "near": 0.1, "far": 80, "FOVy": 50},
                   "objects": objects, "lights": [],
                   "directional_light": {"direction": {"x": 0.5, "y": -0.7, "z": -0.3},
                                         "color": {"x": 1, "y": 1, "z": 1}}}, stream)
    return path, objects


@pytest.fixture
def copies_scene(empty_scene, tmp_path):
    path, objects = _write_scene(str(tmp_path))
    collection = scene_builder.import_scene_file(path, empty_scene)
    scene = empty_scene
    scene.render.resolution_x, scene.render.resolution_y = 200, 150
    scene.csm.fxaa = False
    return scene, collection, objects


def test_references_to_one_file_are_copies_of_one_mesh_at_the_file_transforms(copies_scene):
    scene, collection, objects = copies_scene
    copies = collection.objects["wedge (48 copies)"]
    assert len(copies.data.vertices) == 48
    assert len([m for m in bpy.data.meshes if m.users and m.polygons]) == 2    # wedge, ground
    # What a renderer is handed: one instance of the wedge per reference, at the file's
    # transform (conventions.object_matrix_zup) times the importer's own object transform
    # (as a scene object's empty parent gives it), mirrored ones with a negative determinant.
    source = np.array(bpy.data.objects["wedge"].matrix_world)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    found = [np.array(i.matrix_world) for i in depsgraph.object_instances
             if i.is_instance and i.object.original.name == "wedge"]
    wanted = [conventions.object_matrix_zup(*(tuple(o[k].values())
                                              for k in ("translate", "rotate", "scale")))
              @ source for o in objects[1:]]
    assert len(found) == len(wanted)
    found = sorted(found, key=lambda m: tuple(np.round(m[:3, 3], 3)))
    wanted = sorted(wanted, key=lambda m: tuple(np.round(m[:3, 3], 3)))
    assert max(np.abs(a - b).max() for a, b in zip(found, wanted)) < 1e-5
    assert sum(np.linalg.det(m[:3, :3]) < 0 for m in found) == 16


def _render_counting_matrix_uploads(scene, monkeypatch):
    """A final render drawing every pass, and the number of copies of each instanced
    matrix upload it made."""
    uploads = []
    real = instancing.matrix_texture
    monkeypatch.setattr(instancing, "matrix_texture",
                        lambda matrices: uploads.append(len(matrices)) or real(matrices))
    engine.forget_final_render_passes()
    instanced = engine.render_final(scene, keep_images=True)
    assert instanced.error is None, instanced.error
    return instanced, uploads


def test_instanced_draws_give_the_pixels_of_one_draw_per_object(copies_scene, monkeypatch):
    scene, collection, _objects = copies_scene
    instanced, uploads = _render_counting_matrix_uploads(scene, monkeypatch)
    # The G-buffer and each shadow tile drew the copies instanced (48 copies, fewer in a
    # tile that sees only some of them).
    assert len(uploads) >= 2 and max(uploads) == 48, uploads

    monkeypatch.setattr(draw_lists.HeldDrawLists, "instancing", False)
    uploads.clear()
    engine.forget_final_render_passes()
    separate = engine.render_final(scene, keep_images=True)
    assert separate.error is None, separate.error
    assert uploads == []
    for name in ("combined", "normal", "aux"):
        assert np.array_equal(instanced.images[name], separate.images[name]), name

    # And the copies are in the picture: hiding them changes a good share of it (the
    # wedges and their shadows on the ground).
    collection.objects.unlink(collection.objects["wedge (48 copies)"])
    engine.forget_final_render_passes()
    without = engine.render_final(scene, keep_images=True)
    changed = np.abs(without.images["combined"][..., :3] -
                     instanced.images["combined"][..., :3]).max(axis=-1) > 0.02
    assert changed.mean() > 0.05, changed.mean()


def test_runs_keep_draw_order_around_a_mesh_drawn_once():
    # Rows in draw order; group 0 repeats around the lone group 1, group 2 repeats too.
    rows = np.array([5, 3, 9, 1, 4, 7, 8])
    groups = np.zeros(10, dtype=np.int64)
    groups[[9]] = 1
    groups[[4, 8]] = 2
    runs = instancing.runs(rows, groups)
    assert [r.tolist() for r in runs] == [[5, 3], [9], [1, 7], [4, 8]]


def test_packed_matrices_read_back_as_the_shader_reads_them():
    matrices = np.arange(2500 * 16, dtype=np.float32).reshape(2500, 16)
    texels = instancing.pack(matrices)
    per_row = instancing.MATRICES_PER_ROW
    assert texels.shape == (3, 4 * per_row, 4)
    for index in (0, 1, per_row - 1, per_row, 2499):
        row, first = index // per_row, (index % per_row) * 4
        assert np.array_equal(texels[row, first:first + 4].ravel(), matrices[index])


def test_the_gbuffer_draws_only_boxes_that_reach_the_view():
    from csm_engine.render.gbuffer import in_view
    # A GL perspective camera at the origin looking down -z, 90 degrees, clip 0.1 .. 100.
    near, far = 0.1, 100.0
    clip_from_world = np.array([[1, 0, 0, 0], [0, 1, 0, 0],
                                [0, 0, -(far + near) / (far - near),
                                 -2 * far * near / (far - near)],
                                [0, 0, -1, 0]], dtype=np.float64)
    centres = np.array([[0, 0, -5],        # ahead
                        [0, 0, 5],         # behind
                        [20, 0, -5],       # far to the right of a 90-degree view
                        [5.4, 0, -5],      # its box (half size 0.5) reaches x = z
                        [0, 0, -150],      # beyond clip end
                        [0, 0, 0.3]])      # around the eye, reaching past clip start
    lo, hi = centres - 0.5, centres + 0.5
    seen = in_view(clip_from_world, (lo, hi), np.arange(len(centres)), len(centres))
    assert seen.tolist() == [True, False, False, True, False, True]


def test_blenders_own_collection_instances_draw_instanced_with_the_same_pixels(
        empty_scene, monkeypatch):
    from tests.bpy.scenes import add_camera, add_ground, add_sun
    scene = empty_scene
    scene.render.resolution_x, scene.render.resolution_y = 160, 120
    scene.csm.fxaa = False
    add_ground(30.0)
    add_sun((0.4, 0.3, -0.87))
    add_camera(scene, (0.0, -18.0, 12.0), (0.0, 0.0, 0.0))
    tree = bpy.data.collections.new("tree")
    bpy.ops.mesh.primitive_cone_add(radius1=0.8, depth=2.0, location=(0, 0, 1.5))
    bpy.ops.mesh.primitive_cylinder_add(radius=0.2, depth=1.0, location=(0, 0, 0.5))
    for obj in list(scene.collection.objects):
        if obj.type == 'MESH' and obj.name != "Plane":
            scene.collection.objects.unlink(obj)
            tree.objects.link(obj)
    for index in range(12):
        empty = bpy.data.objects.new(f"tree{index}", None)
        empty.instance_type = 'COLLECTION'
        empty.instance_collection = tree
        empty.location = (-7.5 + 3.0 * (index % 6), -3.0 + 6.0 * (index // 6), 0.0)
        empty.scale = (-1.0 if index % 4 == 1 else 1.0, 1.0, 0.8 + 0.1 * (index % 3))
        scene.collection.objects.link(empty)
    bpy.context.view_layer.update()
    instanced, uploads = _render_counting_matrix_uploads(scene, monkeypatch)
    assert uploads and max(uploads) == 24, uploads      # 12 cones and 12 trunks
    monkeypatch.setattr(draw_lists.HeldDrawLists, "instancing", False)
    engine.forget_final_render_passes()
    separate = engine.render_final(scene, keep_images=True)
    for name in ("combined", "normal", "aux"):
        assert np.array_equal(instanced.images[name], separate.images[name]), name


def test_moving_one_copy_in_the_viewport_moves_it_and_uploads_no_mesh(copies_scene):
    from csm_engine.blender import mesh_cache
    from csm_engine.render.pipeline import Pipeline
    from tests.bpy.bpy_helpers import viewport_frame
    scene, collection, _objects = copies_scene
    engine.render_final(scene)                  # a GPU context exists from here on
    cache = mesh_cache.MeshCache()
    handler = lambda _scene, depsgraph: engine.apply_depsgraph_updates(      # noqa: E731
        cache, depsgraph.updates)
    bpy.app.handlers.depsgraph_update_post.append(handler)
    try:
        renderer = Pipeline()
        before = viewport_frame(scene, renderer, cache, 120, 90)
        assert set(cache.meshes) == {"wedge", "ground"}
        # Edit Mode's move of one vertex of the copies object: that copy moves.
        copies = collection.objects["wedge (48 copies)"]
        copies.data.vertices[24].co.y += 4.0
        copies.data.update()
        bpy.context.view_layer.update()
        after = viewport_frame(scene, renderer, cache, 120, 90)
        assert cache.last_sync["uploaded"] == 0
        changed = np.abs(after[..., :3] - before[..., :3]).max(axis=-1) > 0.02
        assert 0.002 < changed.mean() < 0.2, changed.mean()
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)


def test_mirrored_copies_with_backface_culling_show_their_outside(copies_scene):
    """A closed mesh seen from outside looks the same with Backface Culling on or off,
    unless the culling takes the wrong faces: a mirrored copy's winding is turned around,
    so culling its 'back' faces by the winding alone would show its inside."""
    scene, _collection, _objects = copies_scene
    material = bpy.data.materials.new("culled")
    bpy.data.meshes["wedge"].materials.append(material)

    def render(culling):
        material.use_backface_culling = culling
        if hasattr(material, "use_backface_culling_shadow"):
            material.use_backface_culling_shadow = culling
        engine.forget_final_render_passes()
        result = engine.render_final(scene, keep_images=True)
        assert result.error is None, result.error
        return result.images["combined"][..., :3]

    culled, both_sides = render(True), render(False)
    differ = np.abs(culled - both_sides).max(axis=-1) > 0.02
    # Only silhouette pixels may differ (a front and a back face meet there at one depth).
    assert differ.mean() < 0.005, differ.mean()


def _instances_bvh():
    """One BVH of every mesh triangle the depsgraph draws, instances included."""
    from mathutils.bvhtree import BVHTree
    depsgraph = bpy.context.evaluated_depsgraph_get()
    verts, polys = [], []
    for instance in depsgraph.object_instances:
        obj = instance.object
        if obj.type != 'MESH':
            continue
        mesh = obj.data
        mesh.calc_loop_triangles()
        matrix = instance.matrix_world.copy()
        base = len(verts)
        verts += [matrix @ v.co for v in mesh.vertices]
        polys += [[base + i for i in tri.vertices] for tri in mesh.loop_triangles]
    return BVHTree.FromPolygons(verts, polys)


def test_instanced_copies_cast_the_shadows_a_ray_cast_finds(copies_scene):
    from tests.bpy.bpy_helpers import render_scene
    from tests.bpy.scenes import ray_cast_shadowed, sun_facing_points
    scene, _collection, _objects = copies_scene
    scene.csm.fxaa = False
    engine.forget_final_render_passes()
    images = render_scene(scene, 320, 240)
    sun = next(obj for obj in scene.objects if obj.type == 'LIGHT')
    to_light = np.array(sun.matrix_world.col[2][:3])
    rows, cols, points, normals = sun_facing_points(images, to_light)
    expected = ray_cast_shadowed(_instances_bvh(), points, normals, to_light)
    assert len(points) > 5000
    assert 0.05 < expected.mean() < 0.7, "the view must show both shadow and light"
    csm_shadowed = images["aux"][rows, cols, 0] < 0.5
    mismatch = np.mean(csm_shadowed != expected)
    assert mismatch < 0.02, f"{mismatch:.2%} of sun-facing pixels disagree with the ray cast"
