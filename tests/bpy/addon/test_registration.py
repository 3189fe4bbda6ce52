"""Registration as Blender users meet it: the engine, its settings and Blender's panels."""
import bpy
import pytest

from csm_engine.blender import settings as blender_settings
from csm_engine.blender import snapshot, ui
from csm_engine.core import settings_model
from csm_engine.core.settings_model import SETTINGS, default_settings

STANDARD_PANELS = ("RENDER_PT_format", "RENDER_PT_output", "RENDER_PT_color_management",
                   "DATA_PT_lens", "DATA_PT_camera", "DATA_PT_EEVEE_light",
                   "EEVEE_WORLD_PT_surface", "WORLD_PT_context_world")


def test_engine_is_selectable_with_a_gpu_context():
    engines = {getattr(e, "bl_idname", None): e for e in bpy.types.RenderEngine.__subclasses__()}
    engine = engines["CSM"]
    assert engine.bl_label == "CSM" and engine.bl_use_gpu_context
    bpy.context.scene.render.engine = "CSM"
    assert bpy.context.scene.render.engine == "CSM"


def test_blenders_standard_panels_show_for_csm_and_irrelevant_ones_do_not():
    panels = {p.__name__: p for p in bpy.types.Panel.__subclasses__()}
    for name in STANDARD_PANELS:
        assert "CSM" in panels[name].COMPAT_ENGINES, name
    assert "CSM" not in panels["DATA_PT_lightprobe"].COMPAT_ENGINES


def _csm_properties():
    return {prop.identifier: prop for prop in bpy.context.scene.csm.bl_rna.properties
            if prop.identifier not in ("rna_type", "name")}


def test_every_blender_setting_is_the_models_setting():
    assert set(_csm_properties()) == {setting.identifier for setting in SETTINGS}
    # Blender lists them in the model's order (the CLI's --list-settings and the
    # snapshot's warnings follow it).
    assert list(_csm_properties()) == [setting.identifier for setting in SETTINGS]


@pytest.mark.parametrize("setting", SETTINGS, ids=lambda setting: setting.identifier)
def test_blender_property_matches_the_model(setting):
    prop = _csm_properties()[setting.identifier]
    assert prop.name == setting.name
    assert prop.description == setting.description
    assert prop.is_animatable
    kind = setting.kind
    rna_type = "FLOAT" if kind == settings_model.FLOAT_VECTOR else kind
    assert prop.type == rna_type
    if setting.is_number:
        assert prop.array_length == (setting.size or 0)
        default = list(prop.default_array) if setting.size else prop.default
        expected = list(setting.default) if setting.size else setting.default
        assert default == pytest.approx(expected, rel=1e-7)    # stored as float32
        assert (prop.hard_min, prop.hard_max) == pytest.approx(setting.hard_range, rel=1e-7)
        assert (prop.soft_min, prop.soft_max) == pytest.approx(setting.soft_range, rel=1e-7)
        # Blender folds a unit into the subtype it reports, so compare each where it shows.
        if setting.unit is not None:
            assert prop.unit == setting.unit
        else:
            assert prop.subtype == (setting.subtype or 'NONE')
    elif kind == settings_model.ENUM:
        assert prop.default == setting.default
        assert [(item.identifier, item.name, item.description) for item in prop.enum_items] \
            == [(item.identifier, item.label, item.description) for item in setting.items]
    else:
        assert prop.default == setting.default
    # Every edit asks the 3D Views to redraw (viewports do not notice property edits).
    annotation = blender_settings.CSMSettings.__annotations__[setting.identifier]
    assert annotation.keywords["update"] is blender_settings._redraw


def test_a_new_scene_snapshots_to_the_default_settings():
    assert snapshot.settings_snapshot(bpy.context.scene) == default_settings()


def test_every_settings_group_is_a_panel():
    labels = {label for _key, label, _draw in ui.GROUPS}
    assert {setting.group for setting in SETTINGS} <= labels


def test_settings_live_on_the_scene_with_course_defaults():
    csm = bpy.context.scene.csm
    assert (csm.cascade_count, csm.resolution, csm.equal_resolution) == (3, 2048, False)
    assert csm.split_scheme == "HYBRID" and csm.stabilize and csm.pcf_radius == 1
    for prop in csm.bl_rna.properties:
        if prop.identifier not in ("rna_type", "name"):
            assert prop.description, f"{prop.identifier} needs a tooltip"
    # Numbers say their unit or range; every tooltip says more than the label does.
    units = ("texel", "scene units", "degrees", "0 to 1", "fractions", "(1 to 4)",
             "multiplier", "0 = nearest", "per second", "(1 to 64)")
    for prop in list(csm.bl_rna.properties) + list(bpy.context.scene.csm_light.bl_rna.properties):
        if prop.identifier in ("rna_type", "name"):
            continue
        text = prop.description
        assert len(text) > 40, f"{prop.identifier}: tooltip too short: {text!r}"
        if prop.type in ('INT', 'FLOAT') and getattr(prop, "subtype", "") != 'DIRECTION':
            assert any(unit in text.lower() for unit in units), \
                f"{prop.identifier}: tooltip names no unit or range: {text!r}"
    csm.keyframe_insert("pcf_radius", frame=1)   # animatable like any property
    assert bpy.context.scene.animation_data.action is not None


def test_import_menu_entry_and_operators_exist():
    assert hasattr(bpy.ops.csm, "import_scene") and hasattr(bpy.ops.csm, "reload_scene")
    entries = [f.__module__ for f in bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()]
    assert any("csm_engine" in module for module in entries), entries
