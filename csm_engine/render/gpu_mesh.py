"""Meshes on the GPU: numpy arrays -> one vertex buffer and an index buffer per material.

Owns ``GPUMesh`` and ``upload``; ``UPLOADS`` counts uploads so tests and the benchmark can
prove that unchanged meshes are not uploaded again.
"""

from dataclasses import dataclass, field

import numpy as np


# Total mesh uploads in this process; read by tests and the benchmark.
UPLOADS = {"count": 0, "bytes": 0}
# Serial number of the next upload: a GPUMesh's ``serial`` names its geometry, so a shadow
# tile drawn from the same serials, matrices and light matrix need not be drawn again.
_NEXT_SERIAL = [1]
BYTES_PER_CORNER = 32       # position + normal + uv, float32 (see _vertex_format)
BYTES_PER_TRIANGLE = 12     # three int32 indices


@dataclass
class MaterialInfo:
    base_color: tuple = (0.8, 0.8, 0.8, 1.0)
    image: object = None          # bpy.types.Image or None
    shininess: float = 32.0
    specular: float = 0.5
    alpha_cutoff: float = 0.0     # 0 = opaque; >0 = alpha-masked (cutout)


@dataclass
class GPUMesh:
    batches: list                  # one (GPUBatch, material slot index) per used slot
    materials: list                # MaterialInfo per slot
    aabb_min: np.ndarray           # object space
    aabb_max: np.ndarray
    triangle_count: int
    vertex_buffer: object = None
    index_buffers: list = field(default_factory=list)
    serial: int = 0                # unique per upload (see _NEXT_SERIAL)


def _vertex_format():
    import gpu
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type='F32', len=3, fetch_mode='FLOAT')
    fmt.attr_add(id="nor", comp_type='F32', len=3, fetch_mode='FLOAT')
    fmt.attr_add(id="uv", comp_type='F32', len=2, fetch_mode='FLOAT')
    return fmt


def upload(positions, normals, uvs, triangles, material_index, object_bounds, materials):
    """Numpy arrays -> one vertex buffer and an index buffer per used material slot."""
    import gpu
    vbo = gpu.types.GPUVertBuf(_vertex_format(), len(positions))
    vbo.attr_fill("pos", positions)
    vbo.attr_fill("nor", np.ascontiguousarray(normals))
    vbo.attr_fill("uv", np.ascontiguousarray(uvs))
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
    UPLOADS["count"] += 1
    serial = _NEXT_SERIAL[0]
    _NEXT_SERIAL[0] += 1
    UPLOADS["bytes"] += len(positions) * BYTES_PER_CORNER + len(triangles) * BYTES_PER_TRIANGLE
    return GPUMesh(batches=batches, materials=list(materials),
                   aabb_min=aabb_min.astype(np.float64), aabb_max=aabb_max.astype(np.float64),
                   triangle_count=len(triangles), vertex_buffer=vbo, index_buffers=ibos,
                   serial=serial)

