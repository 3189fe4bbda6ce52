"""Turns a parsed scene file into Blender objects, transactionally.

Owns the Blender side of scene import: one collection per imported file (named after
the file, remembering its source in the custom property ``csm_source``), with a sun, point
lights, a camera and the mesh files loaded by Blender's own importers. Parsing and
validation live in ``scene_format``; axis and transform conventions in ``conventions``;
what makes a mesh file safe to hand to an importer in ``mesh_files``.

The import is a transaction. Everything that can be checked without Blender (the JSON,
every mesh path, every mesh file and the files it references, the importers) is checked
before any datablock is created. If an importer still fails, every datablock created since
the start is removed and the scene camera, active collection and selection are restored,
so the scene is exactly as it was. What importers change outside their datablocks (scene
custom properties, add-on preferences) is put back after every import, failed or not.
Every failure is one ``SceneImportError`` with a one-line message; importers' own output
(progress, tracebacks) is captured and shown only with ``CSM_DEBUG`` set.

Each distinct mesh file is imported once; further references to it get linked copies
(objects sharing its mesh data), each under its own transform.

Re-importing a file replaces its previous import, but only once the new import has
succeeded.
"""

import contextlib
import math
import os
import re

import bpy
import mathutils
import numpy as np

from ..core import conventions, mesh_files, scene_format
from ..core.captured_output import CapturedOutput
from . import compat

# CSM treats a point light's power / 100 W as its intensity multiplier, so 100 W is the
# file's intensity of one.
POINT_LIGHT_WATTS = 100.0
POINT_LIGHT_SOFT_SIZE = 0.1   # metres; small, because the course's lights are points
# W/m^2 for the file's sun intensity of one: the course lights a surface with
# intensity * albedo * cos, and Blender's Lambert (EEVEE's and CSM's) gives
# strength * albedo / pi * cos, so one is pi W/m^2 (docs/lighting.md).
SUN_STRENGTH = math.pi
DEFAULT_CAMERA_FOV_DEGREES = 40.0

# Datablock kinds an importer may create; all are compared before/after for rollback.
_DATA_KINDS = ("objects", "collections", "cameras", "lights", "meshes", "curves",
               "armatures", "lattices", "materials", "node_groups", "textures", "images",
               "actions", "worlds")


class SceneImportError(Exception):
    """A scene could not be imported; ``str()`` is one line naming the file and reason."""


# ----------------------------------------------------------------------------- checks
# Everything in this section runs before the first datablock is created.

def _operator(path):
    module, name = path.split(".")
    op = getattr(getattr(bpy.ops, module), name)
    try:
        op.get_rna_type()
    except (KeyError, AttributeError):
        return None
    return op


def _operator_with_addon(path, addon):
    op = _operator(path)
    if op is None and addon:
        import addon_utils
        with contextlib.suppress(Exception):
            # default_set=False: enable for this session without touching saved preferences
            addon_utils.enable(addon, default_set=False)
        op = _operator(path)
    return op


def _settable(op, wanted):
    """The subset of ``wanted`` keyword arguments this version of ``op`` accepts."""
    properties = op.get_rna_type().properties
    accepted = {}
    for key, value in wanted.items():
        prop = properties.get(key)
        if prop is None:
            continue
        if prop.type == 'ENUM' and value not in {item.identifier for item in prop.enum_items}:
            continue
        accepted[key] = value
    return accepted


class _Importer:
    """One of Blender's mesh importers with the options that make it read Y-up files."""

    def __init__(self, label, op, options, converts_axes):
        self.label = label
        self.op = op
        self.options = options
        # Old importers without axis options leave the file's Y-up data as is; the
        # builder then applies the change of basis to their top-level objects.
        self.converts_axes = converts_axes

    needs_numpy_bool = False

    def run(self, filepath):
        if not self.needs_numpy_bool:
            return self.op(filepath=filepath, **self.options)
        np.bool = bool
        try:
            return self.op(filepath=filepath, **self.options)
        finally:
            del np.bool


def _find_importer(extension):
    yup_new = {"forward_axis": "NEGATIVE_Z", "up_axis": "Y"}
    yup_old = {"axis_forward": "-Z", "axis_up": "Y"}
    if extension in (".gltf", ".glb"):
        op = _operator_with_addon("import_scene.gltf", "io_scene_gltf2")
        if op is None:
            return None
        # glTF is Y-up by definition and the importer always converts. Keep everything in
        # the active collection (5.0 would otherwise add a collection per glTF scene).
        options = _settable(op, {"import_scene_as_collection": False})
        importer = _Importer("glTF importer (io_scene_gltf2)", op, options, True)
        # The 3.4/3.5 importer uses np.bool, which numpy 1.24 removed (Debian 12 ships
        # Blender 3.4 with numpy 1.24). Its other shading modes would drop the file's
        # normals, so lend it the alias for the duration of the import instead.
        importer.needs_numpy_bool = compat.gltf_importer_needs_numpy_bool()
        return importer
    if extension == ".obj":
        op = _operator("wm.obj_import")
        if op is None:
            return None
        options = _settable(op, yup_new)
        return _Importer("OBJ importer", op, options, len(options) == 2)
    if extension in (".ply", ".stl"):
        kind = extension[1:]
        op = _operator(f"wm.{kind}_import")
        if op is not None:
            options = _settable(op, yup_new)
            return _Importer(f"{kind.upper()} importer", op, options, len(options) == 2)
        op = _operator_with_addon(f"import_mesh.{kind}", f"io_mesh_{kind}")
        if op is None:
            return None
        options = _settable(op, yup_old)
        return _Importer(f"{kind.upper()} importer (io_mesh_{kind})", op, options,
                         len(options) == 2)
    return None


def _check_mesh_file(mesh_path, scene_path, json_path):
    """Refuse, before anything is created, a mesh file Blender's importer must not see:
    one that could crash or hang it, or that would import as nothing
    (``core/mesh_files.py``)."""
    try:
        mesh_files.check_mesh_file(mesh_path)
    except mesh_files.MeshFileError as err:
        raise SceneImportError(_one_line(f"{scene_path}: {json_path}: {err}")) from None


def _one_line(text):
    return " ".join(str(text).split())


class _PlannedObject:
    def __init__(self, index, scene_object, mesh_path, importer):
        self.index = index
        self.scene_object = scene_object
        self.mesh_path = mesh_path
        self.importer = importer

    @property
    def json_path(self):
        return f"objects[{self.index}].mesh"


def _plan(scene_path, description, cwd):
    planned = []
    importers = {}
    checked = set()
    for index, scene_object in enumerate(description.objects):
        json_path = f"objects[{index}].mesh"
        try:
            mesh_path = scene_format.resolve_mesh_path(scene_object.mesh, scene_path, cwd,
                                                       json_path=json_path)
        except scene_format.SceneFormatError as err:
            raise SceneImportError(str(err)) from None
        extension = os.path.splitext(mesh_path)[1].lower()
        if extension not in importers:
            importers[extension] = _find_importer(extension)
        importer = importers[extension]
        if importer is None:
            raise SceneImportError(
                f"{scene_path}: {json_path}: this Blender has no importer for "
                f"'{extension}' files (is the add-on for it disabled?)")
        if mesh_path not in checked:
            _check_mesh_file(mesh_path, scene_path, json_path)
            checked.add(mesh_path)
        planned.append(_PlannedObject(index, scene_object, mesh_path, importer))
    return planned


# --------------------------------------------------------------------- bookkeeping

def _data_snapshot():
    return {kind: {block.as_pointer() for block in getattr(bpy.data, kind)}
            for kind in _DATA_KINDS if hasattr(bpy.data, kind)}


def _created_since(snapshot):
    created = {}
    for kind, before in snapshot.items():
        created[kind] = [block for block in getattr(bpy.data, kind)
                         if block.as_pointer() not in before]
    return created


def _walk_collections(root):
    yield root
    for child in root.children:
        yield from _walk_collections(child)


def _walk_layer_collections(layer_collection):
    yield layer_collection
    for child in layer_collection.children:
        yield from _walk_layer_collections(child)


def _layer_collection_for(view_layer, collection):
    for layer_collection in _walk_layer_collections(view_layer.layer_collection):
        if layer_collection.collection == collection:
            return layer_collection
    return None


def _same_file(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.normcase(os.path.abspath(a)) == os.path.normcase(os.path.abspath(b))


def imported_collections(scene):
    """Collections in ``scene`` made by ``import_scene_file``, oldest import first."""
    found = [c for c in _walk_collections(scene.collection)
             if c is not scene.collection and "csm_source" in c]
    return sorted(found, key=lambda c: int(c.get("csm_import_order", 0)))


class _SceneState:
    """What an import may change outside its own datablocks, to restore on failure."""

    def __init__(self, scene, view_layer):
        self.scene = scene
        self.view_layer = view_layer
        self.camera = scene.camera
        self.world = scene.world
        self.active_collection = view_layer.active_layer_collection.collection
        self.active_collection_pointer = self.active_collection.as_pointer()
        self.active_object = view_layer.objects.active
        self.selected = [obj for obj in view_layer.objects if obj.select_get(view_layer=view_layer)]

    def restore_active_collection(self, removed_pointers=()):
        target = None
        # Compare pointers: a removed collection must not be touched through Python.
        if self.active_collection_pointer not in removed_pointers:
            target = _layer_collection_for(self.view_layer, self.active_collection)
        self.view_layer.active_layer_collection = target or self.view_layer.layer_collection

    def restore(self):
        self.scene.camera = self.camera
        if self.scene.world is not self.world:
            self.scene.world = self.world
        self.restore_active_collection()
        for obj in self.view_layer.objects:
            obj.select_set(False, view_layer=self.view_layer)
        for obj in self.selected:
            if obj.name in self.view_layer.objects:
                obj.select_set(True, view_layer=self.view_layer)
        self.view_layer.objects.active = self.active_object


def _plain(value):
    """An ID property's value as plain Python (groups and arrays copied), for comparing
    and restoring after the IDProperty itself has changed."""
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if hasattr(value, "to_list"):
        return value.to_list()
    return value


def _preference_values(preferences):
    values = {}
    for addon in preferences.addons:
        addon_preferences = getattr(addon, "preferences", None)
        if addon_preferences is None:
            continue
        for prop in addon_preferences.bl_rna.properties:
            if prop.identifier == "rna_type" or prop.type in ('POINTER', 'COLLECTION'):
                continue
            with contextlib.suppress(Exception):
                value = getattr(addon_preferences, prop.identifier)
                values[(addon.module, prop.identifier)] = \
                    tuple(value) if getattr(prop, "is_array", False) else value
    return values


class _OutsideChanges:
    """What Blender's importers change outside the import's own datablocks, put back after
    every import, failed or not: custom properties of the scenes (the glTF importer stores
    a glTF scene's ``extras`` there, and its KHR_materials_variants list) and the user's
    preferences (KHR_materials_variants turns on a glTF add-on preference and marks the
    preferences dirty, so auto-save would write it)."""

    def __init__(self, scenes):
        self.scenes = []
        for scene in scenes:
            if all(scene != kept for kept, _ in self.scenes):
                self.scenes.append((scene, {key: _plain(scene[key]) for key in scene.keys()}))
        preferences = bpy.context.preferences
        self.preferences_dirty = preferences.is_dirty
        self.preference_values = _preference_values(preferences)

    def restore(self):
        for scene, before in self.scenes:
            with contextlib.suppress(ReferenceError):
                for key in list(scene.keys()):
                    if key not in before:
                        del scene[key]
                    elif _plain(scene[key]) != before[key]:
                        scene[key] = before[key]
                for key, value in before.items():
                    if key not in scene:
                        scene[key] = value
        preferences = bpy.context.preferences
        now = _preference_values(preferences)
        for (module, name), value in self.preference_values.items():
            if now.get((module, name), value) != value:
                addon = preferences.addons.get(module)
                with contextlib.suppress(Exception):
                    setattr(addon.preferences, name, value)
        if preferences.is_dirty != self.preferences_dirty:
            with contextlib.suppress(Exception):
                preferences.is_dirty = self.preferences_dirty


def _remove_datablocks(created):
    """Remove the given datablocks; objects and collections first so data loses users."""
    first = [block for kind in ("objects", "collections") for block in created.get(kind, [])]
    rest = [block for kind in _DATA_KINDS if kind not in ("objects", "collections")
            for block in created.get(kind, [])]
    if first:
        bpy.data.batch_remove(first)
    if rest:
        bpy.data.batch_remove(rest)


def _material_dependencies(material, node_groups, images):
    def walk(tree):
        if tree is None:
            return
        for node in tree.nodes:
            image = getattr(node, "image", None)
            if image is not None:
                images.append(image)
            group = getattr(node, "node_tree", None)
            if group is not None and group not in node_groups:
                node_groups.append(group)
                walk(group)
    walk(material.node_tree)


def _remove_import(collection):
    """Delete an earlier import: its collection tree, objects and now-unused data.

    Data (meshes, materials, images, ...) goes only if nothing else uses it any more, so
    objects the user copied out of the collection keep working.
    """
    collections = list(_walk_collections(collection))
    objects = list(collection.all_objects)
    removed_names = {}
    collection_pointers = {c.as_pointer() for c in collections}
    # NOTE: Object.users_collection scans every collection in Python per object, which is
    # quadratic for a big import; one pass over the other collections is linear.
    elsewhere = set()
    others = [c for c in bpy.data.collections if c.as_pointer() not in collection_pointers]
    others += [s.collection for s in bpy.data.scenes]
    for other in others:
        elsewhere.update(obj.as_pointer() for obj in other.objects)
    only_here = [obj for obj in objects if obj.as_pointer() not in elsewhere]
    only_here_pointers = {obj.as_pointer() for obj in only_here}
    data = [obj.data for obj in only_here if obj.data is not None]
    materials, node_groups, images = [], [], []
    for obj in only_here:
        for slot in obj.material_slots:
            if slot.material is not None and slot.material not in materials:
                materials.append(slot.material)
    for block in data:
        for material in getattr(block, "materials", []):
            if material is not None and material not in materials:
                materials.append(material)
    for material in materials:
        _material_dependencies(material, node_groups, images)
    for obj in objects:
        if obj.as_pointer() not in only_here_pointers:
            for c in collections:
                if obj.name in c.objects:
                    c.objects.unlink(obj)
    for block in only_here + collections:
        removed_names.setdefault(type(block).__name__, set()).add(block.name)
    bpy.data.batch_remove(only_here + collections)
    for group in (data, materials, node_groups, images):
        seen = set()
        unused = []
        for block in group:
            if block.as_pointer() in seen:
                continue
            seen.add(block.as_pointer())
            if block.users == 0:
                removed_names.setdefault(type(block).__name__, set()).add(block.name)
                unused.append(block)
        if unused:
            bpy.data.batch_remove(unused)
    return removed_names


_NUMBERED = re.compile(r"^(.*)\.\d{3,}$")


def _take_back_names(created, removed_names):
    """After replacing an import, give the new datablocks the names the old ones had.

    Blender numbered the new datablocks (``name.001``) while the old import still held
    the plain names; each new block takes the first freed name with the same base.
    Linear in the number of blocks (an import of 10,000 copies renames 10,000 objects).
    """
    def base_of(name):
        match = _NUMBERED.match(name)
        return match.group(1) if match else name

    def number_of(name):
        return name[len(base_of(name)):]

    freed_by_base = {}      # (type name, base) -> [freed names, best first], next index
    for type_name, names in removed_names.items():
        for name in names:
            freed_by_base.setdefault((type_name, base_of(name)), [[], 0])[0].append(name)
    for entry in freed_by_base.values():
        entry[0].sort(key=lambda n: (len(number_of(n)), n))
    for kind, blocks in created.items():
        numbered = sorted((b for b in blocks if _NUMBERED.match(b.name)),
                          key=lambda b: (base_of(b.name), len(b.name), b.name))
        if not numbered:
            continue
        taken = {block.name for block in getattr(bpy.data, kind)}
        for block in numbered:
            entry = freed_by_base.get((type(block).__name__, base_of(block.name)))
            if entry is None:
                continue
            candidates, start = entry
            while start < len(candidates) and candidates[start] in taken:
                start += 1      # a name never becomes free again during this loop
            entry[1] = start
            if start < len(candidates):
                old_name = block.name
                block.name = candidates[start]
                taken.discard(old_name)
                taken.add(block.name)
                entry[1] = start + 1


# --------------------------------------------------------------------------- build

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


_EXCEPTION_LINE = re.compile(r"^[A-Za-z_][\w.]*(Error|Exception)\b")


def _importer_reason(err):
    """The useful line of an importer failure.

    ``bpy.ops`` wraps a Python importer's crash in a RuntimeError holding the whole
    traceback and a "Location:" line; the user needs only the final exception line.
    """
    lines = [line.strip() for line in str(err).splitlines()]
    lines = [line for line in lines if line and not line.startswith(("Location:", "File ", "^", "~"))]
    exception_lines = [line for line in lines if _EXCEPTION_LINE.match(line)]
    if exception_lines:
        return exception_lines[-1]
    for line in lines:
        if not line.startswith(("Traceback", "Error: Python: Traceback")):
            return re.sub(r"^Error:\s*", "", line)
    return type(err).__name__


def _new_parent(planned, collection=None):
    """The empty carrying one scene object's transform; the file's objects hang below it.

    Linked to ``collection`` when given; copies are linked all together later (linking
    one by one between other edits makes Blender resync the view layer each time)."""
    item = planned.scene_object
    stem = os.path.splitext(os.path.basename(planned.mesh_path))[0]
    # Named apart from the importer's objects, which often carry the file's name too.
    parent = bpy.data.objects.new(f"{stem} (scene object {planned.index})", None)
    parent.empty_display_type = 'PLAIN_AXES'
    if collection is not None:
        collection.objects.link(parent)
    location, rotation_mode, euler, scale = conventions.blender_object_transform_zup(
        item.translate, item.rotate, item.scale)
    parent.location = location
    parent.rotation_mode = rotation_mode
    parent.rotation_euler = euler
    parent.scale = scale
    parent["csm_mesh"] = planned.mesh_path
    return parent


def _debug_output():
    """CSM_DEBUG set: importers' own output (tracebacks included) is passed through."""
    return bool(os.environ.get("CSM_DEBUG"))


def _run_importer(planned, scene_path):
    """Run the importer with its output captured at the file-descriptor level.

    Importers print progress and, on failure, the whole Python traceback (bpy.ops prints
    it before raising); the user gets one line instead, and the full log only with
    CSM_DEBUG set.
    """
    failure = None
    with CapturedOutput() as captured:
        try:
            result = planned.importer.run(planned.mesh_path)
        except Exception as err:  # importers raise anything from RuntimeError to KeyError
            failure = err
    if _debug_output() and (captured.text or failure is not None):
        import sys
        details = f"\n{failure}" if failure is not None else ""
        sys.stderr.write(f"CSM_DEBUG: {planned.importer.label} on {planned.mesh_path}:\n"
                         f"{captured.text}{details}\n")
        sys.stderr.flush()
    if failure is not None:
        raise SceneImportError(_one_line(
            f"{scene_path}: {planned.json_path}: Blender's {planned.importer.label} "
            f"failed on {planned.mesh_path}: {_importer_reason(failure)}")) from None
    if 'FINISHED' not in result:
        raise SceneImportError(_one_line(
            f"{scene_path}: {planned.json_path}: Blender's {planned.importer.label} "
            f"could not read {planned.mesh_path}"))


def _import_mesh(planned, collection, scene_path):
    """Run one importer; return the parent empty and the file's objects below it."""
    parent = _new_parent(planned, collection)
    before = {obj.as_pointer() for obj in bpy.data.objects}
    _run_importer(planned, scene_path)
    new_objects = [obj for obj in bpy.data.objects if obj.as_pointer() not in before]
    meshes = [obj for obj in new_objects if obj.type == 'MESH']
    if not meshes:
        raise SceneImportError(_one_line(
            f"{scene_path}: {planned.json_path}: {planned.mesh_path} contains no mesh"))
    if not any(len(obj.data.polygons) for obj in meshes):
        # The STL and OBJ importers report success for files they read nothing from.
        raise SceneImportError(_one_line(
            f"{scene_path}: {planned.json_path}: {planned.mesh_path} is not a valid mesh "
            f"file: Blender's {planned.importer.label} read no faces from it"))
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
    if os.path.splitext(planned.mesh_path)[1].lower() in (".gltf", ".glb"):
        _tag_course_materials(new_objects)
    return parent, new_objects


# NOTE: the course's glTF files keep specular in the blue and shininess in the green channel
# of metallicRoughnessTexture (docs/scene-format.md), which Blender's importer wires to
# Metallic and Roughness; this tag makes mesh_cache read them the course's way
# (docs/materials.md). Materials made or imported any other way keep Blender's meaning.
COURSE_SURFACE_TAG = ("csm_surface_convention", "COURSE")


def _tag_course_materials(objects):
    for obj in objects:
        for slot in getattr(obj, "material_slots", ()):
            if slot.material is not None:
                slot.material[COURSE_SURFACE_TAG[0]] = COURSE_SURFACE_TAG[1]


def _copy_import(planned, first_parent, first_objects, unlinked):
    """A further reference to a file already imported: linked copies of its objects.

    NOTE: running the importer again per reference costs a view-layer update over the whole
    scene each time (quadratic: 3,000 references took 23 minutes); copies share the mesh
    data, so N references cost one import plus N cheap object copies. The new objects are
    appended to ``unlinked``, for the caller to link in one go.
    """
    parent = _new_parent(planned)
    unlinked.append(parent)
    copies = {first_parent.as_pointer(): parent}
    for obj in first_objects:
        copies[obj.as_pointer()] = obj.copy()      # shares obj.data: a linked duplicate
    for obj in first_objects:
        copy = copies[obj.as_pointer()]
        unlinked.append(copy)
        if obj.parent is not None:
            matrix_parent_inverse = obj.matrix_parent_inverse.copy()
            copy.parent = copies.get(obj.parent.as_pointer(), obj.parent)
            copy.matrix_parent_inverse = matrix_parent_inverse
        for modifier in copy.modifiers:            # e.g. an armature of the file's skin
            target = getattr(modifier, "object", None)
            if target is not None and target.as_pointer() in copies:
                modifier.object = copies[target.as_pointer()]
    return parent


def _corners_in_parent(parent, objects):
    """Bounding-box corners of the mesh objects below ``parent``, in the parent's space
    (the mesh file's own frame), as an (n, 3) array; needs an updated view layer."""
    bounds = _mesh_bounds(objects, np.linalg.inv(np.array(parent.matrix_world, np.float64)))
    if bounds is None:
        return np.zeros((0, 3))
    low, high = bounds
    return np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                     for z in (low[2], high[2])])


def _placed_bounds(planned, corners_by_file):
    """World (min, max) of every scene object's mesh, from its file's corners and its
    transform: numpy over the file's transforms, not Blender over every object."""
    points = []
    for item in planned:
        corners = corners_by_file[item.mesh_path]
        if not len(corners):
            continue
        o = item.scene_object
        matrix = conventions.object_matrix_zup(o.translate.as_tuple(), o.rotate.as_tuple(),
                                               o.scale.as_tuple())
        points.append(corners @ matrix[:3, :3].T + matrix[:3, 3])
    if not points:
        return None
    points = np.concatenate(points)
    return points.min(axis=0), points.max(axis=0)


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


def _add_sun(light, collection, bounds, name):
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


def _add_point_light(light, collection, name):
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


def _add_camera(camera, collection, name):
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


def _add_default_camera(collection, bounds, name):
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


def _override_for(scene):
    if scene == bpy.context.scene:
        return contextlib.nullcontext(), bpy.context.view_layer
    view_layer = scene.view_layers[0]
    return bpy.context.temp_override(scene=scene, view_layer=view_layer), view_layer


# Course files carry no ambient term (students hard-coded ~0.02). A scene without a World
# gets a soft sky: its colour is CSM's ambient light and the background.
DEFAULT_SKY_COLOR = (0.12, 0.16, 0.22)


def _ensure_world(scene):
    if scene.world is not None:
        return      # the user's own World (and ambient) stays as it is
    world = bpy.data.worlds.new("CSM Sky")
    world.color = DEFAULT_SKY_COLOR
    if world.node_tree is not None:
        for node in world.node_tree.nodes:
            if node.type == 'BACKGROUND':
                node.inputs[0].default_value = (*DEFAULT_SKY_COLOR, 1.0)
    scene.world = world


def _build(description, planned, scene, view_layer, scene_path, name):
    collection = bpy.data.collections.new(name)
    scene.collection.children.link(collection)
    view_layer.active_layer_collection = _layer_collection_for(view_layer, collection)
    for obj in view_layer.objects:
        obj.select_set(False, view_layer=view_layer)

    parents = []
    imported = {}       # mesh path -> (parent, objects) of its first, real import
    corners_by_file = {}
    unlinked = []
    for item in planned:
        first = imported.get(item.mesh_path)
        if first is None:
            parent, objects = _import_mesh(item, collection, scene_path)
            imported[item.mesh_path] = (parent, objects)
            view_layer.update()     # while the scene is small: only for distinct files
            corners_by_file[item.mesh_path] = _corners_in_parent(parent, objects)
        else:
            parent = _copy_import(item, first[0], first[1], unlinked)
        parents.append(parent)
    for obj in unlinked:
        collection.objects.link(obj)
    bounds = _placed_bounds(planned, corners_by_file)
    if bounds is None:
        bounds = (np.full(3, -1.0), np.full(3, 1.0))

    if description.directional_light is not None:
        _add_sun(description.directional_light, collection, bounds, "Sun")
        collection["csm_sun_direction"] = [float(v) for v in conventions.direction_zup_from_yup(
            description.directional_light.direction.as_tuple())]
    for index, light in enumerate(description.lights):
        _add_point_light(light, collection, f"Point light {index + 1}")
    if description.camera is not None:
        camera = _add_camera(description.camera, collection, "Camera")
    else:
        camera = _add_default_camera(collection, bounds, "Camera (default view)")
    scene.camera = camera
    _ensure_world(scene)

    in_layer = {obj.as_pointer() for obj in view_layer.objects}
    for obj in collection.all_objects:
        if obj.as_pointer() in in_layer:
            obj.select_set(True, view_layer=view_layer)
    view_layer.objects.active = parents[0] if parents else camera
    # Callers (the renderer, tests) read matrix_world right away.
    view_layer.update()
    return collection


def import_scene_file(path, scene=None):
    """Import the scene file at ``path`` into ``scene`` (default: the context scene).

    Returns the new collection. Raises only ``SceneImportError``; then nothing changed.
    """
    scene = scene if scene is not None else bpy.context.scene
    scene_path = os.path.abspath(os.fspath(path))
    try:
        description = scene_format.load_scene(scene_path)
    except scene_format.SceneFormatError as err:
        raise SceneImportError(str(err)) from None
    planned = _plan(scene_path, description, os.getcwd())

    override, view_layer = _override_for(scene)
    previous = [c for c in imported_collections(scene) if _same_file(c["csm_source"], scene_path)]
    order = max((int(c.get("csm_import_order", 0)) for c in imported_collections(scene)),
                default=0) + 1
    name = os.path.splitext(os.path.basename(scene_path))[0]

    state = _SceneState(scene, view_layer)
    outside = _OutsideChanges((scene, bpy.context.scene))
    snapshot = _data_snapshot()
    try:
        with override:
            collection = _build(description, planned, scene, view_layer, scene_path, name)
    except BaseException as err:
        _remove_datablocks(_created_since(snapshot))
        state.restore()
        outside.restore()
        if isinstance(err, SceneImportError):
            raise
        if not isinstance(err, Exception):
            raise
        raise SceneImportError(_one_line(
            f"{scene_path}: import failed: {type(err).__name__}: {err}")) from err

    outside.restore()
    collection["csm_source"] = scene_path
    collection["csm_import_order"] = order
    created = _created_since(snapshot)
    previous_pointers = {c.as_pointer() for c in previous}
    removed_names = {}
    for old in previous:
        for kind, names in _remove_import(old).items():
            removed_names.setdefault(kind, set()).update(names)
    _take_back_names(created, removed_names)
    state.restore_active_collection(previous_pointers)
    return collection


def reload_scene(collection):
    """Import the collection's source file again, replacing the collection."""
    source = collection.get("csm_source") if collection is not None else None
    if not source:
        name = collection.name if collection is not None else "None"
        raise SceneImportError(f"collection '{name}' was not imported from a CSM scene file")
    scene = bpy.context.scene
    for candidate in bpy.data.scenes:
        if any(c == collection for c in _walk_collections(candidate.collection)):
            scene = candidate
            break
    return import_scene_file(source, scene)
