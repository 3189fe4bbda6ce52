"""Turns a parsed scene file into Blender objects, transactionally.

Owns the Blender side of scene import as one transaction: one collection per imported file
(named after the file, remembering its source in the custom property ``csm_source``), built
in order (mesh files, sun, point lights, camera, World) and selected. Parsing and
validation live in ``core/scene_format``; axis and transform conventions in
``core/conventions``; finding and running Blender's importers, and the checks made before
one runs, in ``mesh_importers``; the objects themselves in ``object_builders``; what is
recorded and put back in ``import_transaction``.

Everything that can be checked without Blender (the JSON, every mesh path, every mesh file
and the files it references, the importers) is checked before any datablock is created.
If an importer still fails, every datablock created since the start is removed and the
scene camera, active collection and selection are restored, so the scene is exactly as it
was. What importers change outside their datablocks (scene custom properties, add-on
preferences) is put back after every import, failed or not. Every failure is one
``SceneImportError`` with a one-line message; importers' own output (progress, tracebacks)
is captured and shown only with ``CSM_DEBUG`` set.

Each distinct mesh file is imported once. A file the scene references once becomes its
objects under an empty carrying the scene object's transform; a file referenced several
times becomes one copies object instancing the file's objects at every reference
(``mesh_copies``): one mesh, however many copies.

Re-importing a file replaces its previous import, but only once the new import has
succeeded. "Replace current scene" (``replace=True``) empties the scene the way File > New
starts one (``import_transaction.clear_scene``), also only once the new import has
succeeded, so a failed import leaves the old scene exactly as it was.
"""

import collections
import contextlib
import os

import bpy
import numpy as np

from ..core import conventions, scene_format
from . import mesh_copies, mesh_importers, object_builders, preferences
from .import_transaction import (OutsideChanges, SceneImportError, SceneState,
                                 clear_scene, created_since, data_snapshot, layer_collection_for,
                                 one_line, remove_datablocks, remove_import,
                                 take_back_names, walk_collections)

__all__ = ["SceneImportError", "import_scene_file", "reload_scene", "imported_collections"]


def _same_file(a, b):
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.normcase(os.path.abspath(a)) == os.path.normcase(os.path.abspath(b))


def imported_collections(scene):
    """Collections in ``scene`` made by ``import_scene_file``, oldest import first."""
    found = [c for c in walk_collections(scene.collection)
             if c is not scene.collection and "csm_source" in c]
    return sorted(found, key=lambda c: int(c.get("csm_import_order", 0)))


def _override_for(scene):
    if scene == bpy.context.scene:
        return contextlib.nullcontext(), bpy.context.view_layer
    view_layer = scene.view_layers[0]
    return bpy.context.temp_override(scene=scene, view_layer=view_layer), view_layer


def _build(description, planned, scene, view_layer, scene_path, name, replace=False):
    """The import's collection with everything in it, linked to ``scene`` and selected;
    raises on the first failure, leaving the rollback to ``import_scene_file``."""
    collection = bpy.data.collections.new(name)
    scene.collection.children.link(collection)
    view_layer.active_layer_collection = layer_collection_for(view_layer, collection)
    for obj in view_layer.objects:
        obj.select_set(False, view_layer=view_layer)

    parents = []
    corners_by_file = {}
    references = collections.Counter(item.mesh_path for item in planned)
    copies = {}         # mesh path -> (source collection, its scene objects)
    for item in planned:
        if item.mesh_path in corners_by_file:
            copies[item.mesh_path][1].append(item)
            continue
        into = collection
        if references[item.mesh_path] > 1:
            into = bpy.data.collections.new(f"{object_builders.mesh_stem(item)} (source)")
            collection.children.link(into)
            copies[item.mesh_path] = (into, [item])
        parent, objects = object_builders.add_mesh_file(item, into, scene_path,
                                                        placed=into is collection)
        view_layer.update()     # while the scene is small: only for distinct files
        corners_by_file[item.mesh_path] = object_builders.corners_in_parent(parent, objects)
        if into is collection:
            parents.append(parent)
    for source, items in copies.values():
        mesh_copies.exclude_from_view_layers(scene, source)
        parents.append(mesh_copies.add_copies(
            items, source, collection,
            f"{object_builders.mesh_stem(items[0])} ({len(items)} copies)"))
    bounds = object_builders.placed_bounds(planned, corners_by_file)
    if bounds is None:
        bounds = (np.full(3, -1.0), np.full(3, 1.0))

    if description.directional_light is not None:
        object_builders.add_sun(description.directional_light, collection, bounds, "Sun")
        collection["csm_sun_direction"] = [float(v) for v in conventions.direction_zup_from_yup(
            description.directional_light.direction.as_tuple())]
    for index, light in enumerate(description.lights):
        object_builders.add_point_light(light, collection, f"Point light {index + 1}")
    if description.camera is not None:
        camera = object_builders.add_camera(description.camera, collection, "Camera")
    else:
        camera = object_builders.add_default_camera(collection, bounds, "Camera (default view)")
    scene.camera = camera
    object_builders.ensure_world(scene, replace=replace)

    in_layer = {obj.as_pointer() for obj in view_layer.objects}
    # Not the source collections' objects: they are out of the view layer.
    for obj in collection.objects:
        if obj.as_pointer() in in_layer:
            obj.select_set(True, view_layer=view_layer)
    view_layer.objects.active = parents[0] if parents else camera
    # Callers (the renderer, tests) read matrix_world right away.
    view_layer.update()
    return collection


def import_scene_file(path, scene=None, replace=False, allowed_folders=()):
    """Import the scene file at ``path`` into ``scene`` (default: the context scene).

    Files are read only from the scene file's folder tree, each mesh file's folder, the
    Allowed Folders preference and ``allowed_folders`` (the CLI's ``--allow-folder``).

    ``replace``: the import becomes the scene's only content (objects, collections, World;
    see ``clear_scene``); otherwise it is added, replacing only an earlier import of the
    same file. Returns the new collection. Raises only ``SceneImportError``; then nothing
    changed.
    """
    scene = scene if scene is not None else bpy.context.scene
    scene_path = os.path.abspath(os.fspath(path))
    try:
        description = scene_format.load_scene(scene_path)
    except scene_format.SceneFormatError as err:
        raise SceneImportError(str(err)) from None
    extra_folders = [*preferences.chosen_allowed_folders(), *allowed_folders]
    planned = mesh_importers.plan(scene_path, description, os.getcwd(), extra_folders)

    override, view_layer = _override_for(scene)
    previous = [c for c in imported_collections(scene) if _same_file(c["csm_source"], scene_path)]
    order = max((int(c.get("csm_import_order", 0)) for c in imported_collections(scene)),
                default=0) + 1
    name = os.path.splitext(os.path.basename(scene_path))[0]

    state = SceneState(scene, view_layer)
    outside = OutsideChanges((scene, bpy.context.scene))
    snapshot = data_snapshot()
    try:
        with override:
            collection = _build(description, planned, scene, view_layer, scene_path, name,
                                replace)
    except BaseException as err:
        remove_datablocks(created_since(snapshot))
        state.restore()
        outside.restore()
        if isinstance(err, SceneImportError):
            raise
        if not isinstance(err, Exception):
            raise
        raise SceneImportError(one_line(
            f"{scene_path}: import failed: {type(err).__name__}: {err}")) from err

    outside.restore()
    collection["csm_source"] = scene_path
    collection["csm_import_order"] = order
    created = created_since(snapshot)
    if replace:
        removed_names, removed_pointers = clear_scene(scene, collection, state.world)
    else:
        removed_pointers = {c.as_pointer() for c in previous}
        removed_names = {}
        for old in previous:
            for kind, names in remove_import(old).items():
                removed_names.setdefault(kind, set()).update(names)
    take_back_names(created, removed_names)
    state.restore_active_collection(removed_pointers)
    return collection


def reload_scene(collection):
    """Import the collection's source file again, replacing the collection."""
    source = collection.get("csm_source") if collection is not None else None
    if not source:
        name = collection.name if collection is not None else "None"
        raise SceneImportError(f"collection '{name}' was not imported from a CSM scene file")
    scene = bpy.context.scene
    for candidate in bpy.data.scenes:
        if any(c == collection for c in walk_collections(candidate.collection)):
            scene = candidate
            break
    return import_scene_file(source, scene)
