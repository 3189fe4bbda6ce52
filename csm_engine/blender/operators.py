"""Operators: import/reload scene files, reload shaders, reset the sun, screenshot, and the
first-person camera; plus the File > Import entries (a scene file, or a sample scene that
ships with the add-on, by name).

Owns the user-facing commands. Errors are shown as one-line operator reports and the
operator returns ``{'CANCELLED'}``; a traceback never reaches the user, and a failed
import or reload leaves the scene untouched (the builder guarantees it).

The first-person movement is plain numpy math (``step``, ``turn``) on a world_from_camera
4x4 matrix (camera looks down its local -Z, local +Y is up), so it is testable without a
window; the modal operator only feeds it key states and mouse motion. Like Blender's Fly
mode, Esc or right-click cancels (the camera or view goes back to where it started) and a
left click or Enter keeps the new view.
"""

import contextlib
import math
import os
import time

import bpy
import numpy as np
from bpy.props import EnumProperty, FloatProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper
from mathutils import Matrix

from ..core import paths
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


IMPORT_MODES = (
    ('REPLACE', "Replace Current Scene",
     "Start the scene afresh, as File > New would, with only the imported scene: every "
     "object and collection of this scene goes (the startup Cube, Light and Camera, "
     "earlier imports, your own objects), and the sky replaces the World. Ctrl+Z brings "
     "them back. Settings, render options and other scenes stay"),
    ('ADD', "Add to Scene",
     "Keep what the scene has and add the import as a new collection; an earlier import "
     "of the same file is replaced"),
)


class CSM_OT_import_scene(bpy.types.Operator, ImportHelper):
    """Import a CSM/CS562 JSON scene (camera, sun, point lights and meshes). By default it \
replaces the current scene's contents, as File > New would (Ctrl+Z brings them back); \
"Add to Scene" keeps them"""
    bl_idname = "csm.import_scene"
    bl_label = "Import CSM Scene"
    bl_options = {'REGISTER', 'UNDO'}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})
    mode: EnumProperty(
        name="Import",
        description="What happens to the objects the scene already has",
        items=IMPORT_MODES, default='REPLACE')

    def draw(self, context):
        # Expanded, one choice a line: a drop-down cuts "Replace Current Scene" in the
        # file browser's narrow side panel.
        self.layout.column().prop(self, "mode", expand=True)

    def execute(self, context):
        replace = self.mode == 'REPLACE'
        try:
            with keeping_render_engines():
                collection = scene_builder.import_scene_file(self.filepath, context.scene,
                                                             replace=replace)
        except scene_builder.SceneImportError as err:
            self.report({'ERROR'}, str(err))
            return {'CANCELLED'}
        if replace:
            # A new scene has a new size: the next flight picks its automatic speed again.
            context.scene.csm_light.fly_speed = 0.0
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
    """Automatic first-person speed, metres per second: the diagonal of the visible
    meshes' bounds / 10, so a flight crosses any scene in about ten seconds."""
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
_CONFIRM_KEYS = {'RET', 'NUMPAD_ENTER'}
_CANCEL_KEYS = {'ESC', 'RIGHTMOUSE'}
# The object channels a flight may change, put back exactly (no matrix round trip) on cancel.
_CAMERA_CHANNELS = ("rotation_mode", "location", "rotation_euler", "rotation_quaternion",
                    "rotation_axis_angle", "scale")
_VIEW_CHANNELS = ("view_perspective", "view_location", "view_rotation", "view_distance")


def _copy(value):
    return value.copy() if hasattr(value, "copy") else value


def round_speed(speed):
    """A speed rounded to two significant digits, as a user would type it (55.3 -> 55)."""
    return float(f"{speed:.2g}")


class CSM_OT_first_person(bpy.types.Operator):
    """First-person camera, like Blender's Fly mode: W/S forward/back, A/D left/right, \
Q/E down/up, drag or arrow keys to look, mouse wheel for speed; left click or Enter keeps \
the new view, Esc or right-click puts the camera back. Moves the scene camera when \
looking through it, else the viewport"""
    bl_idname = "csm.first_person"
    bl_label = "CSM First-Person Camera"
    bl_options = {'REGISTER', 'UNDO', 'BLOCKING'}

    speed: FloatProperty(
        name="Speed",
        description="Movement speed in metres per second; 0 = the scene's Fly Speed "
                    "(CSM Scene panel)",
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

    def _remember_start(self, context):
        """What cancelling puts back: the scene camera's transform channels and the view."""
        camera = context.scene.camera
        self._camera_start = None
        if camera is not None:
            self._camera_start = (camera, {name: _copy(getattr(camera, name))
                                           for name in _CAMERA_CHANNELS})
        self._view_start = {name: _copy(getattr(self._rv3d, name)) for name in _VIEW_CHANNELS}

    def _restore_start(self, context):
        if self._camera_start is not None:
            camera, channels = self._camera_start
            for name in _CAMERA_CHANNELS:   # rotation_mode first: it converts the others
                setattr(camera, name, channels[name])
        for name in _VIEW_CHANNELS:
            setattr(self._rv3d, name, self._view_start[name])

    def _header(self, context):
        context.area.header_text_set(
            f"CSM first person: W/S A/D Q/E move, drag or arrows look, "
            f"wheel speed {self._speed(context):.3g} m/s, click/Enter confirm, "
            f"Esc/right-click cancel")

    def _speed(self, context):
        """Metres per second: the operator's own speed, else the scene's Fly Speed."""
        if self.speed > 0.0:
            return self.speed
        return context.scene.csm_light.fly_speed

    def _change_speed(self, context, factor):
        if self.speed > 0.0:
            self.speed *= factor
            return
        light = context.scene.csm_light
        light.fly_speed = min(max(light.fly_speed * factor, 1e-3), 1e5)

    # -- modal ------------------------------------------------------------------------
    def invoke(self, context, event):
        self._rv3d = context.region_data
        self._remember_start(context)
        if self._rv3d.view_perspective == 'ORTHO':
            self._rv3d.view_perspective = 'PERSP'   # first person needs a perspective eye
        light = context.scene.csm_light
        if self.speed <= 0.0 and light.fly_speed <= 0.0:
            light.fly_speed = round_speed(scene_speed(context.scene))
        self._held = set()
        self._arrows = set()
        self._drag_from = None      # where the left button went down (then the last point)
        self._dragged = False       # it moved past the drag threshold: a look, not a click
        self._last_time = time.perf_counter()
        self._timer = context.window_manager.event_timer_add(1.0 / 60.0, window=context.window)
        context.window_manager.modal_handler_add(self)
        self._header(context)
        return {'RUNNING_MODAL'}

    def _finish(self, context):
        context.window_manager.event_timer_remove(self._timer)
        context.area.header_text_set(None)
        context.area.tag_redraw()

    def _confirm(self, context):
        self._finish(context)
        return {'FINISHED'}

    def _cancel(self, context):
        self._restore_start(context)
        self._finish(context)
        return {'CANCELLED'}

    def _drag_threshold(self):
        inputs = getattr(bpy.context.preferences, "inputs", None)
        return getattr(inputs, "drag_threshold_mouse", 3)

    def _left_button(self, context, event):
        # A click (press and release without moving) confirms, as in Fly mode; a drag looks.
        # A quick second press comes as DOUBLE_CLICK; Blender also sends CLICK and
        # CLICK_DRAG, which the PRESS/RELEASE pair already covers.
        if event.value in {'PRESS', 'DOUBLE_CLICK'}:
            self._drag_from = (event.mouse_x, event.mouse_y)
            self._dragged = False
        elif event.value == 'RELEASE' and self._drag_from is not None:
            clicked = not self._dragged
            self._drag_from = None
            if clicked:
                return self._confirm(context)
        return {'RUNNING_MODAL'}

    def _look(self, context, event):
        x, y = event.mouse_x, event.mouse_y
        if not self._dragged:
            threshold = self._drag_threshold()
            if max(abs(x - self._drag_from[0]), abs(y - self._drag_from[1])) <= threshold:
                return {'RUNNING_MODAL'}
            self._dragged = True
        dx, dy = x - self._drag_from[0], y - self._drag_from[1]
        self._drag_from = (x, y)
        self._set_matrix(context, turn(self._get_matrix(context), *mouse_turn(dx, dy)))
        context.area.tag_redraw()
        return {'RUNNING_MODAL'}

    def _fly(self, context):
        now = time.perf_counter()
        # A long stall (a slow render) must not throw the camera across the scene, but a
        # slow software-GL viewport (several frames per second) still moves in real time.
        dt = min(now - self._last_time, 0.5)
        self._last_time = now
        if self._held or self._arrows:
            matrix = self._get_matrix(context)
            rate = math.degrees(context.scene.csm_light.fly_turn_speed) * dt
            yaw = sum(_ARROWS[key][0] for key in self._arrows) * rate
            pitch = sum(_ARROWS[key][1] for key in self._arrows) * rate
            if yaw or pitch:
                matrix = turn(matrix, yaw, pitch)
            matrix = step(matrix, self._held, dt, self._speed(context))
            self._set_matrix(context, matrix)
            context.area.tag_redraw()
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        kind, value = event.type, event.value
        if kind in _CANCEL_KEYS and value == 'PRESS':
            return self._cancel(context)
        if kind in _CONFIRM_KEYS and value == 'PRESS':
            return self._confirm(context)
        if kind in _MOVE_KEYS or kind in _ARROWS:
            keys, key = ((self._held, _MOVE_KEYS[kind]) if kind in _MOVE_KEYS
                         else (self._arrows, kind))
            if value == 'PRESS':
                keys.add(key)
            elif value == 'RELEASE':
                keys.discard(key)
            return {'RUNNING_MODAL'}
        if kind in {'WHEELUPMOUSE', 'WHEELDOWNMOUSE'}:
            self._change_speed(context, 1.25 if kind == 'WHEELUPMOUSE' else 0.8)
            self._header(context)
            return {'RUNNING_MODAL'}
        if kind == 'LEFTMOUSE':
            return self._left_button(context, event)
        if kind == 'MOUSEMOVE' and self._drag_from is not None:
            return self._look(context, event)
        if kind == 'TIMER':
            return self._fly(context)
        return {'PASS_THROUGH'}


def sample_scenes():
    """The scene files that ship with the add-on, as (menu label, path), by label:
    ``point_lights.json`` is "Point Lights"."""
    folder = os.path.join(paths.data_dir(), "scenes")
    scenes = [(os.path.splitext(name)[0].replace("_", " ").title(), os.path.join(folder, name))
              for name in os.listdir(folder) if name.lower().endswith(".json")]
    return sorted(scenes)


class CSM_MT_import_sample_scene(bpy.types.Menu):
    """The scenes that ship with CSM, imported at once in place of the current scene's \
contents (Ctrl+Z brings them back; the Adjust Last Operation panel switches to Add)"""
    bl_idname = "CSM_MT_import_sample_scene"
    bl_label = "CSM Sample Scene"

    def draw(self, context):
        layout = self.layout
        layout.operator_context = 'EXEC_DEFAULT'    # no file browser: the path is known
        for label, path in sample_scenes():
            item = layout.operator(CSM_OT_import_scene.bl_idname, text=label)
            item.filepath = path
            # Set, so a file import's remembered "Add to Scene" does not apply here.
            item.mode = 'REPLACE'


def menu_import(self, context):
    self.layout.operator(CSM_OT_import_scene.bl_idname, text="CSM Scene (.json)")
    self.layout.menu(CSM_MT_import_sample_scene.bl_idname)


classes = (
    CSM_OT_import_scene,
    CSM_OT_reload_scene,
    CSM_OT_reload_shaders,
    CSM_OT_open_shader_folder,
    CSM_OT_reset_sun_direction,
    CSM_OT_screenshot,
    CSM_OT_first_person,
)


menus = (CSM_MT_import_sample_scene,)


def register():
    for cls in classes + menus:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    for cls in reversed(classes + menus):
        bpy.utils.unregister_class(cls)
