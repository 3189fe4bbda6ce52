"""Operators, keymap, sun controls and panels as a user meets them (pip bpy, no window).

Covers: the 3D View shortcuts in the add-on keymap, F5 shader reload with last-good
fallback (a real GLSL error and its fix), Ctrl+R reload resetting the light and surviving a
broken file, the sun azimuth/elevation/vector controls and "Reset to scene file", the
screenshot PNG, the first-person movement math, and the Light/Scene panel contents.
Here only the first-person operator's registration and poll are checked; its modal keys
(cancel, confirm, wheel) are driven with fake events in ``test_first_person.py``.
"""

import json
import math
import os
import re
import shutil

import bpy
import numpy as np
import pytest

from tests.bpy.bpy_helpers import RecordingLayout, load_png, render_scene
from tests.conftest import REPO
from csm_engine.blender import keymap, light_controls, operators, ui
from csm_engine.core import controls, paths
from csm_engine.render import shaders

DEFAULT_SCENE = os.path.join(REPO, "csm_engine", "data", "scenes", "default.json")


def _lit_plane(scene):
    """A 4 m grey plane under a 45-degree sun, seen from above by the scene camera."""
    mesh = bpy.data.meshes.new("Plane")
    mesh.from_pydata([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [], [(0, 1, 2, 3)])
    plane = bpy.data.objects.new("Plane", mesh)
    scene.collection.objects.link(plane)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    scene.collection.objects.link(sun)
    light_controls.set_sun_travel(sun, controls.travel_from_azimuth_elevation(0, 45))
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location = (0.0, 0.0, 6.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    bpy.context.view_layer.update()
    return plane, sun, camera


# ------------------------------------------------------------------------ registration
def test_operators_are_registered_with_tooltips_and_undo():
    for cls in operators.classes:
        assert cls.__doc__ and cls.__doc__.strip(), cls.__name__
        module, name = cls.bl_idname.split(".")
        assert hasattr(getattr(bpy.ops, module), name), cls.bl_idname
    changes_data = {"csm.import_scene", "csm.reload_scene", "csm.reset_sun_direction",
                    "csm.first_person"}
    for cls in operators.classes:
        if cls.bl_idname in changes_data:
            assert {'REGISTER', 'UNDO'} <= cls.bl_options, cls.bl_idname
    props = bpy.ops.csm.first_person.get_rna_type().properties
    assert "per second" in props["speed"].description
    props = bpy.ops.csm.screenshot.get_rna_type().properties
    assert "PNG" in props["filepath"].description


def test_light_properties_have_tooltips_with_units():
    for prop in light_controls.CSMLightControls.bl_rna.properties:
        if prop.identifier in ("rna_type", "name"):
            continue
        assert prop.description, prop.identifier
    props = light_controls.CSMLightControls.bl_rna.properties
    for name in ("sun_azimuth", "sun_elevation"):   # Blender's angles: shown in degrees
        assert (props[name].subtype, props[name].unit) == ('ANGLE', 'ROTATION'), name
    assert "metres per second" in props["fly_speed"].description
    assert props["fly_speed"].unit == 'VELOCITY'
    assert "per second" in props["fly_turn_speed"].description
    assert props["fly_turn_speed"].subtype == 'ANGLE'
    assert props["fly_turn_speed"].unit == 'ROTATION'


def _addon_items():
    km = bpy.context.window_manager.keyconfigs.addon.keymaps[keymap.KEYMAP_NAME]
    return km, {(ki.idname, ki.type, ki.ctrl, ki.shift) for ki in km.keymap_items}


def test_keymap_items_are_in_the_addon_keyconfig_and_unregister_removes_them():
    # pip bpy has window-manager keyconfigs, so this checks the real add-on keymap (the
    # one Preferences > Keymap lists), not just the data table.
    assert bpy.context.window_manager.keyconfigs.addon is not None
    km, items = _addon_items()
    assert km.space_type == 'VIEW_3D'
    expected = {("csm.reload_scene", 'R', True, False), ("csm.reload_shaders", 'F5', False, False),
                ("csm.first_person", 'F', False, True)}
    assert expected == set(keymap.ITEMS)
    assert expected <= items
    keymap.unregister()
    try:
        _km, items = _addon_items()
        assert not {item for item in items if item[0].startswith("csm.")}
    finally:
        keymap.register()
    assert expected <= _addon_items()[1]


def test_first_person_cannot_start_without_a_3d_view():
    assert hasattr(bpy.ops.csm, "first_person")
    assert not operators.CSM_OT_first_person.poll(bpy.context)
    assert not bpy.ops.csm.first_person.poll()


def test_automatic_speed_is_a_tenth_of_the_scene_diagonal_per_second(empty_scene):
    assert operators.scene_speed(empty_scene) == 1.0
    plane, _sun, _camera = _lit_plane(empty_scene)
    plane.scale = (2.0, 2.0, 1.0)
    bpy.context.view_layer.update()
    assert operators.scene_speed(empty_scene) == pytest.approx(math.hypot(8.0, 8.0) / 10.0)


# ------------------------------------------------------------------------ sun controls
def test_azimuth_elevation_and_vector_round_trip_through_the_sun(empty_scene):
    _plane, sun, _camera = _lit_plane(empty_scene)
    light = empty_scene.csm_light
    light.sun_azimuth, light.sun_elevation = math.radians(30.0), math.radians(40.0)
    assert (light.sun_azimuth, light.sun_elevation) == (pytest.approx(math.radians(30.0)),
                                                        pytest.approx(math.radians(40.0)))
    bpy.context.view_layer.update()
    travel = -np.array(sun.matrix_world)[:3, 2]
    towards = [math.cos(math.radians(40)) * math.cos(math.radians(30)),
               math.cos(math.radians(40)) * math.sin(math.radians(30)),
               math.sin(math.radians(40))]
    np.testing.assert_allclose(travel, -np.array(towards), atol=1e-6)
    np.testing.assert_allclose(light.sun_direction, travel, atol=1e-6)
    light.sun_direction = (0.0, 0.0, -2.0)           # straight down, not normalized
    assert light.sun_elevation == pytest.approx(math.pi / 2)
    light.sun_direction = (-1.0, 0.0, 0.0)           # travels to -X: sun in +X on horizon
    assert (light.sun_azimuth, light.sun_elevation) == (pytest.approx(0.0, abs=1e-5),
                                                        pytest.approx(0.0, abs=1e-5))
    sun.location = (5.0, 6.0, 7.0)
    light.sun_azimuth = math.radians(-135.0)
    assert light.sun_azimuth == pytest.approx(math.radians(-135.0))
    assert tuple(sun.location) == pytest.approx((5.0, 6.0, 7.0))   # only rotation changes


def test_rotating_the_sun_object_shows_in_the_controls(empty_scene):
    _plane, sun, _camera = _lit_plane(empty_scene)
    sun.rotation_mode = 'XYZ'
    sun.rotation_euler = (0.0, 0.0, 0.0)      # Blender's default sun shines straight down
    bpy.context.view_layer.update()
    assert empty_scene.csm_light.sun_elevation == pytest.approx(math.pi / 2)


def test_editing_the_sun_direction_changes_the_rendered_picture(empty_scene):
    _lit_plane(empty_scene)
    empty_scene.csm_light.sun_elevation = math.radians(80.0)
    bright = render_scene(empty_scene, 48, 32)["combined"][..., :3].mean()
    empty_scene.csm_light.sun_elevation = math.radians(15.0)
    grazing = render_scene(empty_scene, 48, 32)["combined"][..., :3].mean()
    assert grazing < bright * 0.6


def test_controls_without_a_sun_show_a_message_and_do_nothing(empty_scene):
    light = empty_scene.csm_light
    light.sun_azimuth = math.radians(45.0)
    assert tuple(light.sun_direction) == (0.0, 0.0, -1.0)
    assert not bpy.ops.csm.reset_sun_direction.poll()
    layout = RecordingLayout()
    ui.draw_light(layout, bpy.context)
    assert any("No Sun" in text for text in layout.labels)


@pytest.fixture
def default_copy(tmp_path):
    """default.json copied to a temp dir, its mesh path made absolute."""
    with open(DEFAULT_SCENE, encoding="utf-8") as handle:
        data = json.load(handle)
    mesh = data["objects"][0]["mesh"]
    data["objects"][0]["mesh"] = os.path.normpath(os.path.join(os.path.dirname(DEFAULT_SCENE),
                                                               mesh))
    path = tmp_path / "default.json"
    path.write_text(json.dumps(data, indent=2), encoding="utf-8")
    return path


def _sun_travel(scene):
    sun = light_controls.sun_object(scene)
    return np.array(light_controls.sun_travel(sun)), sun


def test_reset_to_scene_file_restores_the_imported_direction(empty_scene, default_copy):
    assert bpy.ops.csm.import_scene(filepath=str(default_copy)) == {'FINISHED'}
    file_travel = np.array(bpy.data.collections["default"]["csm_sun_direction"])
    travel, sun = _sun_travel(empty_scene)
    np.testing.assert_allclose(travel, file_travel / np.linalg.norm(file_travel), atol=1e-6)
    empty_scene.csm_light.sun_elevation = math.radians(10.0)
    assert not np.allclose(_sun_travel(empty_scene)[0], travel, atol=1e-3)
    assert bpy.ops.csm.reset_sun_direction() == {'FINISHED'}
    np.testing.assert_allclose(_sun_travel(empty_scene)[0], travel, atol=1e-6)
    bpy.ops.ed.undo_push(message="test")  # the reset is an ordinary, undoable data change


# ------------------------------------------------------------------------ Ctrl+R reload
def test_reload_keeps_the_scene_on_a_broken_file_and_resets_the_light_when_fixed(
        empty_scene, default_copy, monkeypatch):
    assert bpy.ops.csm.import_scene(filepath=str(default_copy)) == {'FINISHED'}
    light = empty_scene.csm_light
    light.sun_azimuth, light.sun_elevation = math.radians(120.0), math.radians(20.0)
    edited, sun = _sun_travel(empty_scene)
    objects_before = sorted(obj.name for obj in empty_scene.objects)

    good_text = default_copy.read_text(encoding="utf-8")
    default_copy.write_text(good_text.replace('"directional_light"', '"directional_light" ,,'),
                            encoding="utf-8")
    # bpy.ops turns an ERROR report into RuntimeError carrying the message.
    with pytest.raises(RuntimeError, match=r"Error: .*default\.json") as failure:
        bpy.ops.csm.reload_scene()
    assert "Traceback" not in str(failure.value)
    assert sorted(obj.name for obj in empty_scene.objects) == objects_before
    np.testing.assert_allclose(_sun_travel(empty_scene)[0], edited, atol=1e-9)

    data = json.loads(good_text)
    data["directional_light"]["direction"] = {"x": -0.5, "y": -1.0, "z": 0.2}
    default_copy.write_text(json.dumps(data), encoding="utf-8")
    assert bpy.ops.csm.reload_scene() == {'FINISHED'}
    collection = bpy.data.collections["default"]
    file_travel = np.array(collection["csm_sun_direction"])
    file_travel /= np.linalg.norm(file_travel)
    np.testing.assert_allclose(file_travel, np.array([-0.5, -0.2, -1.0]) / math.sqrt(1.29),
                               atol=1e-6)       # Y-up (x, y, z) -> Z-up (x, -z, y)
    travel, sun = _sun_travel(empty_scene)
    np.testing.assert_allclose(travel, file_travel, atol=1e-6)
    assert sorted(obj.name for obj in empty_scene.objects) == objects_before


# ------------------------------------------------------------------------ F5 shaders
def test_shader_reload_keeps_the_last_good_shaders_and_picks_up_the_fix(
        empty_scene, tmp_path, monkeypatch):
    _lit_plane(empty_scene)
    render_scene(empty_scene, 48, 32)       # makes sure a GPU context exists
    directory = tmp_path / "shaders"
    shutil.copytree(paths.shaders_dir(), directory)
    library = shaders.ShaderLibrary(directory=str(directory))
    monkeypatch.setattr(shaders, "LIBRARY", library)

    before = render_scene(empty_scene, 48, 32)["combined"]
    assert before[..., :3].max() > 0.2

    lighting = directory / "lighting_frag.glsl"
    good = lighting.read_text(encoding="utf-8")
    lines = good.splitlines()
    broken_line = len(lines) - 1         # inside main(), before its last statement
    lines.insert(broken_line - 1, "  float broken = ;")
    lighting.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(RuntimeError) as failure:    # bpy.ops raises on an ERROR report
        bpy.ops.csm.reload_shaders()
    message = str(failure.value)
    assert message.startswith("Error: ") and "keeping the previous shaders" in message
    # Every host names the line (3.4/4.2 through shader_diagnostics; see test_shader_errors).
    match = re.search(r"lighting_frag\.glsl:(\d+)", message)
    assert match and int(match.group(1)) == broken_line, message
    assert library.last_error and "lighting_frag.glsl" in library.last_error
    layout = RecordingLayout()
    ui.draw_scene(layout, bpy.context)          # the Scene panel shows the error
    assert any("lighting_frag.glsl" in text for text in layout.labels), layout.labels
    still = render_scene(empty_scene, 48, 32)["combined"]
    np.testing.assert_array_equal(still, before)        # old shaders keep running

    fixed = good.replace("out_color = vec4(color, 1.0);", "out_color = vec4(color * 0.5, 1.0);")
    assert fixed != good
    lighting.write_text(fixed, encoding="utf-8")
    generation = library.generation
    assert bpy.ops.csm.reload_shaders() == {'FINISHED'}
    assert library.last_error is None
    assert library.generation == generation + 1
    after = render_scene(empty_scene, 48, 32)["combined"]
    lit = before[..., :3].sum(axis=-1) > 0.2
    assert lit.any()
    np.testing.assert_allclose(after[..., :3][lit], before[..., :3][lit] * 0.5, atol=0.02)
    layout = RecordingLayout()
    ui.draw_scene(layout, bpy.context)
    assert not any("error" in text.lower() for text in layout.labels)


# ------------------------------------------------------------------------ screenshot
def test_screenshot_writes_a_lit_png_of_the_render_size(empty_scene, tmp_path):
    _lit_plane(empty_scene)
    empty_scene.render.resolution_x, empty_scene.render.resolution_y = 64, 40
    empty_scene.render.engine = "BLENDER_WORKBENCH"     # the screenshot still uses CSM
    path = tmp_path / "shots" / "view.png"
    assert bpy.ops.csm.screenshot(filepath=str(path)) == {'FINISHED'}
    assert empty_scene.render.engine == "BLENDER_WORKBENCH"
    with open(path, "rb") as handle:
        assert handle.read(8) == b"\x89PNG\r\n\x1a\n"
    rgb = load_png(path)[..., :3]
    assert rgb.shape[:2] == (40, 64)
    assert (rgb.max(axis=-1) > 0.3).mean() > 0.5       # the sunlit plane fills the view


def test_screenshot_default_path_is_next_to_the_blend_or_the_current_folder(
        empty_scene, tmp_path, monkeypatch):
    _lit_plane(empty_scene)
    empty_scene.render.resolution_x, empty_scene.render.resolution_y = 16, 16
    monkeypatch.chdir(tmp_path)
    assert bpy.ops.csm.screenshot() == {'FINISHED'}
    assert (tmp_path / "csm_screenshot.png").stat().st_size > 0


def test_screenshot_without_a_camera_reports_an_error(empty_scene, tmp_path):
    with pytest.raises(RuntimeError, match="no camera"):
        bpy.ops.csm.screenshot(filepath=str(tmp_path / "x.png"))
    assert not (tmp_path / "x.png").exists()


# ------------------------------------------------------------------------ panels
def test_light_and_scene_groups_are_in_both_panels(empty_scene):
    keys = [key for key, _label, _draw in ui.GROUPS]
    assert keys == ["cascades", "filtering", "bias", "occluders", "light", "antialiasing",
                    "debug", "scene"]
    for key in ("light", "scene"):
        for space in ("properties", "view_3d"):
            assert hasattr(bpy.types, f"CSM_PT_{space}_{key}"), (space, key)
    assert bpy.types.CSM_PT_view_3d_light.bl_category == "CSM"
    _lit_plane(empty_scene)
    layout = RecordingLayout()
    ui.draw_light(layout, bpy.context)
    assert {"sun_azimuth", "sun_elevation", "sun_direction"} <= set(layout.props)
    assert "csm.reset_sun_direction" in layout.operators
    layout = RecordingLayout()
    ui.draw_scene(layout, bpy.context)
    assert {"csm.import_scene", "csm.reload_scene", "csm.reload_shaders",
            "csm.screenshot", "csm.first_person"} <= set(layout.operators)
    for op in layout.operators:
        module, name = op.split(".")
        assert hasattr(getattr(bpy.ops, module), name), op


def test_compiler_logs_of_blender_3_4_4_2_and_5_name_the_glsl_file():
    """Each file owns a block of line numbers, so every log format maps back to file:line."""
    from csm_engine.render import shaders
    ids = {"lighting_frag.glsl": 1, "shadow_atlas.glsl": 2}
    mesa_34 = "0:20017(3): error: syntax error, unexpected ';'"
    # 3.4/4.2 print no location ("      | Error: syntax error"); shader_diagnostics
    # recompiles through raw GL and this is Mesa's line from there, stage-prefixed.
    driver_42 = "fragment: 10171(17): error: syntax error, unexpected ';'"
    blender_5 = "   |       | :20017:17: Error: syntax error, unexpected ';'"
    assert "shadow_atlas.glsl:17(3): error" in shaders._map_log(mesa_34, ids)
    assert "lighting_frag.glsl:171(17): error" in shaders._map_log(driver_42, ids)
    assert ":shadow_atlas.glsl:17:17: Error" in shaders._map_log(blender_5, ids)
    assert shaders._map_log("error at 0.12345 in 99999", ids) == "error at 0.12345 in 99999"


def test_object_panel_shows_the_shadow_terminator_offset_csm_reads(empty_scene):
    """Blender shows the Geometry Offset only for Cycles and EEVEE; CSM reads it, so its
    Object panel shows it, on the setting this Blender keeps (the Object in 5.0, the Cycles
    add-on's object.cycles before), and an edit there is what the render reads."""
    from csm_engine.blender import compat
    bpy.ops.mesh.primitive_uv_sphere_add()
    sphere = bpy.context.object
    panel = bpy.types.CSM_PT_object_shadow_terminator
    assert panel.poll(bpy.context)
    layout = RecordingLayout()
    ui.draw_shadow_terminator(layout, bpy.context)
    assert layout.props == ["shadow_terminator_geometry_offset"]
    owner = compat.terminator_offset_owner(sphere)
    assert owner == (sphere if bpy.app.version >= (5, 0, 0) else sphere.cycles)
    owner.shadow_terminator_geometry_offset = 0.35
    assert compat.terminator_geometry_offset(sphere) == pytest.approx(0.35)
    bpy.ops.object.light_add(type='SUN')
    assert not panel.poll(bpy.context)               # a light has no terminator
    empty_scene.render.engine = 'CYCLES'
    bpy.context.view_layer.objects.active = sphere
    assert not panel.poll(bpy.context)               # Cycles' own panel shows it there
