"""The Blender objects one scene file becomes, each built into the import's collection.

Owns one builder per kind of object, in the file's units and Blender's Z-up frame
(``core/conventions.py``): a mesh file's objects under an empty carrying the scene
object's transform, or at the origin as the source of ``mesh_copies`` (``add_mesh_file``);
the sun (``add_sun``), point lights
(``add_point_light``), the file's camera or a default view of the whole scene
(``add_camera``, ``add_default_camera``) and a sky World for scenes without one or being
replaced (``ensure_world``); and the scene's bounds the sun and default camera are placed
from.
Running importers is ``mesh_importers``'s part, the transaction ``scene_builder``'s.
"""

import math
import os

import bpy
import mathutils
import numpy as np

from ..core import conventions
from . import mesh_copies, mesh_importers

# CSM treats a point light's power / 100 W as its intensity multiplier, so 100 W is the
# file's intensity of one.
POINT_LIGHT_WATTS = 100.0
POINT_LIGHT_SOFT_SIZE = 0.1   # metres; small, because the course's lights are points
# W/m^2 for the file's sun intensity of one: the course lights a surface with
# intensity * albedo * cos, and Blender's Lambert (EEVEE's and CSM's) gives
# strength * albedo / pi * cos, so one is pi W/m^2 (docs/lighting.md).
SUN_STRENGTH = math.pi
DEFAULT_CAMERA_FOV_DEGREES = 40.0


def _matrix(array):
    return mathutils.Matrix(np.asarray(array, dtype=np.float64).tolist())


def _vector_zup(vec):
    return mathutils.Vector(conventions.ZUP_FROM_YUP[:3, :3] @ np.array(vec.as_tuple()))


def _link_only_to(obj, collection):
    if obj.name not in collection.objects:
        collection.objects.link(obj)
    for other in list(obj.users_collection):
        if other != collection:
            other.objects.unlink(obj)


def mesh_stem(planned):
    """The mesh file's name without its extension, which names what is built from it."""
    return os.path.splitext(os.path.basename(planned.mesh_path))[0]


def _new_parent(planned, collection=None, placed=True):
    """The empty carrying one scene object's transform; the file's objects hang below it.

    Linked to ``collection`` when given; copies are linked all together later (linking
    one by one between other edits makes Blender resync the view layer each time).
    Not ``placed``: the empty stays at the origin (a source for ``mesh_copies``)."""
    item = planned.scene_object
    stem = mesh_stem(planned)
    # Named apart from the importer's objects, which often carry the file's name too.
    parent = bpy.data.objects.new(
        f"{stem} (scene object {planned.index})" if placed else f"{stem} (source)", None)
    parent.empty_display_type = 'PLAIN_AXES'
    if collection is not None:
        collection.objects.link(parent)
    parent["csm_mesh"] = planned.mesh_path
    if not placed:
        return parent
    location, rotation_mode, euler, scale = conventions.blender_object_transform_zup(
        item.translate, item.rotate, item.scale)
    parent.location = location
    parent.rotation_mode = rotation_mode
    parent.rotation_euler = euler
    parent.scale = scale
    return parent


def add_mesh_file(planned, collection, scene_path, placed=True):
    """Import one mesh file into ``collection`` below a new parent empty carrying the scene
    object's transform (not ``placed``: at the origin); return the parent and the file's
    objects."""
    parent = _new_parent(planned, collection, placed)
    new_objects = mesh_importers.import_objects(planned, scene_path)
    for obj in new_objects:
        _link_only_to(obj, collection)
        if obj.parent is None:
            if not planned.importer.converts_axes:
                obj.matrix_basis = _matrix(conventions.ZUP_FROM_YUP) @ obj.matrix_basis
            # Keep the importer's own (node) transform below the file's object transform.
            basis = obj.matrix_basis.copy()
            obj.parent = parent
            obj.matrix_parent_inverse = mathutils.Matrix.Identity(4)
            obj.matrix_basis = basis
    return parent, new_objects


def corners_in_parent(parent, objects):
    """Bounding-box corners of the mesh objects below ``parent``, in the parent's space
    (the mesh file's own frame), as an (n, 3) array; needs an updated view layer."""
    bounds = _mesh_bounds(objects, np.linalg.inv(np.array(parent.matrix_world, np.float64)))
    if bounds is None:
        return np.zeros((0, 3))
    low, high = bounds
    return np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                     for z in (low[2], high[2])])


def placed_bounds(planned, corners_by_file):
    """World (min, max) of every scene object's mesh, from its file's corners and its
    transform: numpy over the file's transforms, not Blender over every object."""
    lows, highs = [], []
    by_file = {}
    for item in planned:
        by_file.setdefault(item.mesh_path, []).append(item.scene_object)
    for mesh_path, scene_objects in by_file.items():
        corners = corners_by_file[mesh_path]
        if not len(corners):
            continue
        matrices = mesh_copies.placement_matrices(scene_objects)
        points = np.einsum("nij,kj->nki", matrices[:, :3, :3], corners) + \
            matrices[:, None, :3, 3]
        lows.append(points.min(axis=(0, 1)))
        highs.append(points.max(axis=(0, 1)))
    if not lows:
        return None
    return np.min(lows, axis=0), np.max(highs, axis=0)


def _mesh_bounds(objects, space_from_world=None):
    """(min, max) corners of the mesh objects' bounding boxes in world space (or in the
    space ``space_from_world`` maps to), or None."""
    corners = []
    for obj in objects:
        if obj.type != 'MESH':
            continue
        local = np.array([tuple(corner) for corner in obj.bound_box], dtype=np.float64)
        world = np.array(obj.matrix_world, dtype=np.float64)
        if space_from_world is not None:
            world = space_from_world @ world
        corners.append(local @ world[:3, :3].T + world[:3, 3])
    if not corners:
        return None
    corners = np.concatenate(corners)
    return corners.min(axis=0), corners.max(axis=0)


def add_sun(light, collection, bounds, name):
    data = bpy.data.lights.new(name, 'SUN')
    data.color = light.color.as_tuple()
    data.energy = SUN_STRENGTH
    obj = bpy.data.objects.new(name, data)
    collection.objects.link(obj)
    # A sun's position does not matter for lighting; put it above the scene so it is
    # easy to find and grab in the viewport.
    low, high = bounds
    centre = (low + high) / 2.0
    location = (centre[0], centre[1], high[2] + 0.1 * max(np.max(high - low), 1.0))
    obj.matrix_world = _matrix(conventions.sun_matrix_zup(light.direction.as_tuple(), location))
    return obj


def add_point_light(light, collection, name):
    data = bpy.data.lights.new(name, 'POINT')
    data.color = light.color.as_tuple()
    data.energy = POINT_LIGHT_WATTS
    data.shadow_soft_size = POINT_LIGHT_SOFT_SIZE
    # The course's point lights cast no shadows (scene-format.md); Blender's own point
    # lights cast cube-map shadows as in EEVEE.
    data.use_shadow = False
    if hasattr(data, "use_custom_distance"):
        data.use_custom_distance = True
        data.cutoff_distance = light.radius
    # The renderer's falloff radius; also kept where a Blender has no custom distance.
    data["csm_radius"] = light.radius
    obj = bpy.data.objects.new(name, data)
    obj.location = _vector_zup(light.position)
    collection.objects.link(obj)
    return obj


def add_camera(camera, collection, name):
    data = bpy.data.cameras.new(name)
    data.sensor_fit = 'VERTICAL'
    data.angle_y = math.radians(camera.fov_y_degrees)
    data.clip_start = camera.near
    data.clip_end = camera.far
    obj = bpy.data.objects.new(name, data)
    location, rotation_mode, euler = conventions.blender_camera_transform_zup(
        camera.translate, camera.rotate)
    obj.location = location
    obj.rotation_mode = rotation_mode
    obj.rotation_euler = euler
    collection.objects.link(obj)
    return obj


def add_default_camera(collection, bounds, name):
    """A view of the whole scene from a raised diagonal, for files without a camera."""
    low, high = bounds
    centre = (low + high) / 2.0
    radius = max(float(np.linalg.norm(high - low)) / 2.0, 1e-3)
    half_fov = math.radians(DEFAULT_CAMERA_FOV_DEGREES) / 2.0
    distance = radius / math.sin(half_fov) * 1.05
    direction = np.array([-1.0, -1.0, 0.8])
    eye = centre + direction / np.linalg.norm(direction) * distance
    data = bpy.data.cameras.new(name)
    data.sensor_fit = 'VERTICAL'
    data.angle_y = 2.0 * half_fov
    data.clip_start = max(distance - 1.5 * radius, 0.01 * distance)
    data.clip_end = distance + 1.5 * radius
    obj = bpy.data.objects.new(name, data)
    obj.matrix_world = _matrix(conventions.look_at_matrix_zup(eye, centre))
    collection.objects.link(obj)
    return obj


# Course files carry no ambient term (students hard-coded ~0.02). A scene without a World
# gets a soft sky: its colour is CSM's ambient light and the background.
DEFAULT_SKY_COLOR = (0.12, 0.16, 0.22)


def ensure_world(scene, replace=False):
    """Give ``scene`` the CSM sky; a World it already has stays unless ``replace``."""
    if scene.world is not None and not replace:
        return      # the user's own World (and ambient) stays as it is
    world = bpy.data.worlds.new("CSM Sky")
    world.color = DEFAULT_SKY_COLOR
    if world.node_tree is not None:
        for node in world.node_tree.nodes:
            if node.type == 'BACKGROUND':
                node.inputs[0].default_value = (*DEFAULT_SKY_COLOR, 1.0)
    scene.world = world
