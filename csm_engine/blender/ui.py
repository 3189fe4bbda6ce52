"""Panels: the CSM settings in Properties > Render and in the 3D View sidebar ("CSM" tab),
and the per-object setting CSM reads in Properties > Object.

Owns layout only. Both places draw the same groups through ``draw_*`` functions, so a
setting appears identically wherever the user looks for it; a setting that does not change
the picture under the others is greyed out (``settings_model.is_active``; its tooltip says
why). The first panel's header holds the preset menu (presets.py). Properties > Object >
"Shadow Terminator" shows Blender's own Geometry Offset, which Blender shows only for
Cycles and EEVEE. "Light" edits the sun (``Scene.csm_light``, see light_controls.py) and the
ambient term; "Scene" holds the import/reload/shader-reload/screenshot/first-person
commands and the last shader error.
"""

import bpy

from ..core import settings_model
from ..core.settings_model import BY_IDENTIFIER
from . import preferences, presets


def _prop(layout, csm, identifier, **keywords):
    """One setting, greyed out where it does not change the picture under the other
    settings (its tooltip ends with the reason: ``settings_model``)."""
    sub = layout.column()
    sub.active = settings_model.is_active(BY_IDENTIFIER[identifier], csm)
    sub.prop(csm, identifier, **keywords)


def _manual_splits(layout, csm):
    """The splits the cascades use (Cascades - 1) in one labelled row: a property-split
    row would give each field a label column of its own."""
    setting = BY_IDENTIFIER["manual_splits"]
    split = layout.split(factor=0.4)
    split.active = settings_model.is_active(setting, csm)
    label = split.row()
    label.alignment = 'RIGHT'
    label.label(text=setting.name)
    right = split.row()
    row = right.row(align=True)
    row.use_property_split = False
    for i in range(max(csm.cascade_count - 1, 1)):
        row.prop(csm, "manual_splits", index=i, text="")
    if layout.use_property_decorate:
        right.label(text="", icon='BLANK1')   # the keyframe dots' column


def draw_cascades(layout, csm):
    col = layout.column()
    col.prop(csm, "cascade_count")
    col.prop(csm, "resolution")
    _prop(col, csm, "equal_resolution")
    _prop(col, csm, "split_scheme")
    # Both weights show, so the one Fit to View switches to is there to find.
    _prop(col, csm, "split_lambda")
    _prop(col, csm, "fitted_split_lambda")
    _manual_splits(col, csm)
    col.prop(csm, "fit_to_visible")
    col.prop(csm, "shadow_distance")
    col.prop(csm, "stabilize")
    row = col.row(align=True, heading=BY_IDENTIFIER["fade_out"].name)
    row.prop(csm, "fade_out", text="")
    sub = row.row(align=True)
    sub.active = settings_model.is_active(BY_IDENTIFIER["fade_fraction"], csm)
    sub.prop(csm, "fade_fraction", text="")
    _prop(col, csm, "cascade_selection")
    _prop(col, csm, "blend_band")


def draw_filtering(layout, csm):
    col = layout.column()
    col.prop(csm, "shadow_filter")
    for identifier in ("pcf_radius", "pcf_sharpen", "pcf_pattern"):
        _prop(col, csm, identifier)


def draw_bias(layout, csm):
    col = layout.column()
    # Blender has no texel unit to show in the fields.
    col.label(text="In shadow-map texels")
    col.prop(csm, "depth_bias")
    col.prop(csm, "slope_bias")
    col.prop(csm, "normal_offset")
    col.prop(csm, "cull_front_faces")


def draw_occluders(layout, csm):
    col = layout.column()
    col.prop(csm, "occluder_margin_auto")
    _prop(col, csm, "occluder_margin")


def draw_antialiasing(layout, context):
    col = layout.column()
    col.prop(context.scene.csm, "render_samples")
    col.prop(context.scene.csm, "fxaa")
    col.prop(context.scene.render, "filter_size")


def draw_debug(layout, csm):
    col = layout.column()
    col.prop(csm, "debug_view")
    _prop(col, csm, "debug_shadow_map")
    col.prop(csm, "debug_inset")
    col.prop(csm, "freeze_cascades")


def draw_light(layout, context):
    from . import light_controls
    col = layout.column()
    sun = light_controls.sun_object(context.scene)
    if sun is None:
        col.label(text="No Sun light in this scene", icon='INFO')
    else:
        light = context.scene.csm_light
        col.label(text=f"Sun: {sun.name}", icon='LIGHT_SUN')
        col.prop(light, "sun_azimuth", text="Azimuth")
        col.prop(light, "sun_elevation", text="Elevation")
        col.prop(light, "sun_direction", text="Direction")
        col.operator("csm.reset_sun_direction", icon='FILE_REFRESH')
    col.separator()
    csm = context.scene.csm
    col.prop(csm, "ambient_strength")
    col.prop(csm, "ambient_occlusion")
    _prop(col, csm, "ao_distance")
    _prop(col, csm, "ao_strength")
    col.prop(csm, "light_falloff")
    col.prop(context.scene.render, "film_transparent")


def _wrapped(text, width=48):
    lines, line = [], ""
    for word in text.split():
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    return lines + ([line] if line else [])


def draw_scene(layout, context):
    col = layout.column(align=True)
    col.operator("csm.import_scene", text="Import Scene...", icon='IMPORT')
    col.operator("csm.reload_scene", text="Reload Scene (Ctrl R)", icon='FILE_REFRESH')
    col.operator("csm.reload_shaders", text="Reload Shaders (F5)", icon='SHADERFX')
    col.operator("csm.screenshot", text="Screenshot...", icon='RENDER_STILL')
    col.operator("csm.first_person", text="First Person (Shift F)", icon='VIEW_CAMERA')
    layout.prop(context.scene.csm_light, "fly_speed")
    layout.prop(context.scene.csm_light, "fly_turn_speed")
    preferences.draw_shader_folder(layout, context)
    error = shader_error()
    if error:
        box = layout.box()
        box.label(text="Shader error (previous shaders in use):", icon='ERROR')
        for line in _wrapped(error):
            box.label(text=line)


def shader_error():
    """The last shader reload error, without importing gpu when shaders never loaded."""
    import sys
    shaders = sys.modules.get(__package__.rpartition(".")[0] + ".render.shaders")
    return getattr(getattr(shaders, "LIBRARY", None), "last_error", None)


GROUPS = (
    ("cascades", "Cascades", lambda layout, context: draw_cascades(layout, context.scene.csm)),
    ("filtering", "Filtering", lambda layout, context: draw_filtering(layout, context.scene.csm)),
    ("bias", "Bias", lambda layout, context: draw_bias(layout, context.scene.csm)),
    ("occluders", "Occluders", lambda layout, context: draw_occluders(layout, context.scene.csm)),
    ("light", "Light", draw_light),
    ("antialiasing", "Anti-Aliasing", draw_antialiasing),
    ("debug", "Debug", lambda layout, context: draw_debug(layout, context.scene.csm)),
    ("scene", "Scene", draw_scene),
)


# The panel whose header holds the preset menu: the first, so the menu is where a preset
# is looked for, above everything it sets.
PRESET_PANEL = "cascades"


def _make_panel(space, region, context_name, key, label, draw_fn, category=None):
    def draw(self, context):
        # Must return None: Blender 3.4 reports any other return value on every redraw.
        self.layout.use_property_split = True
        # The sidebar is narrow: the keyframe dots' column would take the labels' room
        # (keyframes are still set with I or the context menu over a field).
        self.layout.use_property_decorate = space != 'VIEW_3D'
        draw_fn(self.layout, context)

    attrs = {
        "bl_idname": f"CSM_PT_{space.lower()}_{key}",
        "bl_label": label,
        "bl_space_type": space,
        "bl_region_type": region,
        "COMPAT_ENGINES": {"CSM"},
        "poll": classmethod(lambda cls, context: context.engine == "CSM"),
        "draw": draw,
    }
    if key == PRESET_PANEL:
        # The sidebar's header is too narrow for the title and a preset's name.
        named = space != 'VIEW_3D'
        attrs["draw_header_preset"] = \
            lambda self, context: presets.draw_menu(self.layout, named=named)
    if context_name:
        attrs["bl_context"] = context_name
    if category:
        attrs["bl_category"] = category
    return type(attrs["bl_idname"], (bpy.types.Panel,), attrs)


# Object types CSM draws as surfaces (their evaluated meshes), so they have a terminator.
SURFACE_TYPES = {'MESH', 'CURVE', 'SURFACE', 'META', 'FONT'}


def draw_shadow_terminator(layout, context):
    """Blender's per-object Shadow Terminator Geometry Offset, where this Blender keeps it
    (``compat.terminator_offset_owner``); CSM lifts the shadow lookup of smooth-shaded
    low-poly surfaces by it, as Cycles does (docs/soft-shadows.md)."""
    from . import compat
    obj = context.object
    owner = compat.terminator_offset_owner(obj)
    col = layout.column()
    if owner is None:
        col.label(text=f"Geometry Offset {compat.DEFAULT_TERMINATOR_OFFSET:g} (Blender's "
                       f"default): enable the Cycles add-on to change it", icon='INFO')
    else:
        col.prop(owner, "shadow_terminator_geometry_offset", text="Geometry Offset")


class CSM_PT_object_shadow_terminator(bpy.types.Panel):
    bl_idname = "CSM_PT_object_shadow_terminator"
    bl_label = "Shadow Terminator"
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "object"
    bl_options = {'DEFAULT_CLOSED'}
    COMPAT_ENGINES = {"CSM"}

    @classmethod
    def poll(cls, context):
        obj = context.object
        return context.engine == "CSM" and obj is not None and obj.type in SURFACE_TYPES

    def draw(self, context):
        self.layout.use_property_split = True
        draw_shadow_terminator(self.layout, context)


classes = tuple(
    [_make_panel('PROPERTIES', 'WINDOW', "render", key, label, fn)
     for key, label, fn in GROUPS] +
    [_make_panel('VIEW_3D', 'UI', None, key, label, fn, category="CSM")
     for key, label, fn in GROUPS] +
    [CSM_PT_object_shadow_terminator])


def register():
    presets.register()
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
    presets.unregister()
