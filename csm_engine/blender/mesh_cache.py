"""Meshes on the GPU: evaluated Blender meshes -> numpy -> ``GPUMesh``, and their cache.

Owns the evaluated-mesh -> numpy -> ``GPUBatch`` path and its cache. Every corner (loop) of
a mesh is read with its own split normal and UV, so flat-shaded voxels and UV seams come
out right; corners of one vertex that agree share one GPU vertex (core/vertex_sharing.py);
triangles are grouped into one index buffer per material slot. Meshes
whose materials use a normal map also carry a tangent per corner (``corner_tangents``).
Each slot's material is read once per sync (``materials.memo_material_info``); image
textures are kept here, keyed by image name.

A mesh is uploaded once and re-uploaded only when the depsgraph says its geometry changed
(``invalidate``); a transform change uploads nothing because matrices are per-draw
constants. ``MeshCache.last_sync`` counts what each sync read, uploaded and reused, so
tests can prove it.
"""

import contextlib
import dataclasses
import zlib

import numpy as np

from ..core.vertex_sharing import share_vertices
from ..render.gpu_mesh import upload
from . import compat
from .materials import memo_material_info


def corner_tangents(mesh, uv_name, positions, normals, uvs, triangles):
    """(corners, 4) float32 tangents for a normal-mapped mesh: Blender's MikkTSpace where
    it computes them (``compat.corner_tangents``), else per-triangle UV gradients summed
    over the corners that share a vertex and a UV (n-gons), made perpendicular to each
    corner's normal. w is the bitangent's sign: B = w * cross(N, T)."""
    tangents = compat.corner_tangents(mesh, uv_name)
    if tangents is not None:
        return tangents
    count = len(positions)
    out = np.zeros((count, 4), dtype=np.float32)
    out[:, 3] = 1.0
    if not count or not len(triangles):
        return out
    p = positions[triangles].astype(np.float64)          # (T, 3 corners, xyz)
    t = uvs[triangles].astype(np.float64)                # (T, 3 corners, uv)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    scale = np.where(np.abs(det) > 1e-20, 1.0 / np.where(det == 0.0, 1.0, det), 0.0)[:, None]
    tri_t = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * scale
    tri_b = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * scale
    # Corners at one vertex with one UV share a tangent; UV seams keep theirs apart.
    key = np.concatenate([positions, uvs], axis=1)
    _, group = np.unique(key, axis=0, return_inverse=True)
    group = group.ravel()
    sum_t = np.zeros((group.max() + 1, 3))
    sum_b = np.zeros_like(sum_t)
    for corner in range(3):
        np.add.at(sum_t, group[triangles[:, corner]], tri_t)
        np.add.at(sum_b, group[triangles[:, corner]], tri_b)
    n = normals.astype(np.float64)
    tangent = sum_t[group]
    tangent -= n * np.sum(n * tangent, axis=1, keepdims=True)
    length = np.linalg.norm(tangent, axis=1, keepdims=True)
    out[:, :3] = np.where(length > 1e-12, tangent / np.maximum(length, 1e-12), 0.0)
    handed = np.sum(np.cross(n, out[:, :3]) * sum_b[group], axis=1)
    out[:, 3] = np.where(handed < 0.0, -1.0, 1.0)
    return out


def tangent_uv(materials):
    """The UV map name the mesh's tangents follow ("" = the active one), or None when no
    material of the mesh uses a normal map (then it carries no tangents at all)."""
    for info in materials:
        if info.needs_tangents:
            return info.tangent_uv or ""
    return None


def read_arrays(mesh):
    """The arrays a mesh is drawn from that cost one memory copy each (no triangulation):
    positions (V, 3), corner vertex (L,) and normal (L, 3), UVs (L, 2) or None, per-face
    material slot or None, and each corner's edge (which fixes how corners group into
    faces) or None before 4.0. ``fingerprint`` hashes them; ``extract_arrays`` adds the
    triangles."""
    corner_edges = None
    attributes = getattr(mesh, "attributes", None)
    if attributes is not None and attributes.get(".corner_edge") is not None:
        corner_edges = compat.read_array(attributes[".corner_edge"].data, "value",
                                         len(mesh.loops), np.int32)
    face_material = None
    if attributes is not None:
        material = attributes.get("material_index")
        if material is not None and material.domain == 'FACE':
            face_material = compat.read_array(material.data, "value", len(mesh.polygons),
                                              np.int32)
    elif len(mesh.polygons):
        face_material = compat.read_array(mesh.polygons, "material_index",
                                          len(mesh.polygons), np.int32)
    return {"coords": compat.vertex_positions(mesh),
            "corner_verts": compat.corner_vertex_indices(mesh),
            "normals": compat.corner_normals(mesh),
            "uvs": compat.corner_uvs(mesh),
            "face_material": face_material,
            "corner_edges": corner_edges,
            "counts": (len(mesh.vertices), len(mesh.loops), len(mesh.polygons))}


def fingerprint(raw, mesh):
    """A cheap content key of a mesh: element counts and the CRC-32 of everything it is
    drawn from (``read_arrays``). Two meshes with the same key draw the same triangles.

    NOTE: before 4.0 there is no corner-edge attribute, so the face sizes are read from
    ``polygons.loop_start`` (an element-by-element RNA read, ~80 ns a face)."""
    parts = [raw["counts"]]
    for name in ("coords", "corner_verts", "normals", "uvs", "face_material",
                 "corner_edges"):
        array = raw[name]
        parts.append(None if array is None else zlib.crc32(np.ascontiguousarray(array)))
    if raw["corner_edges"] is None and len(mesh.polygons):
        parts.append(zlib.crc32(compat.read_array(mesh.polygons, "loop_start",
                                                  len(mesh.polygons), np.int32)))
    return tuple(parts)


def extract_arrays(mesh, raw=None):
    """Numpy arrays of one evaluated mesh: per-corner position, normal, UV; triangles."""
    raw = read_arrays(mesh) if raw is None else raw
    mesh.calc_loop_triangles()
    loop_count = len(mesh.loops)
    tri_count = len(mesh.loop_triangles)

    coords = raw["coords"]
    positions = coords[raw["corner_verts"]]
    normals = raw["normals"]
    uvs = raw["uvs"]
    if uvs is None:
        uvs = np.zeros((loop_count, 2), dtype=np.float32)

    # No fast path exists for the triangulation itself (~90 ns a triangle in 5.0).
    triangles = compat.read_array(mesh.loop_triangles, "loops", tri_count * 3, np.int32)
    material_index = compat.triangle_material_indices(mesh, tri_count)
    if len(coords):
        bounds = (coords.min(axis=0), coords.max(axis=0))
    else:
        bounds = (np.zeros(3, np.float32), np.zeros(3, np.float32))
    return (np.ascontiguousarray(positions), normals, uvs, triangles.reshape(-1, 3),
            material_index, bounds)


def _upload_mesh(mesh, materials, raw=None):
    """Read and upload one evaluated mesh; tangents only when a material needs them.
    Corners of one vertex with the same normal, UV and tangent share one GPU vertex
    (``share_vertices``): a smooth mesh uploads one per vertex, not one per corner."""
    raw = read_arrays(mesh) if raw is None else raw
    positions, normals, uvs, triangles, material_index, bounds = extract_arrays(mesh, raw)
    uv_name = tangent_uv(materials)
    tangents = None
    if uv_name is not None:
        tangents = corner_tangents(mesh, uv_name, positions, normals, uvs, triangles)
    first, vertex_of_corner = share_vertices(raw["corner_verts"], len(raw["coords"]),
                                             (normals, uvs, tangents))
    return upload(positions[first], normals[first], uvs[first], vertex_of_corner[triangles],
                  material_index, bounds, materials,
                  tangents=None if tangents is None else tangents[first])


@contextlib.contextmanager
def evaluated_mesh(obj, realize):
    """The evaluated mesh of an evaluated object, for reading. A MESH object's own
    ``data`` is its evaluated mesh (modifiers applied), read in place; curves, surfaces,
    text and metaballs (and any object when ``realize``) go through ``to_mesh()``, which
    builds and copies a mesh.

    NOTE: ``realize`` is for the viewport: with GPU subdivision on, an evaluated object's
    ``data`` there can be the mesh before its last Subdivision modifier (Blender subdivides
    it on the GPU at draw time), which ``to_mesh()`` realizes. Final renders never defer
    subdivision, so they read ``data`` without the copy."""
    if obj.type == 'MESH' and not realize and obj.data is not None:
        yield obj.data
        return
    mesh = obj.to_mesh()
    try:
        yield mesh
    finally:
        obj.to_mesh_clear()


# Modifiers whose result depends only on the object's own mesh and the modifier's own
# settings (no other object, texture, vertex group, time or node tree): an object with only
# these, and no animation, drivers or shape keys, evaluates to the same mesh as long as its
# mesh data, modifier settings and the scene's Simplify settings are the same.
SELF_CONTAINED_MODIFIERS = frozenset({
    'SUBSURF', 'MIRROR', 'SOLIDIFY', 'BEVEL', 'TRIANGULATE', 'WELD', 'EDGE_SPLIT',
    'DECIMATE', 'ARRAY', 'SMOOTH', 'WEIGHTED_NORMAL', 'SCREW', 'WIREFRAME', 'SKIN',
    'REMESH'})
# NOTE: Multires is not here: its sculpted displacements live in a mesh layer that is not a
# generic attribute, so a sculpt stroke would not change ``_mesh_contents``.
_ATTRIBUTE_READS = {'FLOAT': ("value", 1, np.float32), 'INT': ("value", 1, np.int32),
                    'FLOAT_VECTOR': ("vector", 3, np.float32),
                    'FLOAT2': ("vector", 2, np.float32),
                    'FLOAT_COLOR': ("color", 4, np.float32),
                    'BYTE_COLOR': ("color", 4, np.float32),
                    'BOOLEAN': ("value", 1, bool), 'INT8': ("value", 1, np.int8),
                    'INT32_2D': ("value", 2, np.int32)}


# What an object's animation may key without changing its evaluated mesh.
_TRANSFORM_PATHS = frozenset({
    "location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle", "scale",
    "delta_location", "delta_rotation_euler", "delta_rotation_quaternion", "delta_scale",
    "hide_render", "hide_viewport"})


def _action_paths(data):
    """The data paths the action of an AnimData keys, or None when they cannot be read.
    5.0 keeps F-curves in the action's slot's channel bag (4.4+ layered actions);
    before 4.4 they are ``action.fcurves``."""
    action = data.action
    slot = getattr(data, "action_slot", None)
    if slot is not None:
        try:
            from bpy_extras.anim_utils import action_get_channelbag_for_slot
        except ImportError:
            action_get_channelbag_for_slot = None
        if action_get_channelbag_for_slot is not None:
            bag = action_get_channelbag_for_slot(action, slot)
            return [] if bag is None else [curve.data_path for curve in bag.fcurves]
    fcurves = getattr(action, "fcurves", None)
    return None if fcurves is None else [curve.data_path for curve in fcurves]


def _animated(id_block, transform_only_ok=False):
    """Whether ``id_block`` is animated (an action, drivers or NLA tracks). With
    ``transform_only_ok`` an action that keys only the transform (and visibility) does
    not count: it moves the object, it does not change its mesh."""
    data = getattr(id_block, "animation_data", None) if id_block is not None else None
    if data is None:
        return False
    if len(data.drivers) > 0 or len(getattr(data, "nla_tracks", ())) > 0:
        return True
    if data.action is None:
        return False
    if not transform_only_ok:
        return True
    paths = _action_paths(data)
    return paths is None or any(path not in _TRANSFORM_PATHS for path in paths)


def _modifier_settings(modifier):
    """A modifier's settings as a tuple, or None when it reads anything outside the
    object (another ID, a vertex group, a texture)."""
    values = [modifier.type]
    for prop in modifier.bl_rna.properties:
        name = prop.identifier
        if name in ("rna_type", "name", "show_viewport", "show_in_editmode",
                    "show_on_cage", "show_expanded", "is_active", "is_override_data",
                    "persistent_uid", "use_pin_to_last", "execution_time", "ui_expand_flag"):
            continue
        value = getattr(modifier, name, None)
        if prop.type in {'POINTER', 'COLLECTION'}:
            if value is not None and (prop.type == 'POINTER' or len(value)):
                return None
            continue
        if name.startswith("vertex_group") and value:
            return None
        values.append(tuple(value) if hasattr(value, "__len__") and
                      not isinstance(value, str) else value)
    return tuple(values)


def _mesh_contents(mesh):
    """CRC-32 of every generic attribute of an original mesh (positions, corners, edges,
    UVs, materials, sharpness, creases, bevel weights...): no evaluation, one copy each.
    None when part of what the mesh evaluates to is kept outside generic attributes, so
    the mesh must be read at every render instead.

    NOTE: before 4.0 positions, creases, bevel weights and smooth flags are not generic
    attributes (3.x lists only UVs, colours and selection), and before 5.0 custom normals
    are a layer of their own; 4.0 still has the mesh's Auto Smooth settings."""
    attributes = mesh.attributes
    if attributes.get("position") is None:
        return None
    if getattr(mesh, "has_custom_normals", False) and \
            attributes.get("custom_normal") is None:
        return None
    parts = [len(mesh.vertices), len(mesh.edges), len(mesh.loops), len(mesh.polygons),
             getattr(mesh, "use_auto_smooth", None), getattr(mesh, "auto_smooth_angle", None)]
    for attribute in attributes:
        read = _ATTRIBUTE_READS.get(attribute.data_type)
        if read is None:
            return None
        prop, width, dtype = read
        out = np.empty(len(attribute.data) * width, dtype=dtype)
        if len(out):
            attribute.data.foreach_get(prop, out)
        parts.append((attribute.name, attribute.domain, zlib.crc32(out)))
    return tuple(parts)


def recipe(obj, simplify):
    """What an evaluated MESH object's final-render mesh is made from, when that can be
    known without evaluating it: (mesh contents, modifier settings, Simplify settings).
    None when the result may depend on anything else (time, other objects, shape keys,
    drivers, geometry nodes...): such objects are read and hashed at every render."""
    original = obj.original if obj.original is not None else obj
    # An instanced object can come back from the depsgraph with a plain ID as its
    # original (seen for a collection instance's objects): read and hash it.
    mesh = getattr(original, "data", None)
    if getattr(original, "type", None) != 'MESH' or mesh is None or \
            getattr(mesh, "attributes", None) is None:
        return None
    if getattr(mesh, "shape_keys", None) is not None or \
            _animated(original, transform_only_ok=True) or \
            _animated(mesh) or getattr(original, "particle_systems", None):
        return None
    modifiers = []
    for modifier in original.modifiers:
        if not modifier.show_render:
            continue
        if modifier.type not in SELF_CONTAINED_MODIFIERS:
            return None
        settings = _modifier_settings(modifier)
        if settings is None:
            return None
        modifiers.append(settings)
    contents = _mesh_contents(mesh)
    if contents is None:
        return None
    # No mesh identity in it: two meshes with the same contents and the same modifiers
    # evaluate to the same mesh (Shift+D copies), so one read serves both.
    return (contents, tuple(modifiers), simplify)


class MeshCache:
    """GPU meshes keyed by original object name, plus image textures keyed by image name.

    Two ways to know what changed:

    - the viewport's (``check_contents=False``): ``view_update`` hands the depsgraph's
      updates to ``invalidate`` and ``sync`` re-reads only those meshes;
    - final renders' (``check_contents=True``): each render has a new depsgraph and its
      updates say nothing about the previous render, so ``sync`` reads every mesh's cheap
      arrays (``read_arrays``, no ``to_mesh``), hashes them (``fingerprint``) and uploads
      only meshes whose hash it has not seen. GPU geometry is keyed by that hash, so
      objects with identical meshes (linked duplicates, instances) share one upload.
    """

    def __init__(self, check_contents=False, realize=True):
        self.check_contents = check_contents
        self.realize = realize
        self.meshes = {}
        self.textures = {}
        self._geometry = {}       # check_contents: fingerprint -> GPUMesh
        self._recipes = {}        # check_contents: (recipe, slots, tangents) -> key
        self._older = {}          # check_contents: the previous sync's unused geometry
        self._dirty = set()
        self._materials_dirty = False
        self.last_sync = {"read": 0, "uploaded": 0, "reused": 0}

    def invalidate(self, keys=None, materials=False):
        """Mark meshes for re-upload (None = all); ``materials`` re-reads material nodes."""
        if keys is None:
            self._dirty = set(self.meshes)
        else:
            self._dirty.update(keys)
        self._materials_dirty = self._materials_dirty or materials

    def clear(self):
        """Drop every GPU object. Call it where the GPU context that draws is current."""
        self.meshes.clear()
        self._geometry.clear()
        self._older.clear()
        self._recipes.clear()
        self.textures.clear()

    def sync(self, mesh_sources, simplify=None):
        """Make sure every mesh in ``mesh_sources`` (key -> evaluated object) is uploaded.
        ``simplify``: the scene's Simplify settings (they change what modifiers make)."""
        if self.check_contents:
            self._sync_by_contents(mesh_sources, simplify)
            return
        for key in [k for k in self.meshes if k not in mesh_sources]:
            del self.meshes[key]   # deleted objects: drop their buffers
        stats = {"read": 0, "uploaded": 0, "reused": 0}
        memo = {}
        for key, obj in mesh_sources.items():
            materials = None
            if key in self.meshes and key not in self._dirty:
                if not self._materials_dirty:
                    stats["reused"] += 1
                    continue
                materials = [memo_material_info(memo, slot.material)
                             for slot in obj.material_slots]
                # A normal map added or removed changes the vertex format: read it again.
                if (tangent_uv(materials) is not None) == self.meshes[key].has_tangents:
                    self.meshes[key].materials = materials
                    stats["reused"] += 1
                    continue
            with evaluated_mesh(obj, self.realize) as mesh:
                if mesh is None:
                    continue
                if materials is None:
                    materials = [memo_material_info(memo, slot.material)
                                 for slot in obj.material_slots]
                self.meshes[key] = _upload_mesh(mesh, materials)
                stats["read"] += 1
                stats["uploaded"] += 1
        self._dirty.clear()
        self._materials_dirty = False
        self.last_sync = stats

    def _sync_by_contents(self, mesh_sources, simplify=None):
        # Images may have been edited since the last render; Blender keeps each image's GPU
        # texture itself, so asking again is cheap.
        self.textures.clear()
        meshes, geometry, recipes = {}, {}, {}
        by_pointer = {}           # one depsgraph: the same evaluated mesh is read once
        stats = {"read": 0, "uploaded": 0, "reused": 0, "unread": 0}
        memo = {}
        for key, obj in mesh_sources.items():
            materials = [memo_material_info(memo, slot.material)
                         for slot in obj.material_slots]
            # Normal-mapped meshes carry tangents (along one UV map), the others none: part
            # of what makes two meshes' GPU geometry the same.
            tangents = tangent_uv(materials)
            # NOTE: reading an evaluated mesh makes Blender finish evaluating it (a
            # Subdivision modifier runs when ``data`` is first read: ~80 ms a Suzanne at
            # level 2 here), so a mesh whose inputs are unchanged is not read at all.
            made_of = recipe(obj, simplify) if not self.realize else None
            made_key = (made_of, len(materials), tangents) if made_of is not None else None
            # The same inputs make the same mesh: read once in this render (Shift+D copies,
            # objects sharing a mesh) and not at all when the render before read it.
            key_hash = None if made_key is None else \
                recipes.get(made_key) or self._recipes.get(made_key)
            known = None if key_hash is None else \
                geometry.get(key_hash) or self._geometry.get(key_hash)
            if known is not None:
                geometry[key_hash] = known
                recipes[made_key] = key_hash
                stats["unread"] += 1
                meshes[key] = dataclasses.replace(known, materials=materials)
                continue
            # Only a MESH object's own evaluated data has a stable address within one
            # depsgraph; a to_mesh() copy is freed at once and its address reused.
            in_place = obj.type == 'MESH' and not self.realize
            with evaluated_mesh(obj, self.realize) as mesh:
                if mesh is None:
                    continue
                # Triangles are split into one index buffer per material slot, so the slot
                # count is part of what makes two meshes' GPU geometry the same.
                read_once = (mesh.as_pointer(), len(materials), tangents) if in_place else None
                known = by_pointer.get(read_once) if read_once is not None else None
                if known is None:
                    raw = read_arrays(mesh)
                    stats["read"] += 1
                    key_hash = (fingerprint(raw, mesh), len(materials), tangents)
                    known = geometry.get(key_hash) or self._geometry.get(key_hash) or \
                        self._older.get(key_hash)
                    if known is None:
                        known = _upload_mesh(mesh, materials, raw)
                        stats["uploaded"] += 1
                    else:
                        stats["reused"] += 1
                    geometry[key_hash] = known
                    if read_once is not None:
                        by_pointer[read_once] = (known, key_hash)
                else:
                    known, key_hash = known
                    stats["reused"] += 1
                if made_key is not None:
                    recipes[made_key] = key_hash
            meshes[key] = dataclasses.replace(known, materials=materials)
        # The render before's meshes stay one more render (an edit undone, an animation
        # going back and forth); anything older is dropped here, inside the render.
        self._older = {k: v for k, v in self._geometry.items() if k not in geometry}
        self._geometry = geometry
        self._recipes = recipes
        self.meshes = meshes
        self._dirty.clear()
        self._materials_dirty = False
        self.last_sync = stats

    def texture(self, image):
        """GPU texture of a Blender image (Blender's own filtering and colour space)."""
        import gpu
        key = image.name
        texture = self.textures.get(key)
        if texture is None:
            try:
                texture = gpu.texture.from_image(image)
            except Exception as error:   # missing file on disk: draw with the colour factor
                print(f"CSM: image '{image.name}' could not be loaded ({error})")
                texture = False
            self.textures[key] = texture
        return texture or None
