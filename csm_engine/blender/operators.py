"""Operators: import/reload scene files, reload shaders, reset the sun, screenshot, and the
first-person camera; plus the File > Import menu entry.

Owns the user-facing commands. Errors are shown as one-line operator reports and the
operator returns ``{'CANCELLED'}``; a traceback never reaches the user, and a failed
import or reload leaves the scene untouched (the builder guarantees it).

The first-person movement is plain numpy math (``step``, ``turn``) on a world_from_camera
4x4 matrix (camera looks down its local -Z, local +Y is up), so it is testable without a
window; the modal operator only feeds it key states and mouse motion.
"""

import contextlib
import os
import time

import bpy
import numpy as np
from bpy.props import FloatProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper
from mathutils import Matrix

from ..core.controls import mouse_turn, step, turn
from . import light_controls, scene_builder
from .settings import tag_3d_views_for_redraw


@contextlib.contextmanager
def keeping_render_engines():
    """Put back every scene's render engine after an import: Blender 3.4's glTF importer
    switches the current scene to Eevee unless it renders with Cycles or Eevee, so
    importing or reloading (Ctrl+R) a glTF scene would silently leave the CSM engine."""
    engines = {scene.name_full: scene.render.engine for scene in bpy.data.scenes}
    try:
        yield
    finally:
        for scene in bpy.data.scenes:
            engine = engines.get(scene.name_full)
            if engine is not None and scene.render.engine != engine:
                scene.render.engine = engine


class CSM_OT_import_scene(bpy.types.Operator, ImportHelper):
    """Import a CSM/CS562 JSON scene (camera, sun, point lights and meshes)"""
    bl_idname = "csm.import_scene"
    bl_label = "Import CSM Scene"
    bl_options = {'REGISTER', 'UNDO'}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})

    def execute(self, context):
        try:
            with keeping_render_engines():
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
            with keeping_render_engines():
                collection = scene_builder.reload_scene(collection)
        except scene_builder.SceneImportError as err:
            self.report({'ERROR'}, str(err))
            return {'CANCELLED'}
        self.report({'INFO'}, f"Reloaded {collection.name} from {collection['csm_source']}")
        return {'FINISHED'}


class CSM_OT_reload_shaders(bpy.types.Operator):
    """Recompile all CSM shaders from the Shader Folder set in the add-on's preferences, or \
else the add-on's own shaders/. On a GLSL error, or a folder that lacks files, the last good \
shaders keep running and the error (file:line, or the missing files) is shown"""
    bl_idname = "csm.reload_shaders"
    bl_label = "Reload CSM Shaders"
    bl_options = {'REGISTER'}

    def execute(self, context):
        from ..render import shaders   # imports the gpu module: only when the user asks
        library = shaders.LIBRARY
        error = library.reload()
        tag_3d_views_for_redraw(context)   # also redraws the panel that shows the error
        if error is not None:
            # ShaderLibrary.reload already printed it to the console.
            self.report({'ERROR'}, f"{error} (keeping the previous shaders)")
            return {'CANCELLED'}
        # Where the files came from: the Shader Folder preference, or the add-on's own.
        self.report({'INFO'}, f"CSM shaders reloaded from {library.folder_in_use}")
        return {'FINISHED'}


class CSM_OT_open_shader_folder(bpy.types.Operator):
    """Open the folder the CSM shaders are read from in the system's file browser"""
    bl_idname = "csm.open_shader_folder"
    bl_label = "Open Shader Folder"
    bl_options = {'REGISTER'}

    @classmethod
    def description(cls, context, properties):
        from ..render import shaders
        return f"Open the folder the CSM shaders are read from ({shaders.LIBRARY.folder_in_use}) "\
               "in the system's file browser"

    def execute(self, context):
        from ..render import shaders
        folder = shaders.LIBRARY.folder_in_use
        if not os.path.isdir(folder):
            self.report({'ERROR'}, f"Shader folder {folder} does not exist")
            return {'CANCELLED'}
        # Blender's own operator knows each system's file browser (xdg-open, open, Explorer).
        return bpy.ops.wm.path_open(filepath=folder)


class CSM_OT_reset_sun_direction(bpy.types.Operator):
    """Turn the scene's Sun back to the direction given in its scene file"""
    bl_idname = "csm.reset_sun_direction"
    bl_label = "Reset to Scene File"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return context.scene is not None and light_controls.sun_object(context.scene) is not None

    def execute(self, context):
        sun = light_controls.sun_object(context.scene)
        direction = light_controls.file_sun_direction(sun)
        if direction is None:
            self.report({'ERROR'}, f"Sun '{sun.name}' was not imported from a CSM scene file")
            return {'CANCELLED'}
        light_controls.set_sun_travel(sun, direction)
        self.report({'INFO'}, f"Sun '{sun.name}' reset to the scene file's direction")
        return {'FINISHED'}


class CSM_OT_screenshot(bpy.types.Operator, ExportHelper):
    """Render the scene camera with CSM and save the picture as a PNG \
(size: Render > Format resolution)"""
    bl_idname = "csm.screenshot"
    bl_label = "CSM Screenshot"
    bl_options = {'REGISTER'}

    filename_ext = ".png"
    filter_glob: StringProperty(default="*.png", options={'HIDDEN'})
    filepath: StringProperty(
        name="File Path",
        description="PNG file to write; // means next to the .blend file (or the current "
                    "folder when the .blend is not saved)",
        default="//csm_screenshot.png", subtype='FILE_PATH')

    def invoke(self, context, event):
        if not self.filepath:
            self.filepath = "//csm_screenshot.png"
        self.filepath = bpy.path.abspath(self.filepath)
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        scene = context.scene
        if scene.camera is None:
            self.report({'ERROR'}, "The scene has no camera to take a screenshot from")
            return {'CANCELLED'}
        path = os.path.abspath(bpy.path.abspath(self.filepath))
        if not path.lower().endswith(".png"):
            path += ".png"
        render, image_settings = scene.render, scene.render.image_settings
        saved = (render.engine, image_settings.file_format)
        try:
            render.engine = "CSM"
            image_settings.file_format = 'PNG'
            from . import engine
            outcome = engine.render_final(scene)
            if outcome.error:
                self.report({'ERROR'}, f"CSM render failed: {outcome.error}")
                return {'CANCELLED'}
            result = bpy.data.images.get("Render Result")
            if result is None:
                self.report({'ERROR'}, "CSM render produced no image")
                return {'CANCELLED'}
            os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
            result.save_render(path, scene=scene)
        except (OSError, RuntimeError) as err:
            self.report({'ERROR'}, f"{path}: cannot save screenshot ({err})")
            return {'CANCELLED'}
        finally:
            render.engine, image_settings.file_format = saved
        self.report({'INFO'}, f"Saved CSM screenshot to {path}")
        return {'FINISHED'}


# ------------------------------------------------------------------ first-person camera
def scene_speed(scene):
    """Automatic first-person speed, scene units per second: bounds diagonal / 10."""
    corners = []
    for obj in scene.objects:
        if obj.type == 'MESH' and obj.visible_get():
            local = np.array([tuple(c) for c in obj.bound_box], dtype=np.float64)
            world = np.array(obj.matrix_world, dtype=np.float64)
            corners.append(local @ world[:3, :3].T + world[:3, 3])
    if not corners:
        return 1.0
    corners = np.concatenate(corners)
    diagonal = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
    return max(diagonal / 10.0, 1e-3)


_MOVE_KEYS = {'W': "W", 'A': "A", 'S': "S", 'D': "D", 'Q': "Q", 'E': "E"}
_ARROWS = {'LEFT_ARROW': (1.0, 0.0), 'RIGHT_ARROW': (-1.0, 0.0),
           'UP_ARROW': (0.0, 1.0), 'DOWN_ARROW': (0.0, -1.0)}


class CSM_OT_first_person(bpy.types.Operator):
    """First-person camera: W/S forward/back, A/D left/right, Q/E down/up, drag or arrow \
keys to look, mouse wheel for speed, Esc or right-click to leave. Moves the scene camera \
when looking through it, else the viewport"""
    bl_idname = "csm.first_person"
    bl_label = "CSM First-Person Camera"
    bl_options = {'REGISTER', 'UNDO', 'BLOCKING'}

    speed: FloatProperty(
        name="Speed",
        description="Movement speed in scene units (metres) per second; 0 = automatic "
                    "(scene size / 10 per second times the Fly Speed setting)",
        default=0.0, min=0.0, soft_max=1000.0, unit='VELOCITY')

    @classmethod
    def poll(cls, context):
        area = getattr(context, "area", None)
        return (area is not None and area.type == 'VIEW_3D'
                and getattr(context, "region_data", None) is not None)

    # -- where the view lives ---------------------------------------------------------
    def _through_camera(self, context):
        return self._rv3d.view_perspective == 'CAMERA' and context.scene.camera is not None

    def _get_matrix(self, context):
        if self._through_camera(context):
            return np.array(context.scene.camera.matrix_world, dtype=np.float64)
        return np.linalg.inv(np.array(self._rv3d.view_matrix, dtype=np.float64))

    def _set_matrix(self, context, matrix):
        if self._through_camera(context):
            context.scene.camera.matrix_world = Matrix(matrix.tolist())
            return
        rv3d = self._rv3d
        rotation = Matrix(matrix[:3, :3].tolist()).normalized().to_quaternion()
        # The viewport orbits view_location at view_distance; the eye sits behind it.
        eye = matrix[:3, 3]
        back = matrix[:3, 2] / np.linalg.norm(matrix[:3, 2])
        rv3d.view_rotation = rotation
        rv3d.view_location = tuple(eye - back * rv3d.view_distance)

    def _header(self, context):
        speed = self._speed(context)
        context.area.header_text_set(
            f"CSM first person: W/S A/D Q/E move, drag/arrows look, wheel speed "
            f"({speed:.3g} m/s), Esc/right-click exit")

    def _speed(self, context):
        if self.speed > 0.0:
            return self.speed
        return self._auto_speed * context.scene.csm_light.fly_speed_factor

    # -- modal ------------------------------------------------------------------------
    def invoke(self, context, event):
        self._rv3d = context.region_data
        if self._rv3d.view_perspective == 'ORTHO':
            self._rv3d.view_perspective = 'PERSP'   # first person needs a perspective eye
        self._auto_speed = scene_speed(context.scene)
        self._held = set()
        self._arrows = set()
        self._drag_from = None
        self._last_time = time.perf_counter()
        self._timer = context.window_manager.event_timer_add(1.0 / 60.0, window=context.window)
        context.window_manager.modal_handler_add(self)
        self._header(context)
        return {'RUNNING_MODAL'}

    def _finish(self, context):
        context.window_manager.event_timer_remove(self._timer)
        context.area.header_text_set(None)
        context.area.tag_redraw()

    def modal(self, context, event):
        if event.type == 'ESC' or (event.type == 'RIGHTMOUSE' and event.value == 'PRESS'):
            self._finish(context)
            return {'FINISHED'}
        if event.type in _MOVE_KEYS:
            if event.value == 'PRESS':
                self._held.add(_MOVE_KEYS[event.type])
            elif event.value == 'RELEASE':
                self._held.discard(_MOVE_KEYS[event.type])
            return {'RUNNING_MODAL'}
        if event.type in _ARROWS:
            if event.value == 'PRESS':
                self._arrows.add(event.type)
            elif event.value == 'RELEASE':
                self._arrows.discard(event.type)
            return {'RUNNING_MODAL'}
        if event.type in {'WHEELUPMOUSE', 'WHEELDOWNMOUSE'}:
            light = context.scene.csm_light
            factor = 1.25 if event.type == 'WHEELUPMOUSE' else 0.8
            if self.speed > 0.0:
                self.speed *= factor
            else:
                light.fly_speed_factor = min(max(light.fly_speed_factor * factor, 0.01), 100.0)
            self._header(context)
            return {'RUNNING_MODAL'}
        if event.type == 'LEFTMOUSE':
            # Blender also sends CLICK_DRAG once the mouse moves; only PRESS/RELEASE count.
            if event.value == 'PRESS':
                self._drag_from = (event.mouse_x, event.mouse_y)
            elif event.value == 'RELEASE':
                self._drag_from = None
            return {'RUNNING_MODAL'}
        if event.type == 'MOUSEMOVE' and self._drag_from is not None:
            dx = event.mouse_x - self._drag_from[0]
            dy = event.mouse_y - self._drag_from[1]
            self._drag_from = (event.mouse_x, event.mouse_y)
            matrix = turn(self._get_matrix(context), *mouse_turn(dx, dy))
            self._set_matrix(context, matrix)
            context.area.tag_redraw()
            return {'RUNNING_MODAL'}
        if event.type == 'TIMER':
            now = time.perf_counter()
            # A long stall (a slow render) must not throw the camera across the scene, but a
            # slow software-GL viewport (several frames per second) still moves in real time.
            dt = min(now - self._last_time, 0.5)
            self._last_time = now
            if self._held or self._arrows:
                matrix = self._get_matrix(context)
                rate = context.scene.csm_light.fly_turn_speed * dt
                yaw = sum(_ARROWS[key][0] for key in self._arrows) * rate
                pitch = sum(_ARROWS[key][1] for key in self._arrows) * rate
                if yaw or pitch:
                    matrix = turn(matrix, yaw, pitch)
                matrix = step(matrix, self._held, dt, self._speed(context))
                self._set_matrix(context, matrix)
                context.area.tag_redraw()
            return {'RUNNING_MODAL'}
        return {'PASS_THROUGH'}


def menu_import(self, context):
    self.layout.operator(CSM_OT_import_scene.bl_idname, text="CSM Scene (.json)")


classes = (
    CSM_OT_import_scene,
    CSM_OT_reload_scene,
    CSM_OT_reload_shaders,
    CSM_OT_open_shader_folder,
    CSM_OT_reset_sun_direction,
    CSM_OT_screenshot,
    CSM_OT_first_person,
)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
