"""Import with "Replace Current Scene" or "Add to Scene", the sample scenes in File >
Import, and which sun the Light panel edits (pip bpy, in process).

What a student meets: importing a course scene into Blender's startup file leaves only the
course scene (no Cube, Light, grey World), a second import with Replace leaves one
landscape and one sun, Ctrl+Z brings the old scene back, and a failed import changes
nothing. With Add, the Light panel edits the newest import's sun, never a sun the view
layer does not show.
"""

import math
import os
from types import SimpleNamespace

import bpy
import pytest

from csm_engine.blender import light_controls, operators, scene_builder
from csm_engine.blender.scene_builder import SceneImportError
from tests.bpy.addon.test_scene_import import (SCENE_SHADOW, fingerprint, write_box_gltf,
                                               write_scene)
from tests.conftest import SCENES

DEFAULT = os.path.join(SCENES, "default.json")
POINT_LIGHTS = os.path.join(SCENES, "point_lights.json")
SHADOW_TEST = os.path.join(SCENES, "shadow_test.json")


@pytest.fixture
def startup_scene():
    """Blender's startup file: Cube, Light and Camera in "Collection", the grey World."""
    bpy.ops.wm.read_factory_settings(use_empty=False)
    scene = bpy.context.scene
    assert sorted(obj.name for obj in scene.objects) == ["Camera", "Cube", "Light"]
    assert scene.world is not None and scene.world.name == "World"
    scene.render.engine = "CSM"
    return scene


def _kinds(scene, kind):
    return [obj for obj in scene.objects if obj.type == kind]


def _suns(scene):
    return [obj for obj in _kinds(scene, 'LIGHT') if obj.data.type == 'SUN']


def _push(message):
    bpy.ops.ed.undo_push(message=message)


# ------------------------------------------------------------------------ Replace
def test_replace_leaves_only_the_course_scene_and_its_sky(startup_scene):
    collection = scene_builder.import_scene_file(DEFAULT, replace=True)
    scene = bpy.context.scene
    assert [c.name for c in scene.collection.children] == ["default"]
    assert not scene.collection.objects
    assert sorted(obj.name for obj in scene.objects) == sorted(
        obj.name for obj in collection.all_objects)
    for name in ("Cube", "Light", "Collection"):
        assert name not in bpy.data.objects and name not in bpy.data.collections, name
    # The startup data goes with its objects: nothing is left over for a later save.
    assert "Cube" not in bpy.data.meshes and "Light" not in bpy.data.lights
    assert "Material" not in bpy.data.materials
    assert scene.world.name == "CSM Sky" and [w.name for w in bpy.data.worlds] == ["CSM Sky"]
    # The import took the names the startup objects had, not "Camera.001".
    assert scene.camera.name == "Camera" and scene.camera.name in collection.objects
    assert light_controls.sun_object(scene) == collection.objects["Sun"]


def test_a_second_replace_leaves_one_landscape_and_one_sun(startup_scene):
    scene_builder.import_scene_file(DEFAULT, replace=True)
    scene_builder.import_scene_file(POINT_LIGHTS, replace=True)
    scene = bpy.context.scene
    assert [c.name for c in scene.collection.children] == ["point_lights"]
    assert len(_kinds(scene, 'MESH')) == 1
    assert len(_suns(scene)) == 1 and len(bpy.data.lights) == 1 + 6
    assert len(bpy.data.meshes) == 1 and len(bpy.data.worlds) == 1
    # Replacing with the same file again gives the same names (no ".001").
    names = sorted(obj.name for obj in scene.objects)
    scene_builder.import_scene_file(POINT_LIGHTS, replace=True)
    assert sorted(obj.name for obj in bpy.context.scene.objects) == names


def test_replace_takes_hidden_and_excluded_collections_and_keeps_other_scenes(startup_scene):
    scene = startup_scene
    view_layer = bpy.context.view_layer
    hidden = bpy.data.collections.new("hidden")
    scene.collection.children.link(hidden)
    hidden.objects.link(bpy.data.objects.new("hidden empty", None))
    view_layer.layer_collection.children["hidden"].exclude = True
    # Another scene shows the startup Cube and a collection of its own: they stay there.
    other = bpy.data.scenes.new("Other")
    other.collection.objects.link(bpy.data.objects["Cube"])
    shared = bpy.data.collections.new("shared")
    shared.objects.link(bpy.data.objects.new("shared empty", None))
    scene.collection.children.link(shared)
    other.collection.children.link(shared)

    scene_builder.import_scene_file(SHADOW_TEST, replace=True)
    assert "hidden" not in bpy.data.collections and "hidden empty" not in bpy.data.objects
    assert [c.name for c in scene.collection.children] == ["shadow_test"]
    assert "Cube" not in scene.objects and "Light" not in bpy.data.objects
    assert "Cube" in other.objects and bpy.data.objects["Cube"].data is not None
    assert "shared empty" in other.objects and "shared" in other.collection.children
    assert "shared" not in scene.collection.children


def test_a_failed_replace_leaves_the_old_scene_untouched(startup_scene, tmp_path,
                                                        monkeypatch):
    monkeypatch.chdir(tmp_path)
    gltf = tmp_path / "data/gltf/vokselia/vokselia.gltf"
    write_box_gltf(str(gltf))
    path = write_scene(str(tmp_path), "scene.json", SCENE_SHADOW)
    scene_builder.import_scene_file(DEFAULT)
    before = fingerprint()
    # The importer fails after the new collection has been started.
    gltf.write_text(gltf.read_text().replace('"indices": 2', '"indices": 99'))
    with pytest.raises(SceneImportError, match="vokselia.gltf"):
        scene_builder.import_scene_file(path, replace=True)
    assert fingerprint() == before
    assert bpy.context.scene.world.name == "World"
    assert {"Cube", "Light"} <= set(bpy.context.scene.objects.keys())


def test_replace_is_the_operators_default_and_one_undo_step(startup_scene):
    props = bpy.ops.csm.import_scene.get_rna_type().properties
    mode = props["mode"]
    assert mode.default == 'REPLACE'
    assert [item.identifier for item in mode.enum_items] == ['REPLACE', 'ADD']
    assert "File > New" in mode.enum_items['REPLACE'].description
    assert not mode.is_hidden          # drawn in the file browser's side panel
    assert "File > New" in operators.CSM_OT_import_scene.__doc__
    startup_scene.csm_light.fly_speed = 7.0
    _push("startup")
    assert bpy.ops.csm.import_scene('EXEC_DEFAULT', True, filepath=DEFAULT) == {'FINISHED'}
    scene = bpy.context.scene
    assert sorted(obj.type for obj in scene.objects) == ['CAMERA', 'EMPTY', 'LIGHT', 'MESH']
    assert scene.csm_light.fly_speed == 0.0     # a new scene flies at its own speed
    assert scene.render.engine == 'CSM'
    bpy.ops.ed.undo()
    scene = bpy.context.scene
    assert sorted(obj.name for obj in scene.objects) == ["Camera", "Cube", "Light"]
    assert scene.world.name == "World" and "CSM Sky" not in bpy.data.worlds
    assert scene.csm_light.fly_speed == 7.0
    bpy.ops.ed.redo()
    assert [c.name for c in bpy.context.scene.collection.children] == ["default"]


# ------------------------------------------------------------------------ Add
def test_add_keeps_the_startup_objects_and_world(startup_scene):
    assert bpy.ops.csm.import_scene(filepath=DEFAULT, mode='ADD') == {'FINISHED'}
    assert bpy.ops.csm.import_scene(filepath=SHADOW_TEST, mode='ADD') == {'FINISHED'}
    scene = bpy.context.scene
    assert {"Cube", "Light"} <= set(scene.objects.keys())
    assert scene.world.name == "World"
    assert sorted(c.name for c in scene.collection.children) == [
        "Collection", "default", "shadow_test"]


# ------------------------------------------------------------------------ File > Import
class _MenuLayout:
    def __init__(self):
        self.items = []
        self.operator_context = 'INVOKE_REGION_WIN'

    def operator(self, idname, text="", **kwargs):
        item = SimpleNamespace(idname=idname, text=text, context=self.operator_context)
        self.items.append(item)
        return item

    def menu(self, idname, **kwargs):
        self.items.append(SimpleNamespace(idname=idname, text="", context=None))


def test_file_import_lists_the_scene_file_entry_and_the_sample_scenes_by_name():
    drawers = getattr(bpy.types.TOPBAR_MT_file_import, "_dyn_ui_initialize")()
    assert operators.menu_import in drawers
    top = SimpleNamespace(layout=_MenuLayout())
    operators.menu_import(top, bpy.context)
    assert [(i.idname, i.text) for i in top.layout.items] == [
        ("csm.import_scene", "CSM Scene (.json)"), ("CSM_MT_import_sample_scene", "")]
    assert top.layout.items[0].context == 'INVOKE_REGION_WIN'     # opens the file browser

    menu = SimpleNamespace(layout=_MenuLayout())
    bpy.types.CSM_MT_import_sample_scene.draw(menu, bpy.context)
    assert [i.text for i in menu.layout.items] == ["Default", "Point Lights", "Shadow Test"]
    for item in menu.layout.items:
        assert item.idname == "csm.import_scene" and item.context == 'EXEC_DEFAULT'
        assert os.path.isfile(item.filepath) and item.filepath.endswith(".json")
        assert item.mode == 'REPLACE'
    assert menu.layout.items[1].filepath == POINT_LIGHTS


def test_a_sample_scene_from_the_menu_replaces_the_startup_scene(startup_scene):
    _label, path = operators.sample_scenes()[0]
    # What the menu item runs: the operator with the file set, no file browser.
    assert bpy.ops.csm.import_scene('EXEC_DEFAULT', filepath=path) == {'FINISHED'}
    scene = bpy.context.scene
    assert [c.name for c in scene.collection.children] == ["default"]
    assert "Cube" not in bpy.data.objects


# ------------------------------------------------------------------------ the active sun
def test_with_add_the_light_panel_edits_the_newest_imports_sun(startup_scene):
    scene_builder.import_scene_file(DEFAULT)
    scene_builder.import_scene_file(SHADOW_TEST)
    scene = bpy.context.scene
    newest = bpy.data.collections["shadow_test"]
    sun = light_controls.sun_object(scene)
    assert sun.name in newest.objects and len(_suns(scene)) == 2
    scene.csm_light.sun_elevation = math.radians(25.0)
    older = next(obj for obj in _suns(scene) if obj != sun)
    assert older.name in bpy.data.collections["default"].objects
    assert scene.csm_light.sun_elevation == pytest.approx(math.radians(25.0))
    assert light_controls.sun_travel(older) != pytest.approx(light_controls.sun_travel(sun))
    # The user picks the older sun (it becomes the active object): the panel follows.
    bpy.context.view_layer.objects.active = older
    assert light_controls.sun_object(scene) == older
    bpy.context.view_layer.objects.active = None
    assert light_controls.sun_object(scene) == sun


def test_the_render_lights_with_the_sun_the_light_panel_edits(startup_scene):
    """CSM draws one sun: of two, the active one, so what the panel turns is what shows."""
    from csm_engine.blender import snapshot
    scene_builder.import_scene_file(DEFAULT)
    scene_builder.import_scene_file(SHADOW_TEST)
    scene = bpy.context.scene

    def drawn_sun():
        depsgraph = bpy.context.evaluated_depsgraph_get()
        camera = snapshot.camera_from_scene(scene, depsgraph, 64, 36)
        return snapshot.take(depsgraph, camera).sun.name

    sun = light_controls.sun_object(scene)
    assert drawn_sun() == sun.name
    older = next(obj for obj in _suns(scene) if obj != sun)
    bpy.context.view_layer.objects.active = older
    assert drawn_sun() == older.name


def test_a_sun_the_view_layer_does_not_show_is_never_the_active_sun(startup_scene):
    scene_builder.import_scene_file(DEFAULT)
    scene_builder.import_scene_file(SHADOW_TEST)
    scene = bpy.context.scene
    view_layer = bpy.context.view_layer
    older = bpy.data.collections["default"].objects["Sun"]
    newest_layer = view_layer.layer_collection.children["shadow_test"]

    newest_layer.exclude = True
    assert light_controls.sun_object(scene) == older
    view_layer.objects.active = None
    newest_layer.exclude = False
    newest_layer.hide_viewport = True            # the eye icon in the outliner
    assert light_controls.sun_object(scene) == older
    view_layer.layer_collection.children["default"].exclude = True
    assert light_controls.sun_object(scene) is None
    # A user's own sun in an excluded collection is not picked by name either.
    own = bpy.data.collections.new("own")
    scene.collection.children.link(own)
    own.objects.link(bpy.data.objects.new("A Sun", bpy.data.lights.new("A Sun", 'SUN')))
    view_layer.layer_collection.children["own"].exclude = True
    assert light_controls.sun_object(scene) is None
    view_layer.layer_collection.children["own"].exclude = False
    assert light_controls.sun_object(scene).name == "A Sun"
