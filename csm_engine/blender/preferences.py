"""The add-on's preferences (Edit > Preferences > Add-ons > CSM Engine): the Shader Folder
the GLSL is read from, the lines that show which folder is in use, and the Allowed Folders
a scene's files may be read from besides the scene's own folder.

Owns ``CSM_AddonPreferences``, reading its values (``addon_preferences``,
``chosen_shader_folder``, ``chosen_allowed_folders``) and telling the shader library where the user's folder is
(``register``). Blender files add-on preferences under the add-on's module name, which is
``csm_engine`` for the legacy add-on and for pip bpy but ``bl_ext.<repository>.csm_engine``
for an extension: it is taken from this package's own name, never written out.
"""

import os

import bpy
from bpy.props import StringProperty

from ..core import paths
from ..render import shaders
from . import compat

# The top package: "csm_engine", or "bl_ext.user_default.csm_engine" as an extension.
ADDON_MODULE = __package__.rpartition(".")[0]
# Characters of a folder path the panel shows (see draw_shader_folder).
SHOWN_PATH_CHARS = 24


def addon_preferences(context=None, create=False):
    """This add-on's preferences, or None where Blender holds none for it: pip bpy, whose
    ``register()`` is called directly rather than by enabling the add-on, and any host after
    reading factory settings. ``create`` adds the entry as enabling the add-on does."""
    context = context or bpy.context
    addons = context.preferences.addons
    addon = addons.get(ADDON_MODULE)
    if addon is None and create:
        addon = addons.new()
        addon.module = ADDON_MODULE
    return addon.preferences if addon is not None else None


def chosen_shader_folder(context=None):
    """The Shader Folder preference as an absolute, normalised path; "" when it is empty
    (the add-on's own shaders)."""
    try:
        preferences = addon_preferences(context)
    except AttributeError:        # a context without preferences (restricted at startup)
        return ""
    value = getattr(preferences, "shader_folder", "").strip()
    if not value:
        return ""
    return os.path.normpath(os.path.expanduser(bpy.path.abspath(value)))


def chosen_allowed_folders(context=None):
    """The Allowed Folders preference as a list of absolute, normalised paths (empty: only
    the scene's own folder tree)."""
    try:
        preferences = addon_preferences(context)
    except AttributeError:        # a context without preferences (restricted at startup)
        return []
    value = getattr(preferences, "allowed_folders", "")
    return [os.path.normpath(os.path.expanduser(bpy.path.abspath(part.strip())))
            for part in value.split(";") if part.strip()]


def _shader_folder_changed(self, context):
    # The panel's "Shaders:" line and the hint to press F5 follow the new value.
    window_manager = getattr(context, "window_manager", None)
    for window in getattr(window_manager, "windows", ()):
        for area in window.screen.areas:
            area.tag_redraw()


class CSM_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_MODULE

    shader_folder: StringProperty(
        name="Shader Folder",
        description="Folder the CSM shaders are read from when they first compile and when "
                    "F5 (Reload Shaders) reloads them, e.g. the shaders/ folder of your "
                    "checkout. It must hold lighting_frag.glsl and the rest of the GLSL "
                    "library. Empty: the add-on's own shaders",
        subtype='DIR_PATH',
        default="",
        update=_shader_folder_changed,
    )
    allowed_folders: StringProperty(
        name="Allowed Folders",
        description="Folders, separated by ';', that a scene's meshes, material libraries, "
                    "textures and glTF buffers may be read from besides the scene file's "
                    "own folder and each mesh file's folder. Empty: a scene reads nothing "
                    "outside its folder",
        default="",
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "shader_folder")
        folder = chosen_shader_folder(context)
        row = layout.row()
        if not folder:
            row.label(text=f"Empty: the add-on's own shaders ({paths.shaders_dir()})",
                      icon='INFO')
        else:
            problem = shaders.folder_problem(folder)
            if problem:
                row.label(text=f"Not usable: {problem}", icon='ERROR')
            else:
                row.label(text="F5 (Reload Shaders) in the 3D viewport reads this folder",
                          icon='INFO')
        draw_shader_folder(layout, context)
        layout.prop(self, "allowed_folders")


def draw_shader_folder(layout, context):
    """The panel lines for the folder in use: where the running shaders come from (the
    add-on's own, or the Shader Folder shortened to fit), the button that opens it, and a
    hint when the preference names another folder than the one in use (unless the last
    reload failed: the panel shows that error instead)."""
    library = shaders.LIBRARY
    in_use = library.folder_in_use
    col = layout.column(align=True)
    if in_use == library.own_folder:
        row = col.row(align=True)
        row.label(text="Shaders: add-on's own", icon='FILE_FOLDER')
    else:
        # Two lines: the sidebar's default width holds about 24 characters beside the
        # button.
        col.label(text="Shaders from:", icon='FILE_FOLDER')
        row = col.row(align=True)
        row.label(text=paths.display_path(in_use, max_chars=SHOWN_PATH_CHARS))
    row.operator("csm.open_shader_folder", text="", icon='FILEBROWSER')
    if library.folder != in_use and library.last_error is None:
        layout.label(text="Shader Folder set: F5 loads it", icon='INFO')


def register():
    bpy.utils.register_class(CSM_AddonPreferences)
    # pip bpy registers without enabling: give the preferences the entry enabling makes.
    addon_preferences(create=True)
    shaders.LIBRARY.preferred_folder = chosen_shader_folder
    shaders.LIBRARY.host_defines = (("PRINCIPLED_V1", "1"),) if compat.PRINCIPLED_V1 else ()


def unregister():
    shaders.LIBRARY.preferred_folder = None
    bpy.utils.unregister_class(CSM_AddonPreferences)
