"""Undo for every setting change, import and reload, on pip bpy 5.0 without a window.

Blender's undo is a memory-file undo of the whole ``bpy.data``: an undo step is pushed when
an operator with ``{'REGISTER', 'UNDO'}`` finishes or when a property is edited in the UI.
Called from Python, ``bpy.ops.x()`` pushes nothing; ``bpy.ops.x('EXEC_DEFAULT', True)``
pushes the step a user's click or shortcut would (the second argument is ``undo``), and
``bpy.ops.ed.undo_push`` stands in for the step a UI property edit pushes. So these tests
check what a user gets from Ctrl+Z: the CSM data (settings on the scene, the sun's
direction in the Sun object, imported collections) is restored exactly, and the render
engine stays CSM through import, reload, undo and redo.

The same checks through the real window (Blender 3.4, Ctrl+R then Ctrl+Z) are in
``tests/hosts/test_gui_controls.py``.
"""

import json
import math
import os

import bpy
import numpy as np
import pytest

from tests.conftest import REPO
from csm_engine.blender import light_controls, operators, scene_builder, settings

DEFAULT_SCENE = os.path.join(REPO, "csm_engine", "data", "scenes", "default.json")


def _push(message):
    bpy.ops.ed.undo_push(message=message)


def _undo():
    bpy.ops.ed.undo()
    return bpy.context.scene      # undo replaces every datablock: fetch the scene again


def _redo():
    bpy.ops.ed.redo()
    return bpy.context.scene


def _sun_travel(scene):
    return np.array(light_controls.sun_travel(light_controls.sun_object(scene)))


def _imported(scene):
    return [c.name for c in scene_builder.imported_collections(scene)]


@pytest.fixture
def csm_scene(empty_scene):
    """An empty CSM scene with an undo step for its starting state, as after a user's
    earlier actions (without it, Ctrl+Z would go back past the scene's set-up)."""
    _push("CSM scene set up")
    return empty_scene


@pytest.fixture
def default_copy(tmp_path):
    """default.json copied to a temp dir, its mesh path made absolute (so it can change)."""
    with open(DEFAULT_SCENE, encoding="utf-8") as handle:
        data = json.load(handle)
    mesh = data["objects"][0]["mesh"]
    data["objects"][0]["mesh"] = os.path.normpath(
        os.path.join(os.path.dirname(DEFAULT_SCENE), mesh))
    path = tmp_path / "default.json"
    path.write_text(json.dumps(data, indent=2), encoding="utf-8")
    return path


# ------------------------------------------------------------------------ settings
def _other_value(prop, value):
    """A valid value of ``prop`` different from ``value``."""
    if prop.type == 'BOOLEAN':
        return not value
    if prop.type == 'ENUM':
        return next(item.identifier for item in prop.enum_items if item.identifier != value)
    if prop.type in ('INT', 'FLOAT'):
        low = max(prop.hard_min, prop.soft_min)
        high = min(prop.hard_max, prop.soft_max)
        if prop.array_length:
            return [_other_number(prop.type, low, high, v, 0.2 + 0.15 * i)
                    for i, v in enumerate(value)]
        return _other_number(prop.type, low, high, value, 0.37)
    raise AssertionError(f"no test value for {prop.identifier} ({prop.type})")


def _other_number(kind, low, high, value, fraction):
    target = low + (high - low) * fraction
    if kind == 'INT':
        target = int(round(target))
        return target if target != value else (target + 1 if target < high else target - 1)
    return target if abs(target - value) > 1e-6 else (low + high) / 2.0


def _as_plain(value):
    return list(value) if hasattr(value, "__len__") and not isinstance(value, str) else value


def test_undo_restores_every_csm_setting_and_redo_reapplies_it(csm_scene):
    names = [p.identifier for p in settings.CSMSettings.bl_rna.properties
             if p.identifier not in ("rna_type", "name") and not p.is_readonly]
    assert len(names) > 15, names
    for name in names:
        scene = bpy.context.scene
        prop = scene.csm.bl_rna.properties[name]
        before = _as_plain(getattr(scene.csm, name))
        setattr(scene.csm, name, _other_value(prop, before))
        after = _as_plain(getattr(scene.csm, name))
        assert after != before, name
        _push(f"CSM {name}")                   # what the UI pushes after an edit
        scene = _undo()
        assert _as_plain(getattr(scene.csm, name)) == pytest.approx(before), name
        scene = _redo()
        assert _as_plain(getattr(scene.csm, name)) == pytest.approx(after), name
        assert scene.render.engine == 'CSM'


def test_undo_restores_the_first_person_speed_settings(csm_scene):
    csm_scene.csm_light.fly_speed = 3.0
    csm_scene.csm_light.fly_turn_speed = math.radians(45.0)
    _push("fly speed")
    scene = _undo()
    assert scene.csm_light.fly_speed == 0.0                       # automatic
    assert scene.csm_light.fly_turn_speed == pytest.approx(math.radians(90.0))


# ------------------------------------------------------------------------ import
def test_import_is_one_undo_step_and_keeps_the_engine(csm_scene):
    objects_before = sorted(obj.name for obj in csm_scene.objects)
    assert bpy.ops.csm.import_scene('EXEC_DEFAULT', True, filepath=DEFAULT_SCENE) == {'FINISHED'}
    scene = bpy.context.scene
    assert _imported(scene) == ["default"]
    imported_objects = sorted(obj.name for obj in scene.objects)
    assert light_controls.sun_object(scene) is not None
    assert scene.render.engine == 'CSM'

    scene = _undo()
    assert _imported(scene) == []
    assert sorted(obj.name for obj in scene.objects) == objects_before
    assert scene.render.engine == 'CSM'

    scene = _redo()
    assert _imported(scene) == ["default"]
    assert sorted(obj.name for obj in scene.objects) == imported_objects
    assert scene.render.engine == 'CSM'


# ------------------------------------------------------------------------ sun and reload
def test_sun_edit_reset_and_reload_each_undo_to_the_step_before(csm_scene, default_copy):
    assert bpy.ops.csm.import_scene('EXEC_DEFAULT', True,
                                    filepath=str(default_copy)) == {'FINISHED'}
    scene = bpy.context.scene
    file_travel = _sun_travel(scene)

    # A panel edit (azimuth/elevation fields) is one undo step of the Sun's rotation.
    scene.csm_light.sun_azimuth = math.radians(120.0)
    scene.csm_light.sun_elevation = math.radians(20.0)
    _push("Sun Elevation")
    edited = _sun_travel(scene)
    assert np.degrees(np.arccos(np.clip(edited @ file_travel, -1, 1))) > 10.0

    # "Reset to Scene File" and Ctrl+R are operators with their own undo steps.
    assert bpy.ops.csm.reset_sun_direction('EXEC_DEFAULT', True) == {'FINISHED'}
    np.testing.assert_allclose(_sun_travel(bpy.context.scene), file_travel, atol=1e-6)
    scene = _undo()
    np.testing.assert_allclose(_sun_travel(scene), edited, atol=1e-6)

    objects = sorted(obj.name for obj in scene.objects)
    assert bpy.ops.csm.reload_scene('EXEC_DEFAULT', True) == {'FINISHED'}
    scene = bpy.context.scene
    np.testing.assert_allclose(_sun_travel(scene), file_travel, atol=1e-6)
    assert sorted(obj.name for obj in scene.objects) == objects
    assert scene.render.engine == 'CSM'

    scene = _undo()          # Ctrl+Z after Ctrl+R: the edited sun is back
    np.testing.assert_allclose(_sun_travel(scene), edited, atol=1e-6)
    assert sorted(obj.name for obj in scene.objects) == objects
    assert _imported(scene) == ["default"]
    assert scene.render.engine == 'CSM'

    scene = _undo()          # and once more: before the panel edit
    np.testing.assert_allclose(_sun_travel(scene), file_travel, atol=1e-6)

    scene = _redo()
    scene = _redo()          # Ctrl+Shift+Z twice: the reload again
    np.testing.assert_allclose(_sun_travel(scene), file_travel, atol=1e-6)
    assert scene.render.engine == 'CSM'


def test_a_reload_that_changes_the_file_undoes_to_the_old_contents(csm_scene, default_copy):
    assert bpy.ops.csm.import_scene('EXEC_DEFAULT', True,
                                    filepath=str(default_copy)) == {'FINISHED'}
    old_travel = _sun_travel(bpy.context.scene)
    data = json.loads(default_copy.read_text(encoding="utf-8"))
    data["directional_light"]["direction"] = {"x": -0.5, "y": -1.0, "z": 0.2}
    default_copy.write_text(json.dumps(data), encoding="utf-8")
    assert bpy.ops.csm.reload_scene('EXEC_DEFAULT', True) == {'FINISHED'}
    new_travel = _sun_travel(bpy.context.scene)
    assert not np.allclose(new_travel, old_travel, atol=1e-3)
    scene = _undo()
    np.testing.assert_allclose(_sun_travel(scene), old_travel, atol=1e-6)
    np.testing.assert_allclose(
        scene_builder.imported_collections(scene)[0]["csm_sun_direction"],
        bpy.data.collections["default"]["csm_sun_direction"])
    scene = _redo()
    np.testing.assert_allclose(_sun_travel(scene), new_travel, atol=1e-6)


def test_a_failed_reload_pushes_no_undo_step(csm_scene, default_copy):
    assert bpy.ops.csm.import_scene('EXEC_DEFAULT', True,
                                    filepath=str(default_copy)) == {'FINISHED'}
    scene = bpy.context.scene
    scene.csm.pcf_radius = 3
    _push("PCF Radius")
    default_copy.write_text("{ broken", encoding="utf-8")
    with pytest.raises(RuntimeError, match="default.json"):
        bpy.ops.csm.reload_scene('EXEC_DEFAULT', True)
    # Ctrl+Z undoes the user's last real change, not a no-op reload.
    scene = _undo()
    assert scene.csm.pcf_radius != 3
    assert _imported(scene) == ["default"]


# ------------------------------------------------------------------------ render engine
def test_import_and_reload_put_back_an_engine_an_importer_switched(csm_scene, monkeypatch):
    """Blender 3.4's glTF importer sets the scene to Eevee unless it renders with Cycles or
    Eevee (io_scene_gltf2/blender/imp/gltf2_blender_scene.py); the CSM operators undo that.
    Here an importer that does the same stands in for it (4.2 and 5.0 no longer switch)."""
    real_build = scene_builder._build

    def switching_build(*args, **kwargs):
        for scene in bpy.data.scenes:
            scene.render.engine = 'BLENDER_WORKBENCH'
        return real_build(*args, **kwargs)

    monkeypatch.setattr(scene_builder, "_build", switching_build)
    assert bpy.ops.csm.import_scene('EXEC_DEFAULT', True, filepath=DEFAULT_SCENE) == {'FINISHED'}
    assert bpy.context.scene.render.engine == 'CSM'
    assert bpy.ops.csm.reload_scene('EXEC_DEFAULT', True) == {'FINISHED'}
    assert bpy.context.scene.render.engine == 'CSM'
    scene = _undo()
    assert scene.render.engine == 'CSM' and _imported(scene) == ["default"]

    with operators.keeping_render_engines():
        bpy.context.scene.render.engine = 'CYCLES'
    assert bpy.context.scene.render.engine == 'CSM'
