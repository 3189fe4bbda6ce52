"""CSM presets through Blender's own preset mechanism, as Blender's render presets.

Owns ``CSM_MT_presets`` (the menu in the header of the first CSM panel, in Properties >
Render and in the 3D View sidebar: pick a preset, ``script.execute_preset`` runs it),
``CSM_OT_preset_add`` (``AddPresetBase``: the menu's + and - buttons; a preset saves
``settings_model.PRESET_IDENTIFIERS``, the method and quality knobs, not the debug views or
the scene's own lighting) and where presets are found.

Two places: the presets shipped with the add-on (``csm_engine/presets/csm/*.py``, read in
place and never removed from the menu) and the user's own, which ``AddPresetBase`` writes to
Blender's user preset folder ``scripts/presets/csm`` (listed by ``bpy.utils.preset_paths``).
The shipped ones are read in place rather than copied into the user's folder on register:
nothing is written into the user's configuration, a user who deletes a copy does not get it
back on the next start, and an updated add-on's presets are the ones listed. Blender's
``Menu.draw_preset`` only lists ``bpy.utils.preset_paths`` (and ``register_preset_path``,
which would make the add-on's folder one of them, does not exist in Blender 3.4), so the
menu draws both lists itself, the way ``Menu.path_menu`` does.
"""

import os

import bpy
from bl_operators.presets import AddPresetBase

from ..core.settings_model import PRESET_IDENTIFIERS

# The user's presets: Blender's scripts/presets/<this>.
PRESET_SUBDIR = "csm"
# The presets the add-on ships, inside the package.
SHIPPED_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                           "presets", PRESET_SUBDIR)
EXTENSION = ".py"


def preset_files(folders):
    """Preset files in ``folders``, sorted by their menu name (numbers in natural order)."""
    import re
    found = []
    for folder in folders:
        if os.path.isdir(folder):
            found += [os.path.join(folder, name) for name in os.listdir(folder)
                      if name.endswith(EXTENSION) and not name.startswith(".")]
    return sorted(found, key=lambda path: tuple(
        int(part) if part.isdigit() else part
        for part in re.split(r"(\d+)", display_name(path).lower())))


def display_name(path):
    """A preset's name in the menu: its file name without extension, '_' as spaces."""
    return bpy.path.display_name(os.path.basename(path), title_case=False)


def shipped_presets():
    return preset_files([SHIPPED_DIR])


def user_presets():
    shipped = os.path.realpath(SHIPPED_DIR)
    return preset_files([folder for folder in bpy.utils.preset_paths(PRESET_SUBDIR)
                         if os.path.realpath(folder) != shipped])


class CSM_MT_presets(bpy.types.Menu):
    """The CSM preset menu: its label is the last preset applied"""
    bl_label = "Presets"
    preset_subdir = PRESET_SUBDIR
    preset_operator = "script.execute_preset"
    preset_add_operator = "csm.preset_add"

    def draw(self, context):
        layout = self.layout
        col = layout.column(align=True)
        user = user_presets()
        for path in shipped_presets() + user:
            row = col.row(align=True)
            props = row.operator(self.preset_operator, text=display_name(path))
            props.filepath = path
            props.menu_idname = self.bl_idname
            if path in user:
                props = row.operator(self.preset_add_operator, text="", icon='REMOVE')
                props.name = display_name(path)
                props.remove_name = True
        layout.separator()
        window_manager = context.window_manager
        row = layout.row()
        row.prop(window_manager, "preset_name", text="")
        props = row.operator(self.preset_add_operator, text="", icon='ADD')
        props.name = window_manager.preset_name


class CSM_OT_preset_add(AddPresetBase, bpy.types.Operator):
    """Add or remove a CSM preset: the CSM render settings (not the debug views, Ambient or Falloff)"""
    bl_idname = "csm.preset_add"
    bl_label = "Add CSM Preset"
    preset_menu = "CSM_MT_presets"
    preset_subdir = PRESET_SUBDIR
    preset_defines = ["csm = bpy.context.scene.csm"]
    preset_values = [f"csm.{identifier}" for identifier in PRESET_IDENTIFIERS]

    def execute(self, context):
        adding = not (self.remove_name or self.remove_active)
        if adding:
            # A user preset named as a shipped one would show twice and could never be told
            # apart in the menu.
            filename = self.as_filename(self.name.strip())
            shipped = {os.path.splitext(os.path.basename(path))[0].lower()
                       for path in shipped_presets()}
            if filename.lower() in shipped:
                self.report({'WARNING'}, f'"{self.name}" is a preset that comes with CSM: '
                                         f'choose another name')
                return {'CANCELLED'}
        return AddPresetBase.execute(self, context)


def draw_menu(layout, named=True):
    """The preset menu as a panel header shows it: the last preset applied (or "Presets"),
    or only the presets icon where a name would cover the panel's title."""
    layout.menu(CSM_MT_presets.__name__, text=CSM_MT_presets.bl_label if named else "",
                icon='PRESET')


classes = (CSM_MT_presets, CSM_OT_preset_add)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
