"""Undo and redo of CSM changes on pip bpy (no window): what Ctrl+Z / Ctrl+Shift+Z do.

A button in the sidebar pushes one undo step per change, and an operator with ``'UNDO'``
in ``bl_options`` (import, reload, reset sun) pushes one when it finishes from a key or a
button. Without a window Blender pushes neither, so ``bpy.ops.ed.undo_push`` stands in for
those pushes here, and ``ed.undo`` / ``ed.redo`` for the keys. What is checked is what the
steps hold: the add-on's settings, the imported collection, the Sun's rotation (the
sidebar's azimuth/elevation are views onto it). Blender's memfile undo reloads the data,
so every datablock is looked up again after an undo (no stale Python references).
The same Ctrl+Z / Ctrl+Shift+Z in a real Blender 3.4 window: ``tests/hosts/test_gui_controls.py``.
"""

import os

import bpy
import numpy as np
import pytest

from bpy_helpers import REPO
from csm_engine import light_controls

DEFAULT_SCENE = os.path.join(REPO, "data", "scenes", "default.json")


@pytest.fixture
def undo_scene():
    """A fresh file rendering with CSM, with a first undo step to go back to."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CSM"
    bpy.ops.ed.undo_push(message="CSM test start")
    return scene


def push(message):
    bpy.ops.ed.undo_push(message=message)


def csm():
    return bpy.context.scene.csm


def sun_travel():
    return np.array(light_controls.sun_travel(light_controls.sun_object(bpy.context.scene)))


def file_travel():
    sun = light_controls.sun_object(bpy.context.scene)
    return np.array(light_controls.file_sun_direction(sun))


def test_undo_and_redo_a_csm_setting(undo_scene):
    assert csm().stabilize is True and csm().cascade_count == 3
    csm().stabilize = False
    push("Stabilize")
    csm().cascade_count = 2
    push("Cascades")
    bpy.ops.ed.undo()
    assert (csm().stabilize, csm().cascade_count) == (False, 3)
    bpy.ops.ed.undo()
    assert (csm().stabilize, csm().cascade_count) == (True, 3)
    bpy.ops.ed.redo()
    assert (csm().stabilize, csm().cascade_count) == (False, 3)
    bpy.ops.ed.redo()
    assert (csm().stabilize, csm().cascade_count) == (False, 2)
    assert bpy.context.scene.render.engine == "CSM"


def test_undo_an_enum_setting_and_the_debug_view(undo_scene):
    csm().split_scheme = 'LOG' if csm().split_scheme != 'LOG' else 'UNIFORM'
    changed = csm().split_scheme
    push("Split scheme")
    csm().debug_view = 'CASCADES'
    push("Debug view")
    bpy.ops.ed.undo()
    assert (csm().split_scheme, csm().debug_view) == (changed, 'NONE')
    bpy.ops.ed.undo()
    assert csm().split_scheme != changed


def test_undo_brings_back_an_import(undo_scene):
    assert bpy.ops.csm.import_scene(filepath=DEFAULT_SCENE) == {'FINISHED'}
    push("Import CSM Scene")
    assert light_controls.sun_object(bpy.context.scene) is not None
    assert bpy.context.scene.render.engine == "CSM"
    bpy.ops.ed.undo()
    assert light_controls.sun_object(bpy.context.scene) is None
    assert not [c for c in bpy.data.collections if "csm_source" in c]
    bpy.ops.ed.redo()
    assert light_controls.sun_object(bpy.context.scene) is not None
    np.testing.assert_allclose(sun_travel(), file_travel(), atol=1e-6)


def test_undo_a_sun_edit_then_undo_the_reload_that_reset_it(undo_scene):
    """Sidebar azimuth edit, Ctrl+R (reload), then Ctrl+Z twice: edit back, then file sun."""
    bpy.ops.csm.import_scene(filepath=DEFAULT_SCENE)
    push("Import CSM Scene")
    from_file = sun_travel()
    light = bpy.context.scene.csm_light
    azimuth = light.sun_azimuth
    light.sun_azimuth = azimuth + 40.0
    push("Sun Azimuth")
    edited = sun_travel()
    assert np.degrees(np.arccos(np.clip(edited @ from_file, -1, 1))) > 10.0
    assert bpy.ops.csm.reload_scene() == {'FINISHED'}
    push("Reload CSM Scene")
    np.testing.assert_allclose(sun_travel(), from_file, atol=1e-6)
    bpy.ops.ed.undo()       # the reload
    np.testing.assert_allclose(sun_travel(), edited, atol=1e-6)
    assert abs(bpy.context.scene.csm_light.sun_azimuth - (azimuth + 40.0)) < 1e-3
    bpy.ops.ed.undo()       # the azimuth edit
    np.testing.assert_allclose(sun_travel(), from_file, atol=1e-6)
    bpy.ops.ed.redo()
    bpy.ops.ed.redo()
    np.testing.assert_allclose(sun_travel(), from_file, atol=1e-6)
    assert len([c for c in bpy.data.collections if "csm_source" in c]) == 1


def test_undo_reset_sun_direction(undo_scene):
    bpy.ops.csm.import_scene(filepath=DEFAULT_SCENE)
    push("Import CSM Scene")
    bpy.context.scene.csm_light.sun_elevation = 70.0
    push("Sun Elevation")
    edited = sun_travel()
    assert bpy.ops.csm.reset_sun_direction() == {'FINISHED'}
    push("Reset to Scene File")
    np.testing.assert_allclose(sun_travel(), file_travel(), atol=1e-6)
    bpy.ops.ed.undo()
    np.testing.assert_allclose(sun_travel(), edited, atol=1e-6)
    assert abs(bpy.context.scene.csm_light.sun_elevation - 70.0) < 1e-3
