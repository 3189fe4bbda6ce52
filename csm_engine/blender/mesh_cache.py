"""Mesh and material data on the GPU.

Owns the evaluated-mesh -> numpy -> ``GPUBatch`` path and its cache. Every corner (loop) of
a mesh becomes one vertex (position, split normal, UV), so flat-shaded voxels and UV seams
come out right; triangles are grouped into one index buffer per material slot.

A mesh is uploaded once and re-uploaded only when the depsgraph says its geometry changed
(``invalidate``); a transform change uploads nothing because matrices are per-draw
constants. ``UPLOADS`` counts uploads so tests can prove it.
"""

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


def extract_arrays(mesh):
    """Numpy arrays of one evaluated mesh: per-corner position, normal, UV; triangles."""
    mesh.calc_loop_triangles()
    loop_count = len(mesh.loops)
    tri_count = len(mesh.loop_triangles)

    coords = compat.vertex_positions(mesh)
    positions = coords[compat.corner_vertex_indices(mesh)]
    normals = compat.corner_normals(mesh)
    uvs = compat.corner_uvs(mesh)
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


class MeshCache:
    """GPU meshes keyed by original object name, plus image textures keyed by image name."""

    def __init__(self):
        self.meshes = {}
        self.textures = {}
        self._dirty = set()
        self._materials_dirty = False

    def invalidate(self, keys=None, materials=False):
        """Mark meshes for re-upload (None = all); ``materials`` re-reads material nodes."""
        if keys is None:
            self._dirty = set(self.meshes)
        else:
            self._dirty.update(keys)
        self._materials_dirty = self._materials_dirty or materials

    def sync(self, mesh_sources):
        """Make sure every mesh in ``mesh_sources`` (key -> evaluated object) is uploaded."""
        for key in [k for k in self.meshes if k not in mesh_sources]:
            del self.meshes[key]   # deleted objects: drop their buffers
        for key, obj in mesh_sources.items():
            if key in self.meshes and key not in self._dirty:
                if self._materials_dirty:
                    self.meshes[key].materials = [
                        material_info(slot.material) for slot in obj.material_slots]
                continue
            mesh = obj.to_mesh()
            try:
                if mesh is None:
                    continue
                arrays = extract_arrays(mesh)
                materials = [material_info(slot.material) for slot in obj.material_slots]
                self.meshes[key] = upload(*arrays, materials)
            finally:
                obj.to_mesh_clear()
        self._dirty.clear()
        self._materials_dirty = False

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
