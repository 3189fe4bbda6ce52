"""A mesh file referenced several times: the copies object and its source collection are
part of the import's one transaction (a failure leaves nothing), and what the user sees
of them (Outliner names, the source kept out of the view layer)."""
import bpy
import pytest

from csm_engine.blender import object_builders, scene_builder
from csm_engine.blender.scene_builder import SceneImportError
from tests.bpy.addon.test_scene_import import write_box_obj, write_scene


@pytest.fixture
def scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def _names(kind):
    return sorted(block.name for block in getattr(bpy.data, kind))


def test_a_failure_after_the_copies_leaves_nothing_behind(scene, tmp_path, monkeypatch):
    box = write_box_obj(str(tmp_path / "box.obj"), (-1, 0, -1), (1, 1, 1))
    before = {kind: _names(kind) for kind in ("objects", "collections", "meshes",
                                              "node_groups")}
    path = write_scene(str(tmp_path), "two.json", {"objects": [
        {"mesh": box}, {"mesh": box, "translate": {"x": 3, "y": 0, "z": 0}}]})

    def fail(*_args):
        raise RuntimeError("no camera today")
    # The default camera is built after the source collection and the copies object.
    monkeypatch.setattr(object_builders, "add_default_camera", fail)
    with pytest.raises(SceneImportError, match="no camera today"):
        scene_builder.import_scene_file(path, scene)
    assert {kind: _names(kind) for kind in before} == before


def test_the_outliner_shows_the_copies_object_and_an_excluded_source(scene, tmp_path):
    box = write_box_obj(str(tmp_path / "box.obj"), (-1, 0, -1), (1, 1, 1))
    path = write_scene(str(tmp_path), "three.json", {"objects": [
        {"mesh": box, "translate": {"x": 3.0 * i, "y": 0, "z": 0}} for i in range(3)]})
    collection = scene_builder.import_scene_file(path, scene)
    assert "box (3 copies)" in collection.objects
    source = collection.children["box (source)"]
    assert sorted(obj.name for obj in source.objects) == ["box", "box (source)"]
    layer = bpy.context.view_layer.layer_collection.children[collection.name]
    assert layer.children[source.name].exclude
    # The copies object is what the import selects and makes active.
    assert bpy.context.view_layer.objects.active.name == "box (3 copies)"


def test_replace_current_scene_keeps_the_new_copies_and_their_source(scene, tmp_path):
    box = write_box_obj(str(tmp_path / "box.obj"), (-1, 0, -1), (1, 1, 1))
    path = write_scene(str(tmp_path), "two.json", {"objects": [
        {"mesh": box}, {"mesh": box, "translate": {"x": 3, "y": 0, "z": 0}}]})
    for _ in range(2):
        collection = scene_builder.import_scene_file(path, scene, replace=True)
        assert sorted(obj.name for obj in collection.all_objects) == sorted(
            ["box (2 copies)", "box", "box (source)", "Camera (default view)"])
        assert [group.name for group in bpy.data.node_groups] == ["CSM Copies"]
        depsgraph = bpy.context.evaluated_depsgraph_get()
        assert sum(1 for i in depsgraph.object_instances
                   if i.is_instance and i.object.type == 'MESH') == 2
