"""Meshes on the GPU: numpy arrays -> one vertex buffer and an index buffer per material.

Owns ``GPUMesh``, ``MaterialInfo`` (what the passes read of one material slot),
``upload``, and ``uploads_since``, which tells what a sync uploaded (each mesh knows its
bytes and serial), so a render can report it and tests can prove that unchanged meshes are
not uploaded again. Only meshes whose materials use a normal map carry per-corner tangents
(16 more bytes a corner).
"""

import itertools
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np


# Serial numbers of uploads, never reused: a GPUMesh's ``serial`` names its geometry, so a
# shadow tile drawn from the same serials, matrices and light matrix need not be drawn again.
_SERIALS = itertools.count(1)
BYTES_PER_CORNER = 32       # a GPU vertex: position + normal + uv, float32 (see _vertex_format)
BYTES_PER_TANGENT = 16      # tangent xyz + bitangent sign, float32, normal-mapped meshes only
BYTES_PER_TRIANGLE = 12     # three int32 indices


@dataclass(eq=False)
class MaterialInfo:
    """One material slot as the passes draw it (read by ``blender/mesh_cache.py``); images
    are ``bpy.types.Image`` or None, factors multiply their texture. Units and meanings are
    those of ``core/material_layout.py``'s MATERIAL_LAYOUT."""
    base_color: tuple = (0.8, 0.8, 0.8, 1.0)     # linear rgb, alpha
    image: object = None                         # base-colour image
    metallic: float = 0.0
    roughness: float = 0.5
    specular_level: float = 0.5
    ior: float = 1.5                             # the specular layer's IOR
    coat_weight: float = 0.0                     # Principled Coat (v2), clear tint
    coat_roughness: float = 0.03
    coat_ior: float = 1.5
    emission: tuple = (0.0, 0.0, 0.0)            # colour x strength, W/m^2/sr
    emission_image: object = None
    normal_image: object = None                  # tangent-space normal map (Non-Color)
    normal_strength: float = 1.0
    tangent_uv: object = None                    # UV map name the tangents follow, when
                                                 # normal_image is set ("" = active)
    surface_image: object = None                 # the metallic-roughness image
    surface_convention: str = "PRINCIPLED"       # or "COURSE" (docs/materials.md)
    roughness_channel: int = -1                  # surface_image channel, -1 none
    metallic_channel: int = -1
    alpha_mode: str = "OPAQUE"                   # OPAQUE, CLIP, HASHED
    alpha_cutoff: float = 0.0                    # CLIP threshold
    shadow_mode: str = "OPAQUE"                  # NONE, OPAQUE, CLIP, HASHED
    backface_culling: bool = False               # camera passes
    backface_culling_shadow: bool = False        # shadow pass
    name: str = ""                               # the material's name (Cryptomatte)
    gpu_block: object = None                     # draw_lists: (flags, GPUUniformBuf, ...)

    @property
    def needs_tangents(self):
        return self.normal_image is not None


@dataclass
class GPUMesh:
    batches: list                  # one (GPUBatch, material slot index) per used slot
    materials: list                # MaterialInfo per slot
    aabb_min: np.ndarray           # object space
    aabb_max: np.ndarray
    triangle_count: int
    vertex_buffer: object = None
    index_buffers: list = field(default_factory=list)
    serial: int = 0                # unique per upload (see _SERIALS)
    has_tangents: bool = False     # the vertex buffer has "tan" (normal-mapped materials)
    upload_bytes: int = 0          # vertex and index data this upload sent to the GPU
    # The arrays uploaded, kept on the CPU for the Exact filter's shadow volumes
    # (render/shadow_volumes.py): positions (N, 3), triangles (T, 3), material slot per
    # triangle (T,).
    positions: np.ndarray = None
    triangles: np.ndarray = None
    material_index: np.ndarray = None


class Uploads(NamedTuple):
    """Meshes uploaded, and the bytes of vertex and index data they sent."""
    count: int = 0
    bytes: int = 0


def serial_mark():
    """A number below the serial of every upload made after this call: pass it to
    ``uploads_since`` to learn what a sync uploaded."""
    return next(_SERIALS)


def uploads_since(meshes, mark):
    """The uploads among ``meshes`` (GPUMesh or None; copies of one upload count once) made
    after ``serial_mark()`` returned ``mark``."""
    fresh = {mesh.serial: mesh.upload_bytes for mesh in meshes
             if mesh is not None and mesh.serial > mark}
    return Uploads(len(fresh), sum(fresh.values()))


def _vertex_format(with_tangents=False):
    import gpu
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type='F32', len=3, fetch_mode='FLOAT')
    fmt.attr_add(id="nor", comp_type='F32', len=3, fetch_mode='FLOAT')
    fmt.attr_add(id="uv", comp_type='F32', len=2, fetch_mode='FLOAT')
    if with_tangents:
        fmt.attr_add(id="tan", comp_type='F32', len=4, fetch_mode='FLOAT')
    return fmt


def upload(positions, normals, uvs, triangles, material_index, object_bounds, materials,
           tangents=None):
    """Numpy arrays -> one vertex buffer and an index buffer per used material slot.
    ``tangents``: (corners, 4) float32 tangent and bitangent sign, or None."""
    import gpu
    with_tangents = tangents is not None
    vbo = gpu.types.GPUVertBuf(_vertex_format(with_tangents), len(positions))
    vbo.attr_fill("pos", positions)
    vbo.attr_fill("nor", np.ascontiguousarray(normals))
    vbo.attr_fill("uv", np.ascontiguousarray(uvs))
    if with_tangents:
        vbo.attr_fill("tan", np.ascontiguousarray(tangents, dtype=np.float32))
    batches, ibos = [], []
    if len(triangles):
        slot_count = max(len(materials), 1)
        slots = np.clip(material_index, 0, slot_count - 1)
        order = np.argsort(slots, kind="stable")
        sorted_slots = slots[order]
        bounds = np.searchsorted(sorted_slots, np.arange(slot_count + 1))
        for slot in range(slot_count):
            start, end = bounds[slot], bounds[slot + 1]
            if end <= start:
                continue
            indices = np.ascontiguousarray(triangles[order[start:end]], dtype=np.int32)
            ibo = gpu.types.GPUIndexBuf(type='TRIS', seq=indices)
            ibos.append(ibo)
            batches.append((gpu.types.GPUBatch(type='TRIS', buf=vbo, elem=ibo), slot))
    aabb_min, aabb_max = object_bounds
    upload_bytes = len(positions) * (BYTES_PER_CORNER + with_tangents * BYTES_PER_TANGENT) \
        + len(triangles) * BYTES_PER_TRIANGLE
    return GPUMesh(batches=batches, materials=list(materials),
                   aabb_min=aabb_min.astype(np.float64), aabb_max=aabb_max.astype(np.float64),
                   triangle_count=len(triangles), vertex_buffer=vbo, index_buffers=ibos,
                   serial=next(_SERIALS), has_tangents=with_tangents,
                   upload_bytes=upload_bytes, positions=positions, triangles=triangles,
                   material_index=material_index)

