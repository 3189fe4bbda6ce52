"""The CSM render settings stored on each scene (``Scene.csm``).

Owns the ``CSMSettings`` PropertyGroup: every user-facing knob of the engine, saved with the
.blend file and animatable like any Blender property. What each knob is (label, default,
range, unit, tooltip, enum items) is described once in ``core/settings_model.py``; this
module only turns that description into Blender properties that ask the 3D Views to redraw
when edited.

Nothing here touches the GPU. ``snapshot.py`` copies these values into a
``settings_model.Settings`` once per frame, so the pipeline never reads ``bpy`` properties
while drawing.
"""

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty)

from ..core import settings_model
from ..core.settings_model import SETTINGS

# Each enum setting's items as EnumProperty takes them: (identifier, label, tooltip).
ENUM_ITEMS = {setting.identifier: tuple((item.identifier, item.label, item.description)
                                        for item in setting.items)
              for setting in SETTINGS if setting.kind == settings_model.ENUM}


def tag_3d_views_for_redraw(context):
    """Ask every 3D View to draw again (viewports do not notice PropertyGroup edits, shader
    reloads or sun edits by themselves)."""
    window_manager = getattr(context, "window_manager", None) if context else None
    for window in (window_manager.windows if window_manager is not None else ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def _redraw(self, context):
    tag_3d_views_for_redraw(context)


_PROPERTY_TYPES = {
    settings_model.BOOLEAN: BoolProperty,
    settings_model.INT: IntProperty,
    settings_model.FLOAT: FloatProperty,
    settings_model.FLOAT_VECTOR: FloatVectorProperty,
    settings_model.ENUM: EnumProperty,
}


def blender_property(setting):
    """The bpy.props definition of one model setting. Only the limits, subtype and unit the
    model names are passed, so Blender's own defaults apply to the rest exactly as they
    would in a hand-written property (files saved before keep their values)."""
    keywords = {"name": setting.name, "description": setting.description,
                "default": setting.default, "update": _redraw}
    if setting.kind == settings_model.FLOAT_VECTOR:
        keywords["size"] = setting.size
    if setting.kind == settings_model.ENUM:
        keywords["items"] = ENUM_ITEMS[setting.identifier]
    for key in ("min", "max", "soft_min", "soft_max", "subtype", "unit"):
        value = getattr(setting, key)
        if value is not None:
            keywords[key] = value
    return _PROPERTY_TYPES[setting.kind](**keywords)


class CSMSettings(bpy.types.PropertyGroup):
    # Built from the model: Blender registers a PropertyGroup's properties from its
    # annotations, whether written by hand or made here.
    __annotations__ = {setting.identifier: blender_property(setting) for setting in SETTINGS}


classes = (CSMSettings,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.csm = PointerProperty(type=CSMSettings)


def unregister():
    del bpy.types.Scene.csm
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
