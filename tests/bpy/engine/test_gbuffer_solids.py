"""The G-buffer culls the back faces of a big closed solid the camera sees from outside,
the shadow pass those turned away from the light (render/gbuffer.py ``seen_from_outside``,
render/shadow_atlas.py, render/draw_lists.py ``closed_outward``): the picture must stay
what drawing every face gives, and a camera inside a solid must still see its walls.
"""
import bpy
import numpy as np

from csm_engine.render import draw_lists, gbuffer
from tests.bpy.bpy_helpers import render_result

W, H = 160, 120


def _triangles(obj):
    """(positions, triangles) of an object's mesh, as a GPU mesh holds them."""
    mesh = obj.data
    mesh.calc_loop_triangles()
    positions = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", positions)
    triangles = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("vertices", triangles)
    return positions.reshape(-1, 3), triangles.reshape(-1, 3)


def _sphere(location=(0, 0, 1.2), radius=1.0):
    """An ico sphere of 81,920 triangles (above ``SOLID_CHECK_MIN_TRIANGLES``)."""
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=7, radius=radius, location=location)
    return bpy.context.object


def test_a_closed_solid_is_told_from_an_open_or_inside_out_mesh(empty_scene):
    sphere = _sphere()
    positions, triangles = _triangles(sphere)
    assert len(triangles) >= draw_lists.SOLID_CHECK_MIN_TRIANGLES
    assert draw_lists._closed_outward(positions, triangles)
    # Inside out (each triangle wound the other way): its outside faces are back faces.
    assert not draw_lists._closed_outward(positions, triangles[:, ::-1])
    # A hole: one triangle missing.
    assert not draw_lists._closed_outward(positions, triangles[1:])
    # Corners split apart (as at UV seams) are welded back by position.
    split = np.concatenate([positions, positions[triangles[0]]])
    resplit = triangles.copy()
    resplit[0] = len(positions) + np.arange(3)
    assert draw_lists._closed_outward(split, resplit)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=200, y_subdivisions=200, size=4)
    assert not draw_lists._closed_outward(*_triangles(bpy.context.object))


def _scene(empty_scene, camera_location, camera_rotation):
    scene = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=20)
    _sphere()
    bpy.ops.object.light_add(type='SUN', rotation=(np.radians(35), 0, np.radians(25)))
    bpy.ops.object.camera_add(location=camera_location, rotation=camera_rotation)
    scene.camera = bpy.context.object
    return scene


def _both(scene, monkeypatch):
    """(pixels with the solids' back faces culled, pixels without, which instances were
    culled)."""
    culled = []
    real = gbuffer.seen_from_outside

    def spy(camera, instances):
        solids = real(camera, instances)
        culled.append(solids.copy())
        return solids
    monkeypatch.setattr(gbuffer, "seen_from_outside", spy)
    with_culling = render_result(scene, W, H).images["combined"].copy()
    monkeypatch.setattr(gbuffer, "seen_from_outside",
                        lambda camera, instances: np.zeros(len(instances.meshes), bool))
    plain = render_result(scene, W, H).images["combined"].copy()
    return with_culling, plain, culled


def test_culling_a_solid_seen_from_outside_keeps_the_picture(empty_scene, monkeypatch):
    scene = _scene(empty_scene, (0, -5, 3), (np.radians(65), 0, 0))
    with_culling, plain, culled = _both(scene, monkeypatch)
    assert sum(int(c.sum()) for c in culled) >= 1, "the sphere's back faces were culled"
    difference = np.abs(with_culling - plain).max(axis=-1)
    # A back face may own a pixel on the silhouette, where a grazing ray meets both sides;
    # nothing else may change.
    assert (difference > 0.01).mean() < 1e-3, (difference > 0.01).sum()
    assert plain[..., :3].std() > 0.05      # the sphere, its shadow and the ground are there


def test_a_camera_inside_a_solid_still_sees_its_walls(empty_scene, monkeypatch):
    scene = _scene(empty_scene, (0, -0.2, 1.2), (np.radians(90), 0, 0))
    # The camera stands in the middle of the sphere: its inside is all back faces.
    with_culling, plain, culled = _both(scene, monkeypatch)
    assert not any(c.any() for c in culled)
    assert np.array_equal(with_culling, plain)
    coverage = render_result(scene, W, H).images["aux"][..., 3]
    assert coverage.min() > 0.5, "every pixel shows the sphere's inside"


def test_the_shadow_maps_of_a_solid_without_its_far_side_are_the_same(empty_scene,
                                                                       monkeypatch):
    """The shadow pass draws a closed solid wholly beyond a cascade's near plane without
    the faces turned away from the light: the nearest depth each texel keeps is the
    same, so are the shadows."""
    from csm_engine.blender import engine
    from csm_engine.render import shadow_atlas
    scene = _scene(empty_scene, (0, -5, 3), (np.radians(65), 0, 0))
    culled = []
    real = shadow_atlas._solids_beyond_near

    def spy(instances, tile, visible):
        solids = real(instances, tile, visible)
        culled.append(solids is not None and bool(solids.any()))
        return solids
    monkeypatch.setattr(shadow_atlas, "_solids_beyond_near", spy)
    engine.forget_final_render_passes()
    with_culling = render_result(scene, W, H).images["aux"][..., 0].copy()
    assert any(culled), "the sphere was drawn without its far side"
    monkeypatch.setattr(shadow_atlas, "_solids_beyond_near", lambda *args: None)
    engine.forget_final_render_passes()
    plain = render_result(scene, W, H).images["aux"][..., 0].copy()
    assert (plain < 0.5).mean() > 0.01, "the sphere casts a shadow in view"
    assert np.abs(with_culling - plain).max() < 1e-6
