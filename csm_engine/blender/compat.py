"""Every Blender-version difference the add-on works around, in one place (3.4 .. 5.x).

Owns the shims: reading mesh data through generic attributes where they exist (3.5+, one
memory copy) and through the older per-element paths before; corner normals (4.1+) versus
``calc_normals_split``; RenderResult passes that take a flat array (4.x+) or rows (3.4),
and render pass names (spelled out in 5.0, short before); the Principled BSDF's model (v1
before 4.0) and its renamed specular and emission inputs; material alpha, shadow and
culling settings (``blend_method``/``shadow_method`` up to 4.1,
``surface_render_method``/``use_transparent_shadow`` from 4.2); MikkTSpace tangents; the
glTF importer of 3.4/3.5 that needs ``np.bool``; node groups' sockets (``interface`` from
4.0); whether a material or World uses its nodes (always from 5.0); an object's Shadow
Terminator Geometry Offset (Object in 5.0, the Cycles add-on's ``object.cycles``
before); and the exit that pip bpy 4.2 needs to keep a process's exit code. Callers ask
for what they need and never test versions themselves.
"""

import os
import sys

import bpy
import numpy as np

from ..core.frame import DEFAULT_TERMINATOR_OFFSET

# Principled BSDF specular: "Specular IOR Level" in 4.0+, "Specular" before.
PRINCIPLED_SPECULAR_INPUTS = ("Specular IOR Level", "Specular")
# Principled BSDF emission colour: "Emission Color" in 4.0+, "Emission" before.
PRINCIPLED_EMISSION_INPUTS = ("Emission Color", "Emission")
# The Principled BSDF model this Blender's Cycles evaluates: v1 (Disney-style, Burley
# diffuse, no layering) before 4.0, v2 from 4.0 (brdf.glsl evaluates both; the shaders
# get PRINCIPLED_V1 defined on a v1 host).
PRINCIPLED_V1 = bpy.app.version < (4, 0, 0)
# 5.0 renders every material and World with its nodes and deprecates ``use_nodes``.
ALWAYS_NODES = bpy.app.version >= (5, 0, 0)
# Separate RGB (3.4 .. 4.x, outputs R/G/B) and Separate Color (3.3+, Red/Green/Blue).
SEPARATE_NODE_TYPES = frozenset({'SEPARATE_COLOR', 'SEPRGB'})


# -- materials ----------------------------------------------------------------------------
def material_alpha_mode(material):
    """How EEVEE of this version draws a material's alpha: 'OPAQUE', 'CLIP' or 'HASHED'.

    NOTE: 4.2+ has no opaque or clip mode: every surface is Dithered (alpha hashed) or
    Blended, and ``blend_method`` reads HASHED or BLEND (setting CLIP gives HASHED); the
    glTF importer expresses masks with Math nodes instead (materials.py finds their cutoff).
    3.4 .. 4.1: ``blend_method`` OPAQUE ignores alpha, CLIP cuts out at alpha_threshold,
    HASHED and BLEND (drawn hashed here) use it."""
    method = getattr(material, "blend_method", 'OPAQUE')
    if hasattr(material, "surface_render_method"):          # 4.2+
        return 'CLIP' if method == 'CLIP' else 'HASHED'
    return {'OPAQUE': 'OPAQUE', 'CLIP': 'CLIP'}.get(method, 'HASHED')


def material_shadow_mode(material, alpha_mode):
    """How a material's shadow uses alpha: 'NONE' (casts none), 'OPAQUE', 'CLIP' or
    'HASHED'. 4.2+: Transparent Shadows on follow the surface's alpha, off cast opaque
    shadows; 3.4 .. 4.1: the material's Shadow Mode."""
    if hasattr(material, "use_transparent_shadow"):        # 4.2+
        return alpha_mode if material.use_transparent_shadow else 'OPAQUE'
    method = getattr(material, "shadow_method", 'OPAQUE')
    return method if method in {'NONE', 'OPAQUE', 'CLIP', 'HASHED'} else 'OPAQUE'


def shading_nodes(id_block):
    """The node tree a material or World renders with, or None when it renders without
    nodes (Use Nodes off, before 5.0).

    NOTE: 5.0 always renders with nodes (files from before are converted on load) and
    deprecates ``use_nodes``, which reads True there, so it is read only before 5.0."""
    if not ALWAYS_NODES and not id_block.use_nodes:
        return None
    return id_block.node_tree


def enable_shading_nodes(id_block):
    """Use Nodes on for a material or World, as a script that builds one sets it; returns
    its node tree. (5.0 always uses nodes: nothing to set there.)"""
    if not ALWAYS_NODES:
        id_block.use_nodes = True
    return id_block.node_tree


def material_backface_culling_shadow(material):
    """Backface culling in the shadow pass: 4.2+'s own setting; before, shadows of every
    material were drawn from both sides."""
    return bool(getattr(material, "use_backface_culling_shadow", False))


def terminator_offset_owner(obj):
    """What holds the object's Shadow Terminator Geometry Offset: the ``Object`` in 5.0+,
    the Cycles add-on's ``object.cycles`` in 3.x/4.x, None when neither has it (Cycles
    not enabled)."""
    if hasattr(obj, "shadow_terminator_geometry_offset"):
        return obj
    cycles = getattr(obj, "cycles", None)
    if cycles is not None and hasattr(cycles, "shadow_terminator_geometry_offset"):
        return cycles
    return None


def terminator_geometry_offset(obj):
    """The object's Shadow Terminator Geometry Offset (``terminator_offset_owner``), or
    Blender's default when no setting holds it."""
    owner = terminator_offset_owner(obj)
    if owner is None:
        return float(DEFAULT_TERMINATOR_OFFSET)
    return float(owner.shadow_terminator_geometry_offset)


def corner_tangents(mesh, uv_name=""):
    """(L, 4) float32 MikkTSpace tangent (xyz) and bitangent sign (w) of each corner, as
    Blender computes them for its Normal Map node, or None where Blender cannot: no UV
    map, or faces of more than four corners (``calc_tangents`` refuses n-gons in 3.4 ..
    5.0; mesh_cache then computes them with numpy)."""
    count = len(mesh.loops)
    if not count or not len(mesh.uv_layers):
        return None
    sizes = read_array(mesh.polygons, "loop_total", len(mesh.polygons), np.int32)
    if len(sizes) and sizes.max() > 4:
        return None
    try:
        if uv_name and mesh.uv_layers.get(uv_name) is not None:
            mesh.calc_tangents(uvmap=uv_name)
        else:
            mesh.calc_tangents()
    except RuntimeError:
        return None
    out = np.empty((count, 4), dtype=np.float32)
    out[:, :3] = read_array(mesh.loops, "tangent", count * 3, np.float32).reshape(-1, 3)
    out[:, 3] = read_array(mesh.loops, "bitangent_sign", count, np.float32)
    mesh.free_tangents()
    return out


# -- mesh data ----------------------------------------------------------------------------
def read_array(collection, prop, count, dtype):
    """``collection.foreach_get(prop)`` into a new flat numpy array of ``count`` values."""
    out = np.empty(count, dtype=dtype)
    if count:
        collection.foreach_get(prop, out)
    return out


def _attribute(mesh, name, domain, prop, count, dtype):
    """A generic attribute's values, or None when the mesh has no such attribute.

    NOTE: generic attributes (3.5+) are read by ``foreach_get`` as one memory copy; the
    older per-element RNA paths (``loops["vertex_index"]``, ``uv_layers[..].data["uv"]``)
    copy element by element and cost ~100x more in 4.x/5.x (docs/benchmarks.md)."""
    attributes = getattr(mesh, "attributes", None)
    attribute = attributes.get(name) if attributes is not None else None
    if attribute is None or attribute.domain != domain:
        return None
    return read_array(attribute.data, prop, count, dtype)


def vertex_positions(mesh):
    """(V, 3) float32 vertex coordinates."""
    count = len(mesh.vertices) * 3
    coords = _attribute(mesh, "position", 'POINT', "vector", count, np.float32)
    if coords is None:                           # 3.4
        coords = read_array(mesh.vertices, "co", count, np.float32)
    return coords.reshape(-1, 3)


def corner_vertex_indices(mesh):
    """(L,) int32 vertex index of each corner (loop)."""
    count = len(mesh.loops)
    indices = _attribute(mesh, ".corner_vert", 'CORNER', "value", count, np.int32)
    if indices is None:                          # 3.4 .. 3.5
        indices = read_array(mesh.loops, "vertex_index", count, np.int32)
    return indices


def corner_normals(mesh):
    """(L, 3) float32 split normal of each corner."""
    count = len(mesh.loops) * 3
    if hasattr(mesh, "corner_normals"):          # 4.1+
        normals = read_array(mesh.corner_normals, "vector", count, np.float32)
    else:                                        # 3.4 .. 4.0
        mesh.calc_normals_split()
        normals = read_array(mesh.loops, "normal", count, np.float32)
    return normals.reshape(-1, 3)


def corner_uvs(mesh):
    """(L, 2) float32 active UV map per corner, or None without one."""
    uv_layer = mesh.uv_layers.active
    count = len(mesh.loops)
    if uv_layer is None or not count:
        return None
    uvs = _attribute(mesh, uv_layer.name, 'CORNER', "vector", count * 2, np.float32)
    if uvs is None:                              # 3.4: UV maps are not attributes yet
        uvs = read_array(uv_layer.data, "uv", count * 2, np.float32)
    return uvs.reshape(-1, 2)


def triangle_material_indices(mesh, tri_count):
    """Material slot of each loop triangle. Meshes with one material have no
    ``material_index`` attribute in 3.5+, which makes the common case free."""
    face_count = len(mesh.polygons)
    per_face = _attribute(mesh, "material_index", 'FACE', "value", face_count, np.int32)
    if per_face is not None:
        if hasattr(mesh, "loop_triangle_polygons"):      # 3.6+: fast per-triangle face
            face = read_array(mesh.loop_triangle_polygons, "value", tri_count, np.int32)
        else:
            face = read_array(mesh.loop_triangles, "polygon_index", tri_count, np.int32)
        return per_face[face]
    if getattr(mesh, "attributes", None) is not None and \
            hasattr(mesh, "loop_triangle_polygons"):
        return np.zeros(tri_count, dtype=np.int32)
    return read_array(mesh.loop_triangles, "material_index", tri_count, np.int32)


# -- render results -----------------------------------------------------------------------
def new_node_group_socket(tree, name, in_out, socket_type):
    """A node group's input or output socket: ``tree.interface`` in 4.0+, ``tree.inputs``
    and ``tree.outputs`` before."""
    interface = getattr(tree, "interface", None)
    if interface is not None:
        return interface.new_socket(name, in_out=in_out, socket_type=socket_type)
    sockets = tree.inputs if in_out == 'INPUT' else tree.outputs
    return sockets.new(socket_type, name)


# Blender 5.0 spells render passes out; 3.4 .. 4.x use short names (checked on 4.2 and 5.0:
# the compositor's Render Layers sockets with EEVEE).
_SHORT_PASS_NAMES = {"Diffuse Direct": "DiffDir", "Diffuse Color": "DiffCol",
                     "Glossy Direct": "GlossDir", "Glossy Color": "GlossCol",
                     "Emission": "Emit", "Environment": "Env", "Ambient Occlusion": "AO"}


def render_pass_name(name):
    """This Blender's name of the render pass Blender 5.0 calls ``name``."""
    if bpy.app.version >= (5, 0, 0):
        return name
    return _SHORT_PASS_NAMES.get(name, name)


def write_pass(render_pass, pixels):
    """Copy an (H, W, C) float32 array into a RenderResult pass."""
    flat = np.ascontiguousarray(pixels, dtype=np.float32).reshape(-1, render_pass.channels)
    try:
        render_pass.rect.foreach_set(flat.ravel())
    except (TypeError, RuntimeError, ValueError):
        # 3.4 wants W*H rows of channels rather than one flat array.
        render_pass.rect.foreach_set(flat)


# -- text ---------------------------------------------------------------------------------
def blf_size(font, size):
    """``blf.size`` without its dpi argument (removed in 4.0, required before)."""
    import blf
    if bpy.app.version >= (4, 0, 0):
        blf.size(font, size)
    else:
        blf.size(font, size, 72)


# -- importers ----------------------------------------------------------------------------
def gltf_importer_needs_numpy_bool():
    """The 3.4/3.5 glTF importer uses ``np.bool``, which numpy 1.24 removed (Debian 12 ships
    Blender 3.4 with numpy 1.24)."""
    return bpy.app.version < (3, 6, 0) and "bool" not in vars(np)


# -- process exit -------------------------------------------------------------------------
def exit_process(code):
    """Leave the process with ``code``. NOTE: pip bpy 4.2 segfaults while Python shuts down
    after any render by an engine with ``bl_use_gpu_context`` (a six-line engine does it
    too), which would turn every exit code into 139; skipping the shutdown keeps the code.
    5.0 exits cleanly, so it gets the normal path (and its exit handlers)."""
    if bpy.app.version < (5, 0, 0):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)
