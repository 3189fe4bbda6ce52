"""Instanced objects in a final render: a collection instance's objects come from the
depsgraph as temporaries, so their meshes must be read from the evaluated originals."""
import bpy
import numpy as np

from tests.bpy.scenes import add_camera, add_ground, add_sun
from csm_engine.blender import engine


def test_collection_instances_render_and_cast_shadows(empty_scene):
    scene = empty_scene
    add_ground(40.0)
    add_sun((0.4, 0.3, -0.87))
    add_camera(scene, (0.0, -16.0, 8.0), (0.0, 0.0, 0.0))
    collection = bpy.data.collections.new("instanced")
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.object
    scene.collection.objects.unlink(cube)
    collection.objects.link(cube)
    for index in range(3):
        empty = bpy.data.objects.new(f"copy{index}", None)
        empty.instance_type = 'COLLECTION'
        empty.instance_collection = collection
        empty.location = (-4.0 + 4.0 * index, 0.0, 1.0)
        scene.collection.objects.link(empty)
    scene.render.engine = "CSM"
    result = engine.render_final(scene, keep_images=True)
    assert result.error is None, result.error
    without = result.images["combined"].copy()
    for index in range(3):
        bpy.data.objects[f"copy{index}"].instance_collection = None
    bpy.context.view_layer.update()
    result = engine.render_final(scene, keep_images=True)
    assert result.error is None, result.error
    # The copies change a visible share of the picture (their faces and shadows).
    changed = np.abs(without[..., :3] - result.images["combined"][..., :3]).max(axis=-1) > 0.02
    assert changed.mean() > 0.01, changed.mean()
