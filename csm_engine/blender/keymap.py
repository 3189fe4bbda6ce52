"""Add-on keymap: the CSM shortcuts in the 3D View, shown in Preferences > Keymap.

Owns the list of shortcuts (``ITEMS``) and their registration in the add-on keyconfig;
``unregister()`` removes exactly the items ``register()`` added. Known overlaps: Ctrl+R is
Loop Cut in mesh Edit Mode (the mode keymap wins there, so reload works in Object Mode).
"""

import bpy

# (operator idname, key, ctrl, shift): 3D View shortcuts.
ITEMS = (
    ("csm.reload_scene", 'R', True, False),      # Ctrl+R: reload scene, light back to file
    ("csm.reload_shaders", 'F5', False, False),  # F5: recompile shaders/ from disk
    ("csm.first_person", 'F', False, True),      # Shift+F: first-person camera
)

KEYMAP_NAME = "3D View"

# (keymap, keymap item) pairs this add-on created, removed again in unregister().
_added = []


def register():
    keyconfig = bpy.context.window_manager.keyconfigs.addon
    if keyconfig is None:   # Blender started without window-manager keyconfigs
        return
    km = keyconfig.keymaps.new(name=KEYMAP_NAME, space_type='VIEW_3D')
    for idname, key, ctrl, shift in ITEMS:
        item = km.keymap_items.new(idname, key, 'PRESS', ctrl=ctrl, shift=shift)
        _added.append((km, item))


def unregister():
    for km, item in reversed(_added):
        try:
            km.keymap_items.remove(item)
        except (ReferenceError, RuntimeError):
            pass    # already gone with its keyconfig (Blender shutting down)
    _added.clear()
