"""Registration as Blender users meet it: the engine, its settings and Blender's panels."""
import bpy

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
