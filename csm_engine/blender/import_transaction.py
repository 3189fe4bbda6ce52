"""What a scene import changes in Blender, and how to take it back.

Owns the import's transaction bookkeeping: ``SceneImportError`` (every failure of an
import, one line), the record of which datablocks existed before (``data_snapshot`` /
``created_since``) and their removal on failure (``remove_datablocks``), the scene state an
import may change outside its datablocks (``SceneState``: camera, World, active collection,
selection; ``OutsideChanges``: scene custom properties and add-on preferences that
importers write), replacing an earlier import of the same file (``remove_import``,
``take_back_names``) and emptying the scene for "Replace current scene" (``clear_scene``).
``scene_builder`` runs the transaction; nothing here creates objects.
"""

import contextlib
import re

import bpy

# Datablock kinds an importer may create; all are compared before/after for rollback.
DATA_KINDS = ("objects", "collections", "cameras", "lights", "meshes", "curves",
              "armatures", "lattices", "materials", "node_groups", "textures", "images",
              "actions", "worlds")


class SceneImportError(Exception):
    """A scene could not be imported; ``str()`` is one line naming the file and reason."""


def one_line(text):
    return " ".join(str(text).split())


def data_snapshot():
    return {kind: {block.as_pointer() for block in getattr(bpy.data, kind)}
            for kind in DATA_KINDS if hasattr(bpy.data, kind)}


def created_since(snapshot):
    created = {}
    for kind, before in snapshot.items():
        created[kind] = [block for block in getattr(bpy.data, kind)
                         if block.as_pointer() not in before]
    return created


def walk_collections(root):
    yield root
    for child in root.children:
        yield from walk_collections(child)


def _walk_layer_collections(layer_collection):
    yield layer_collection
    for child in layer_collection.children:
        yield from _walk_layer_collections(child)


def layer_collection_for(view_layer, collection):
    for layer_collection in _walk_layer_collections(view_layer.layer_collection):
        if layer_collection.collection == collection:
            return layer_collection
    return None


class SceneState:
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
            target = layer_collection_for(self.view_layer, self.active_collection)
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


class OutsideChanges:
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


def remove_datablocks(created):
    """Remove the given datablocks; objects and collections first so data loses users."""
    first = [block for kind in ("objects", "collections") for block in created.get(kind, [])]
    rest = [block for kind in DATA_KINDS if kind not in ("objects", "collections")
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


def _used_data(objects):
    """What ``objects`` use that may lose its last user with them: their data, materials,
    and the materials' node groups and images, each list without repeats."""
    data = [obj.data for obj in objects if obj.data is not None]
    materials, node_groups, images = [], [], []
    for obj in objects:
        # A Geometry Nodes modifier's group (the copies of a mesh file, ``mesh_copies``).
        for modifier in obj.modifiers:
            group = getattr(modifier, "node_group", None)
            if group is not None and group not in node_groups:
                node_groups.append(group)
        for slot in obj.material_slots:
            if slot.material is not None and slot.material not in materials:
                materials.append(slot.material)
    for block in data:
        for material in getattr(block, "materials", []):
            if material is not None and material not in materials:
                materials.append(material)
    for material in materials:
        _material_dependencies(material, node_groups, images)
    return data, materials, node_groups, images


def _remove(blocks, removed_names):
    for block in blocks:
        removed_names.setdefault(type(block).__name__, set()).add(block.name)
    if blocks:
        bpy.data.batch_remove(blocks)


def _remove_unused(groups, removed_names):
    """Remove the blocks of ``groups`` (in order: users before what they use) that nothing
    uses any more; blocks still in use (a mesh the user copied elsewhere) stay."""
    for group in groups:
        seen = set()
        unused = []
        for block in group:
            if block.as_pointer() in seen:
                continue
            seen.add(block.as_pointer())
            if block.users == 0:
                unused.append(block)
        _remove(unused, removed_names)


def remove_import(collection):
    """Delete an earlier import: its collection tree, objects and now-unused data.

    Data (meshes, materials, images, ...) goes only if nothing else uses it any more, so
    objects the user copied out of the collection keep working.
    """
    collections = list(walk_collections(collection))
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
    used = _used_data(only_here)
    for obj in objects:
        if obj.as_pointer() not in only_here_pointers:
            for c in collections:
                if obj.name in c.objects:
                    c.objects.unlink(obj)
    _remove(only_here + collections, removed_names)
    _remove_unused(used, removed_names)
    return removed_names


def clear_scene(scene, keep, old_world=None):
    """Empty ``scene`` for "Replace current scene", keeping only the collection ``keep``.

    What File > New leaves out of a scene goes: every object and collection of the scene
    (the startup Cube, Light and Camera, earlier imports, the user's own objects, in
    excluded and hidden collections too), then the data and materials nothing uses any
    more, and ``old_world`` once nothing uses it. Objects and collections another scene
    also shows are only unlinked from this one, so the other scene keeps them. Settings,
    render options and other scenes stay. Returns the removed datablocks' names by type
    and the pointers of the removed collections.
    """
    keep_collections = {c.as_pointer() for c in walk_collections(keep)}
    keep_objects = {obj.as_pointer() for obj in keep.all_objects}
    shared_collections, shared_objects = set(), set()
    for other in bpy.data.scenes:
        if other == scene:
            continue
        shared_collections.update(c.as_pointer() for c in walk_collections(other.collection))
        shared_objects.update(obj.as_pointer() for obj in other.collection.all_objects)

    collections = []
    seen = set(keep_collections)
    # A collection another scene shows stays, with everything below it.
    stack = list(scene.collection.children)
    while stack:
        child = stack.pop()
        pointer = child.as_pointer()
        if pointer in seen or pointer in shared_collections:
            continue
        seen.add(pointer)
        collections.append(child)
        stack.extend(child.children)
    for child in list(scene.collection.children):
        if child.as_pointer() in shared_collections:
            scene.collection.children.unlink(child)
    for obj in list(scene.collection.objects):
        if obj.as_pointer() in shared_objects:
            scene.collection.objects.unlink(obj)

    objects = [obj for obj in scene.collection.all_objects
               if obj.as_pointer() not in keep_objects
               and obj.as_pointer() not in shared_objects]
    removed_pointers = {c.as_pointer() for c in collections}
    removed_names = {}
    used = _used_data(objects)
    _remove(objects + collections, removed_names)
    _remove_unused(used, removed_names)
    if old_world is not None and scene.world != old_world:
        _remove_unused([[old_world]], removed_names)
    return removed_names, removed_pointers


_NUMBERED = re.compile(r"^(.*)\.\d{3,}$")


def take_back_names(created, removed_names):
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
