"""Sun direction controls and first-person camera settings (``Scene.csm_light``).

Owns the user's view of the sun: which Sun object is the scene's active sun
(``sun_object``: the one the user picked, else the newest CSM import's, never one in an
excluded or hidden collection); azimuth/elevation as Blender angles (radians, shown in
degrees) and a direction vector, all read from and written to that Sun's rotation, so the
viewport and the Sun gizmo update together through the depsgraph; "Reset to scene file", which puts back the direction the
import stored in the collection property ``csm_sun_direction``; and the first-person
camera's speed (metres per second) and turn rate (an angle per second).

Conventions (Z-up, Blender world):
- azimuth: angle from +X toward +Y of the direction TOWARDS the sun (seen from above);
- elevation: angle above the horizon of the direction towards the sun (90° = overhead);
- vector: the direction the light TRAVELS (the Sun's local -Z axis), as in the scene file.
"""

import math

import bpy
import numpy as np
from bpy.props import FloatProperty, FloatVectorProperty
from mathutils import Matrix, Vector

from ..core.controls import azimuth_elevation_from_travel, travel_from_azimuth_elevation
from .scene_builder import imported_collections

# Fallback direction when the scene has no sun: light coming straight down.
_NO_SUN_TRAVEL = (0.0, 0.0, -1.0)


# ------------------------------------------------------------------ the scene's sun
def _is_sun(obj):
    return obj.type == 'LIGHT' and obj.data is not None and obj.data.type == 'SUN'


def _view_layer_of(scene):
    context_scene = getattr(bpy.context, "scene", None)
    view_layer = getattr(bpy.context, "view_layer", None)
    if context_scene == scene and view_layer is not None:
        return view_layer
    return scene.view_layers[0] if len(scene.view_layers) else None


def sun_object(scene, view_layer=None):
    """The scene's active sun, the one the Light panel edits, or None.

    In order: the view layer's active object when it is a Sun (the user picked it); else
    the Sun of the most recent CSM import into this scene; else the first Sun by name (a
    stable choice). Only Suns the view layer shows count: never one in an excluded or
    hidden collection, nor a hidden Sun.
    """
    view_layer = view_layer if view_layer is not None else _view_layer_of(scene)
    if view_layer is None:
        return None

    def usable(obj):
        return _is_sun(obj) and obj.visible_get(view_layer=view_layer)

    active = view_layer.objects.active
    if active is not None and usable(active):
        return active
    for collection in reversed(imported_collections(scene)):
        suns = [obj for obj in collection.all_objects if usable(obj)]
        if suns:
            return min(suns, key=lambda obj: obj.name)
    suns = [obj for obj in view_layer.objects if usable(obj)]
    return min(suns, key=lambda obj: obj.name) if suns else None


def sun_travel(obj):
    """Unit direction the sun's light travels (its world -Z axis)."""
    # matrix_basis follows edits at once; matrix_world only after a depsgraph update.
    matrix = obj.matrix_basis if obj.parent is None else obj.matrix_world
    axis = -np.array(matrix, dtype=np.float64)[:3, 2]
    length = float(np.linalg.norm(axis))
    return tuple(axis / length) if length > 0.0 else _NO_SUN_TRAVEL


def set_sun_travel(obj, travel):
    """Rotate ``obj`` so its light travels along ``travel``; keeps location and scale."""
    direction = Vector(travel)
    if direction.length == 0.0:
        return
    direction.normalize()
    # The sun's local +Y leans to world +Z (world +Y when the sun points straight up/down),
    # the same choice the importer makes, so reset-to-file gives back identical rotations.
    up = Vector((0.0, 0.0, 1.0)) if abs(direction.z) < 0.999 else Vector((0.0, 1.0, 0.0))
    z_axis = -direction
    x_axis = up.cross(z_axis).normalized()
    y_axis = z_axis.cross(x_axis)
    rotation = Matrix((x_axis, y_axis, z_axis)).transposed()
    rotation = rotation.to_quaternion()
    if obj.parent is not None:
        location, _rotation, scale = obj.matrix_world.decompose()
        obj.matrix_world = Matrix.LocRotScale(location, rotation, scale)
        return
    # Only the rotation channel the user animates changes; location and scale stay exact.
    if obj.rotation_mode == 'QUATERNION':
        obj.rotation_quaternion = rotation
    elif obj.rotation_mode == 'AXIS_ANGLE':
        axis, angle = rotation.to_axis_angle()
        obj.rotation_axis_angle = (angle, *axis)
    else:
        obj.rotation_euler = rotation.to_euler(obj.rotation_mode, obj.rotation_euler)


def file_sun_direction(obj):
    """The ``csm_sun_direction`` stored by the import for the collection holding ``obj``."""
    for collection in obj.users_collection:
        if "csm_sun_direction" in collection:
            return tuple(float(v) for v in collection["csm_sun_direction"])
    return None


# ------------------------------------------------------------------ properties
def _get_travel(self):
    obj = sun_object(self.id_data)
    return sun_travel(obj) if obj is not None else _NO_SUN_TRAVEL


def _set_travel(self, value):
    obj = sun_object(self.id_data)
    if obj is not None:
        set_sun_travel(obj, value)


# Blender's angle properties hold radians and show degrees (with the scene's rotation
# units); the core's sun math is in degrees.
def _get_azimuth(self):
    return math.radians(azimuth_elevation_from_travel(_get_travel(self))[0])


def _get_elevation(self):
    return math.radians(azimuth_elevation_from_travel(_get_travel(self))[1])


def _set_azimuth(self, value):
    _set_travel(self, travel_from_azimuth_elevation(math.degrees(value),
                                                    math.degrees(_get_elevation(self))))


def _set_elevation(self, value):
    _set_travel(self, travel_from_azimuth_elevation(math.degrees(_get_azimuth(self)),
                                                    math.degrees(value)))


class CSMLightControls(bpy.types.PropertyGroup):
    """Sun direction (a view onto the active Sun object) and first-person camera settings."""

    sun_azimuth: FloatProperty(
        name="Sun Azimuth",
        description="Compass direction towards the sun, in degrees from +X toward +Y "
                    "(0\u00b0 = sun in +X, 90\u00b0 = sun in +Y). Rotates the scene's active "
                    "Sun (the selected one, else the newest imported scene's)",
        get=_get_azimuth, set=_set_azimuth,
        soft_min=-math.pi, soft_max=math.pi, step=100, precision=1,
        subtype='ANGLE', unit='ROTATION', options=set())
    sun_elevation: FloatProperty(
        name="Sun Elevation",
        description="Height of the sun above the horizon, in degrees (0\u00b0 = grazing "
                    "light, 90\u00b0 = straight overhead). Rotates the scene's active Sun",
        get=_get_elevation, set=_set_elevation,
        min=-math.pi / 2, max=math.pi / 2, step=100, precision=1,
        subtype='ANGLE', unit='ROTATION', options=set())
    sun_direction: FloatVectorProperty(
        name="Light Direction",
        description="Direction the sunlight travels (unit vector, world Z-up, as in the "
                    "scene file's directional_light.direction after Y-up to Z-up). "
                    "Rotates the scene's active Sun",
        size=3, subtype='DIRECTION', get=_get_travel, set=_set_travel,
        options=set())
    fly_speed: FloatProperty(
        name="Fly Speed",
        description="First-person camera speed, in metres per second. 0 = automatic: "
                    "the next flight starts at a tenth of the scene's size per second "
                    "and writes it here. The mouse wheel changes it while flying",
        default=0.0, min=0.0, max=1.0e5, soft_max=1000.0, precision=2,
        unit='VELOCITY')
    fly_turn_speed: FloatProperty(
        name="Turn Speed",
        description="How fast the arrow keys turn the first-person camera: the angle "
                    "turned per second (a mouse drag turns 0.2 degrees per pixel)",
        default=math.radians(90.0), min=math.radians(1.0), max=math.radians(720.0),
        subtype='ANGLE', unit='ROTATION')


classes = (CSMLightControls,)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.csm_light = bpy.props.PointerProperty(
        type=CSMLightControls, name="CSM Light",
        description="CSM sun direction controls and first-person camera settings")


def unregister():
    del bpy.types.Scene.csm_light
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
