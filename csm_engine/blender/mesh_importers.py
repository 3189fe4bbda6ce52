"""Blender's mesh importers, and what is checked before one of them runs.

Owns finding the importer for a mesh file's extension (glTF, OBJ, PLY, STL: the operators
of this Blender, enabling a bundled add-on when needed, with the options that read Y-up
files), planning an import (``plan``: every mesh path resolved, its importer found and the
file checked by ``core/mesh_files.py`` before any datablock is created, and every file
read kept inside the scene's folder tree and the folders the user allowed), and running one
importer (``import_objects``): its output captured, its failure turned into one line, its
result checked for faces, and glTF materials tagged with the course's surface convention.
Where the imported objects go is ``object_builders``'s part.
"""

import contextlib
import os
import re

import bpy
import numpy as np

from ..core import mesh_files, paths, scene_format
from ..core.captured_output import CapturedOutput
from . import compat
from .materials import COURSE_SURFACE_TAG
from .import_transaction import SceneImportError, one_line


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
            # default_set=False: enable until Blender quits, without touching saved preferences
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


def allowed_folders(scene_path, extra_folders=()):
    """The folders a scene's importers may read from: the scene file's folder first (the
    one error messages name); for a scene in a ``scenes`` folder, that folder's parent (the
    course's layout, ``data/scenes`` beside ``data/gltf``, which the bundled scenes follow);
    the add-on's own data folder (read-only files it ships); then the user's folders."""
    scene_dir = os.path.dirname(os.path.abspath(scene_path))
    folders = [scene_dir, paths.data_dir()]
    if os.path.basename(scene_dir) == "scenes":
        folders.append(os.path.dirname(scene_dir))
    for folder in extra_folders:
        folder = folder.strip()
        if folder:
            folders.append(os.path.abspath(os.path.expanduser(folder)))
    return folders


def _course_root(mesh, mesh_path, scene_path, cwd):
    """The folder a relative mesh path without '..' was found under when that is the current
    folder or an ancestor of the scene's folder (course files name meshes from the project
    root while living in ``data/scenes/``); None otherwise. The filesystem root never
    counts: it would let a scene name any file on the disk."""
    mesh = os.path.normpath(mesh.replace("\\", "/") if os.sep == "/" else mesh)
    if os.path.isabs(os.path.expanduser(mesh)) or mesh.split(os.sep)[0] == os.pardir:
        return None
    if not mesh_path.endswith(os.sep + mesh):
        return None
    base = mesh_path[:-len(os.sep + mesh)] or os.sep
    scene_dir = os.path.dirname(os.path.abspath(scene_path))
    if base == os.path.dirname(base):
        return None
    is_ancestor = scene_dir.startswith(base.rstrip(os.sep) + os.sep)
    return base if is_ancestor or base == os.path.abspath(cwd) else None


def _confine_mesh_path(mesh, mesh_path, scene_path, cwd, folders, json_path):
    """Refuse a mesh file that resolves (symbolic links followed) outside the allowed
    folders, unless a course file found it under its project root."""
    roots = list(folders)
    root = _course_root(mesh, mesh_path, scene_path, cwd)
    if root is not None:
        roots.append(root)
    if not mesh_files.is_inside(mesh_path, roots):
        raise SceneImportError(one_line(
            f"{scene_path}: {json_path}: mesh file {mesh_path} is outside the scene's folder "
            f"{folders[0]} ({mesh_files.ALLOW_HINT})"))


def _check_mesh_file(mesh_path, scene_path, json_path, folders=None):
    """Refuse, before anything is created, a mesh file Blender's importer must not see:
    one that could crash or hang it, that would import as nothing, or that makes the
    importer read a file outside ``folders`` (``core/mesh_files.py``)."""
    try:
        mesh_files.check_mesh_file(mesh_path, folders)
    except mesh_files.MeshFileError as err:
        raise SceneImportError(one_line(f"{scene_path}: {json_path}: {err}")) from None


class PlannedObject:
    """One scene object checked and ready to import: its index in the file, its
    ``scene_format`` description, its resolved mesh path and the importer for it."""

    def __init__(self, index, scene_object, mesh_path, importer):
        self.index = index
        self.scene_object = scene_object
        self.mesh_path = mesh_path
        self.importer = importer

    @property
    def json_path(self):
        return f"objects[{self.index}].mesh"


def plan(scene_path, description, cwd, extra_folders=()):
    """Every scene object as a ``PlannedObject``, or ``SceneImportError`` for the first
    that cannot be imported: a mesh path that does not resolve or resolves outside the
    allowed folders (``allowed_folders``; ``extra_folders`` are the user's), an extension
    without an importer, a mesh file ``core/mesh_files.py`` refuses (each distinct file
    checked once). Creates nothing."""
    folders = allowed_folders(scene_path, extra_folders)
    planned = []
    importers = {}
    checked = set()
    resolved = {}       # the file's mesh string -> its checked path
    for index, scene_object in enumerate(description.objects):
        json_path = f"objects[{index}].mesh"
        # Objects naming one file the same way resolve the same (100,000 references to
        # one mesh: 15 s of path resolution when each was resolved again).
        mesh_path = resolved.get(scene_object.mesh)
        if mesh_path is None:
            try:
                mesh_path = scene_format.resolve_mesh_path(scene_object.mesh, scene_path, cwd,
                                                           json_path=json_path)
            except scene_format.SceneFormatError as err:
                raise SceneImportError(str(err)) from None
            _confine_mesh_path(scene_object.mesh, mesh_path, scene_path, cwd, folders,
                               json_path)
            resolved[scene_object.mesh] = mesh_path
        extension = os.path.splitext(mesh_path)[1].lower()
        if extension not in importers:
            importers[extension] = _find_importer(extension)
        importer = importers[extension]
        if importer is None:
            raise SceneImportError(
                f"{scene_path}: {json_path}: this Blender has no importer for "
                f"'{extension}' files (is the add-on for it disabled?)")
        if mesh_path not in checked:
            _check_mesh_file(mesh_path, scene_path, json_path, folders)
            checked.add(mesh_path)
        planned.append(PlannedObject(index, scene_object, mesh_path, importer))
    return planned


_EXCEPTION_LINE = re.compile(r"^[A-Za-z_][\w.]*(Error|Exception)\b")


def _importer_reason(err):
    """The useful line of an importer failure.

    ``bpy.ops`` wraps a Python importer's crash in a RuntimeError holding the whole
    traceback and a "Location:" line; the user needs only the final exception line.
    """
    lines = [line.strip() for line in str(err).splitlines()]
    lines = [line for line in lines
             if line and not line.startswith(("Location:", "File ", "^", "~"))]
    exception_lines = [line for line in lines if _EXCEPTION_LINE.match(line)]
    if exception_lines:
        return exception_lines[-1]
    for line in lines:
        if not line.startswith(("Traceback", "Error: Python: Traceback")):
            return re.sub(r"^Error:\s*", "", line)
    return type(err).__name__


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
        raise SceneImportError(one_line(
            f"{scene_path}: {planned.json_path}: Blender's {planned.importer.label} "
            f"failed on {planned.mesh_path}: {_importer_reason(failure)}")) from None
    if 'FINISHED' not in result:
        raise SceneImportError(one_line(
            f"{scene_path}: {planned.json_path}: Blender's {planned.importer.label} "
            f"could not read {planned.mesh_path}"))


def import_objects(planned, scene_path):
    """Run the planned object's importer; return the objects it created, or raise
    ``SceneImportError`` when it failed or read no faces."""
    before = {obj.as_pointer() for obj in bpy.data.objects}
    _run_importer(planned, scene_path)
    new_objects = [obj for obj in bpy.data.objects if obj.as_pointer() not in before]
    meshes = [obj for obj in new_objects if obj.type == 'MESH']
    if not meshes:
        raise SceneImportError(one_line(
            f"{scene_path}: {planned.json_path}: {planned.mesh_path} contains no mesh"))
    if not any(len(obj.data.polygons) for obj in meshes):
        # The STL and OBJ importers report success for files they read nothing from.
        raise SceneImportError(one_line(
            f"{scene_path}: {planned.json_path}: {planned.mesh_path} is not a valid mesh "
            f"file: Blender's {planned.importer.label} read no faces from it"))
    if os.path.splitext(planned.mesh_path)[1].lower() in (".gltf", ".glb"):
        _tag_course_materials(new_objects)
    return new_objects


def _tag_course_materials(objects):
    """The course's glTF files keep specular in the blue and shininess in the green channel
    of metallicRoughnessTexture (docs/scene-format.md), which Blender's importer wires to
    Metallic and Roughness; the tag makes ``materials`` read them the course's way
    (docs/materials.md). Materials made or imported any other way keep Blender's meaning."""
    for obj in objects:
        for slot in getattr(obj, "material_slots", ()):
            if slot.material is not None:
                slot.material[COURSE_SURFACE_TAG[0]] = COURSE_SURFACE_TAG[1]
