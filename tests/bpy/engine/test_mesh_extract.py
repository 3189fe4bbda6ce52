"""Mesh extraction: the fast generic-attribute reads give exactly what Blender's per-element
paths give (positions, corner normals, UVs, triangles, material slots, bounds), so the speed-up
cannot change a picture."""
import bmesh
import bpy
import numpy as np

from csm_engine.blender import mesh_cache


def _slow_reference(mesh):
    """The same arrays through the per-element RNA paths (what 3.4 reads)."""
    mesh.calc_loop_triangles()
    loops, tris = len(mesh.loops), len(mesh.loop_triangles)
    coords = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", coords)
    vertex_index = np.empty(loops, np.int32)
    mesh.loops.foreach_get("vertex_index", vertex_index)
    uvs = np.empty(loops * 2, np.float32)
    mesh.uv_layers.active.data.foreach_get("uv", uvs)
    triangles = np.empty(tris * 3, np.int32)
    mesh.loop_triangles.foreach_get("loops", triangles)
    material_index = np.empty(tris, np.int32)
    mesh.loop_triangles.foreach_get("material_index", material_index)
    return (coords.reshape(-1, 3)[vertex_index], uvs.reshape(-1, 2), triangles.reshape(-1, 3),
            material_index, coords.reshape(-1, 3))


def _two_material_mesh():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.5,
                                         location=(3.0, -1.0, 2.0))
    obj = bpy.context.object
    mesh = obj.data
    # A pentagon fan cap (n-gons triangulate through Blender's polyfill) and a second
    # material on every third face.
    bm = bmesh.new()
    bm.from_mesh(mesh)
    bmesh.ops.translate(bm, verts=bm.verts, vec=(0.25, 0.0, -0.5))
    bm.to_mesh(mesh)
    bm.free()
    for name in ("first", "second"):
        mesh.materials.append(bpy.data.materials.new(name))
    indices = (np.arange(len(mesh.polygons)) % 3 == 0).astype(np.int32)
    mesh.polygons.foreach_set("material_index", indices)
    mesh.update()
    return obj


def test_fast_extraction_matches_blenders_per_element_paths():
    obj = _two_material_mesh()
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    try:
        positions, normals, uvs, triangles, material_index, (lo, hi) = \
            mesh_cache.extract_arrays(mesh)
        ref_positions, ref_uvs, ref_triangles, ref_material, coords = _slow_reference(mesh)
    finally:
        evaluated.to_mesh_clear()
    assert np.array_equal(positions, ref_positions)
    assert np.array_equal(uvs, ref_uvs)
    assert np.array_equal(triangles, ref_triangles)
    assert np.array_equal(material_index, ref_material)
    assert set(np.unique(material_index)) == {0, 1}, "both slots are used"
    assert np.allclose(lo, coords.min(axis=0)) and np.allclose(hi, coords.max(axis=0))
    assert normals.shape == positions.shape
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-4)


def test_single_material_mesh_has_slot_zero_everywhere():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.object
    evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = evaluated.to_mesh()
    try:
        arrays = mesh_cache.extract_arrays(mesh)
        reference = _slow_reference(mesh)
        triangle_count = len(mesh.loop_triangles)
    finally:
        evaluated.to_mesh_clear()
    assert len(arrays[4]) == triangle_count == 968
    assert not arrays[4].any()
    assert np.array_equal(arrays[3], reference[2])


def test_shared_vertices_draw_the_same_pixels_as_one_vertex_per_corner(empty_scene,
                                                                        monkeypatch):
    """Smooth, flat, UV-seamed, normal-mapped and mirrored meshes: sharing GPU vertices
    between agreeing corners changes no pixel, and a smooth sphere uploads one vertex per
    mesh vertex (not one per corner)."""
    from csm_engine.blender import engine
    from csm_engine.core import vertex_sharing
    from tests.bpy.bpy_helpers import render_result
    from tests.bpy.engine.test_materials import normal_mapped_material
    scene = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=14)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, location=(-2, 0, 1.2))
    sphere = bpy.context.object
    if hasattr(sphere.data, "shade_smooth"):
        sphere.data.shade_smooth()
    else:
        for polygon in sphere.data.polygons:
            polygon.use_smooth = True
    bpy.ops.mesh.primitive_cube_add(location=(1.5, 0, 1.0))          # flat, UV seams
    bpy.ops.mesh.primitive_monkey_add(location=(0, 2.5, 1.2))
    monkey = bpy.context.object
    monkey.scale.x = -1.0                                             # mirrored
    monkey.data.materials.append(normal_mapped_material("bumpy", 15))  # tangents
    bpy.ops.object.light_add(type='SUN', rotation=(np.radians(40), np.radians(20), 0))
    bpy.ops.object.camera_add(location=(8, -8, 6), rotation=(np.radians(60), 0,
                                                              np.radians(45)))
    scene.camera = bpy.context.object

    engine.forget_final_render_meshes()
    result = render_result(scene, 160, 120)
    shared, shared_bytes = result.images["combined"].copy(), result.upload_bytes

    def one_per_corner(corner_verts, vertex_count, corner_arrays):
        corners = np.arange(len(corner_verts))
        return corners, corners
    monkeypatch.setattr(mesh_cache, "share_vertices", one_per_corner)
    engine.forget_final_render_meshes()
    result = render_result(scene, 160, 120)
    per_corner, per_corner_bytes = result.images["combined"], result.upload_bytes
    assert np.array_equal(shared, per_corner)
    assert shared_bytes < 0.8 * per_corner_bytes     # flat cube and monkey keep theirs

    mesh = sphere.data
    first, _ = vertex_sharing.share_vertices(
        mesh_cache.read_arrays(mesh)["corner_verts"], len(mesh.vertices),
        (mesh_cache.read_arrays(mesh)["normals"], mesh_cache.read_arrays(mesh)["uvs"]))
    # The UV sphere's one seam (and its poles' UVs) keep a few corners apart.
    assert len(first) < 1.3 * len(mesh.vertices) < 0.4 * len(mesh.loops)
