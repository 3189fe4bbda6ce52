"""The G-buffer's packed targets (shaders/gbuffer_layout.glsl) give back what was drawn: the
normals a user reads from the Normal pass are the faces' own, finer than the half floats
the G-buffer held before, and the background has none.
"""
import bpy
import numpy as np
from mathutils import Euler

from tests.bpy.bpy_helpers import render_scene
from tests.bpy.scenes import add_camera, add_sun

W, H = 120, 90


def _face_normals(obj):
    """The world normals of ``obj``'s faces (flat shaded, no scale)."""
    rotation = obj.matrix_world.to_3x3()
    return np.array([tuple((rotation @ polygon.normal).normalized())
                     for polygon in obj.data.polygons])


def test_normals_come_back_as_the_faces_own(empty_scene):
    """A flat-shaded ico sphere turned off every axis, and a ground: every covered pixel's
    normal is one of their face normals within 2.5e-4 (two 15-bit octahedral coordinates:
    ~1e-4; the half floats held before were off by up to ~5e-4), every background pixel's
    is zero. A packing mistake (a swapped or mis-signed coordinate, a wrong fold of the
    lower hemisphere) is off by far more."""
    scene = empty_scene
    bpy.ops.mesh.primitive_plane_add(size=12)
    ground = bpy.context.object
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=1, radius=1.5, location=(0, 0, 1.6))
    sphere = bpy.context.object
    sphere.rotation_euler = Euler((0.3, 0.7, 1.1))
    bpy.context.view_layer.update()
    add_sun((0.3, 0.2, -1.0))
    add_camera(scene, (3.0, -6.0, 5.0), (0, 0, 0.8), lens=30)
    scene.csm.fxaa = False
    scene.csm.render_samples = 1
    images = render_scene(scene, W, H)
    normal = images["normal"][..., :3].astype(np.float64)
    covered = images["aux"][..., 3] > 0.5
    faces = np.concatenate([_face_normals(sphere), _face_normals(ground)])
    # Facing the camera: the lower hemisphere's faces (z < 0) are among them.
    assert (normal[covered][:, 2] < -0.2).any()
    error = np.linalg.norm(normal[covered][:, None, :] - faces[None], axis=-1).min(axis=1)
    print(f"normal error over {int(covered.sum())} pixels: max {error.max():.1e}, "
          f"mean {error.mean():.1e}")
    assert 0.2 < covered.mean() < 0.95
    assert error.max() <= 2.5e-4
    assert not normal[~covered].any()
