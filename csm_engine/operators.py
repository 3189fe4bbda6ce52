"""Operators: import and reload CSM scene files, and the File > Import menu entry.

Owns the user-facing commands around ``scene_builder``. Errors are shown as one-line
operator reports and the operator returns ``{'CANCELLED'}``; a traceback never reaches
the user, and a failed import leaves the scene untouched (the builder guarantees it).
"""

import bpy
from bpy.props import StringProperty
from bpy_extras.io_utils import ImportHelper

from . import scene_builder


class CSM_OT_import_scene(bpy.types.Operator, ImportHelper):
    """Import a CSM/CS562 JSON scene (camera, sun, point lights and meshes)"""
    bl_idname = "csm.import_scene"
    bl_label = "Import CSM Scene"
    bl_options = {'REGISTER', 'UNDO'}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})

    def execute(self, context):
        try:
            collection = scene_builder.import_scene_file(self.filepath, context.scene)
        except scene_builder.SceneImportError as err:
            self.report({'ERROR'}, str(err))
            return {'CANCELLED'}
        self.report({'INFO'}, f"Imported {collection.name} from {self.filepath}")
        return {'FINISHED'}


def _collection_to_reload(context):
    imported = scene_builder.imported_collections(context.scene)
    active = context.active_object
    if active is not None:
        # The newest import wins if the object was copied into several imports.
        for collection in reversed(imported):
            if active.name in collection.all_objects:
                return collection
    return imported[-1] if imported else None


class CSM_OT_reload_scene(bpy.types.Operator):
    """Import the scene file again, replacing the collection that holds the active \
object (or the most recent import)"""
    bl_idname = "csm.reload_scene"
    bl_label = "Reload CSM Scene"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        collection = _collection_to_reload(context)
        if collection is None:
            self.report({'ERROR'}, "No imported CSM scene to reload in this scene")
            return {'CANCELLED'}
        try:
            collection = scene_builder.reload_scene(collection)
        except scene_builder.SceneImportError as err:
            self.report({'ERROR'}, str(err))
            return {'CANCELLED'}
        self.report({'INFO'}, f"Reloaded {collection.name} from {collection['csm_source']}")
        return {'FINISHED'}


def menu_import(self, context):
    self.layout.operator(CSM_OT_import_scene.bl_idname, text="CSM Scene (.json)")


classes = (
    CSM_OT_import_scene,
    CSM_OT_reload_scene,
)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
