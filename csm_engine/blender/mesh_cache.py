"""Mesh and material data on the GPU.

Owns the evaluated-mesh -> numpy -> ``GPUBatch`` path and its cache. Every corner (loop) of
a mesh becomes one vertex (position, split normal, UV), so flat-shaded voxels and UV seams
come out right; triangles are grouped into one index buffer per material slot.

A mesh is uploaded once and re-uploaded only when the depsgraph says its geometry changed
(``invalidate``); a transform change uploads nothing because matrices are per-draw
constants. ``UPLOADS`` counts uploads so tests can prove it.
"""

import contextlib
import dataclasses
import zlib

import numpy as np

from ..render.gpu_mesh import MaterialInfo, upload
from . import compat

def _find_input(node, *names):
    for name in names:
        socket = node.inputs.get(name)
        if socket is not None:
            return socket
    return None


def _upstream_image(socket, depth=0):
    """The image texture feeding a socket, through a few pass-through nodes."""
    if socket is None or not socket.is_linked or depth > 4:
        return None, None
    link = socket.links[0]
    node = link.from_node
    if node.type == 'TEX_IMAGE':
        return node.image, link.from_socket.name
    for candidate in node.inputs:
        if candidate.is_linked and candidate.type in {'RGBA', 'VALUE', 'SHADER'}:
            image, out = _upstream_image(candidate, depth + 1)
            if image is not None:
                return image, out
    return None, None


def _alpha_cutoff(material, alpha_socket):
    """Alpha-mask threshold of a material, in the ways 3.4 .. 5.0 and glTF express it."""
    method = getattr(material, "blend_method", 'OPAQUE')
    if method == 'CLIP':
        return float(getattr(material, "alpha_threshold", 0.5))
    if alpha_socket is None or not alpha_socket.is_linked:
        return 0.0
    # glTF importer (4.2+) expresses a mask as a Math node (e.g. 1 - (alpha < cutoff)).
    node = alpha_socket.links[0].from_node
    for _ in range(3):
        if node.type == 'MATH':
            for socket in node.inputs:
                if not socket.is_linked and 0.0 < socket.default_value < 1.0:
                    return float(socket.default_value)
            linked = [s for s in node.inputs if s.is_linked]
            if not linked:
                break
            node = linked[0].links[0].from_node
        else:
            break
    if method in {'BLEND', 'HASHED'} or alpha_socket.is_linked:
        return 0.5
    return 0.0


def material_info(material):
    """Principled BSDF -> Blinn-Phong parameters (base colour/texture, shininess, mask)."""
    info = MaterialInfo()
    if material is None:
        return info
    info.base_color = tuple(material.diffuse_color)
    if not (material.use_nodes and material.node_tree):
        info.shininess = _shininess(getattr(material, "roughness", 0.5))
        return info
    bsdf = next((n for n in material.node_tree.nodes if n.type == 'BSDF_PRINCIPLED'), None)
    if bsdf is None:
        return info
    base = _find_input(bsdf, "Base Color")
    info.base_color = tuple(base.default_value)
    image, _ = _upstream_image(base)
    if image is not None:
        info.image = image
        info.base_color = (1.0, 1.0, 1.0, 1.0)
    roughness = _find_input(bsdf, "Roughness")
    info.shininess = _shininess(roughness.default_value if roughness is not None else 0.5)
    specular = _find_input(bsdf, *compat.PRINCIPLED_SPECULAR_INPUTS)
    level = float(specular.default_value) if specular is not None and \
        not specular.is_linked else 0.5
    # A fully rough surface has no visible highlight; without this, roughness 1 (glTF's
    # default) gives exponent 1 and washes everything white.
    r = roughness.default_value if roughness is not None else 0.5
    info.specular = level * (1.0 - min(max(r, 0.0), 1.0)) ** 2
    alpha = _find_input(bsdf, "Alpha")
    if alpha is not None and not alpha.is_linked:
        info.base_color = info.base_color[:3] + (float(alpha.default_value),)
    info.alpha_cutoff = _alpha_cutoff(material, alpha)
    return info


def _shininess(roughness):
    """Map roughness to a Blinn-Phong exponent (Beckmann-style 2/r^4 - 2), clamped."""
    r = min(max(float(roughness), 0.02), 1.0)
    return float(min(max(2.0 / (r ** 4) - 2.0, 1.0), 4096.0))


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
    'REMESH', 'MULTIRES'})
_ATTRIBUTE_READS = {'FLOAT': ("value", 1, np.float32), 'INT': ("value", 1, np.int32),
                    'FLOAT_VECTOR': ("vector", 3, np.float32),
                    'FLOAT2': ("vector", 2, np.float32),
                    'FLOAT_COLOR': ("color", 4, np.float32),
                    'BYTE_COLOR': ("color", 4, np.float32),
                    'BOOLEAN': ("value", 1, bool), 'INT8': ("value", 1, np.int8),
                    'INT32_2D': ("value", 2, np.int32)}


def _animated(id_block):
    data = getattr(id_block, "animation_data", None) if id_block is not None else None
    return data is not None and (data.action is not None or len(data.drivers) > 0
                                 or len(getattr(data, "nla_tracks", ())) > 0)


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
    UVs, materials, sharpness, custom normals...): no evaluation, one copy each."""
    parts = [len(mesh.vertices), len(mesh.edges), len(mesh.loops), len(mesh.polygons)]
    for attribute in mesh.attributes:
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
    mesh = original.data
    if original.type != 'MESH' or mesh is None or getattr(mesh, "attributes", None) is None:
        return None
    if getattr(mesh, "shape_keys", None) is not None or _animated(original) or \
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
    return (mesh.as_pointer(), contents, tuple(modifiers), simplify)


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
        self._recipes = {}        # check_contents: key -> (recipe, fingerprint)
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
        for key, obj in mesh_sources.items():
            if key in self.meshes and key not in self._dirty:
                if self._materials_dirty:
                    self.meshes[key].materials = [
                        material_info(slot.material) for slot in obj.material_slots]
                stats["reused"] += 1
                continue
            with evaluated_mesh(obj, self.realize) as mesh:
                if mesh is None:
                    continue
                arrays = extract_arrays(mesh)
                materials = [material_info(slot.material) for slot in obj.material_slots]
                self.meshes[key] = upload(*arrays, materials)
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
        for key, obj in mesh_sources.items():
            materials = [material_info(slot.material) for slot in obj.material_slots]
            # NOTE: reading an evaluated mesh makes Blender finish evaluating it (a
            # Subdivision modifier runs when ``data`` is first read: ~80 ms a Suzanne at
            # level 2 here), so a mesh whose inputs are unchanged is not read at all.
            made_of = recipe(obj, simplify) if not self.realize else None
            previous = self._recipes.get(key)
            if made_of is not None and previous is not None and previous[0] == made_of \
                    and previous[1] in self._geometry:
                known = self._geometry[previous[1]]
                geometry[previous[1]] = known
                recipes[key] = previous
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
                memo = (mesh.as_pointer(), len(materials)) if in_place else None
                known = by_pointer.get(memo) if memo is not None else None
                if known is None:
                    raw = read_arrays(mesh)
                    stats["read"] += 1
                    key_hash = (fingerprint(raw, mesh), len(materials))
                    known = geometry.get(key_hash) or self._geometry.get(key_hash) or \
                        self._older.get(key_hash)
                    if known is None:
                        known = upload(*extract_arrays(mesh, raw), materials)
                        stats["uploaded"] += 1
                    else:
                        stats["reused"] += 1
                    geometry[key_hash] = known
                    if memo is not None:
                        by_pointer[memo] = (known, key_hash)
                else:
                    known, key_hash = known
                    stats["reused"] += 1
                if made_of is not None:
                    recipes[key] = (made_of, key_hash)
            meshes[key] = dataclasses.replace(known, materials=materials)
        # Geometry no object uses any more is dropped here, inside the render.
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
