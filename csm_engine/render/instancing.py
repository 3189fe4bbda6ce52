"""Instanced draws: every copy of one mesh in one draw call per pass.

Owns how a pass's instances (in the order it draws them) are cut into runs of one mesh
(``runs``), the texture of per-copy matrices the instanced programs read by
``gl_InstanceID`` (``matrix_texture``, ``shaders/instance_matrix.glsl``), and whether this
Blender can draw instanced at all (``available``). The passes (``gbuffer``,
``shadow_atlas``) decide what to draw; this module only packs and groups.

NOTE: a run of one copy draws as before (the matrix a push constant), so a scene without
repeated meshes draws exactly the same calls in the same order. Matrices are the same
float32 values either way (the shadow pass multiplies each tile's ``clip_from_world`` in
float64 on the CPU for both), so instanced and per-object draws give the same pixels.
"""

import numpy as np

# Matches INSTANCE_MATRICES_PER_ROW in instance_matrix.glsl: 4096 texels a row, far below
# any GL's maximum texture width, and 16 million copies before the height runs out.
MATRICES_PER_ROW = 1024


def available():
    """Whether this Blender's ``GPUBatch`` has ``draw_instanced`` (Blender 3.4's has
    not: there every copy is one draw, as without instancing)."""
    import gpu
    return hasattr(gpu.types.GPUBatch, "draw_instanced")


def runs(rows, group_keys):
    """``rows`` (instance indices in draw order) cut into runs drawn together:
    ``group_keys[i]`` (an int per instance) names instance i's group. Returns a list of
    int64 arrays in draw order of their first rows, each in draw order (so copies of a
    mesh stay front to back within their draw).

    NOTE: where two meshes' surfaces meet at exactly the same depth, the one drawn later
    wins (the depth test is LESS_EQUAL), so moving a copy before or after another mesh can
    change a pixel there. A row whose group has no other row here (a mesh drawn once) is a
    run of its own and copies are not moved across it: a scene where one mesh repeats
    (cubes on a ground) draws in exactly the order of one draw per object."""
    rows = np.asarray(rows, dtype=np.int64)
    if not len(rows):
        return []
    keys = np.asarray(group_keys, dtype=np.int64)[rows]
    _, group, counts = np.unique(keys, return_inverse=True, return_counts=True)
    group = group.ravel()
    alone = counts[group] == 1
    # Copies between two lone rows form one segment; the run key is (segment, group).
    segment = np.cumsum(alone)
    keys = segment * (len(counts) + 1) + np.where(alone, len(counts), group)
    # A stable sort by key keeps each run's rows in draw order; runs are then put in the
    # order their first row comes in.
    by_key = np.argsort(keys, kind="stable")
    sorted_keys = keys[by_key]
    starts = np.flatnonzero(np.concatenate(([True], sorted_keys[1:] != sorted_keys[:-1])))
    ends = np.append(starts[1:], len(rows))
    first_rows = by_key[starts]
    return [rows[by_key[starts[g]:ends[g]]] for g in np.argsort(first_rows, kind="stable")]


def pack(matrices_gl):
    """(N, 16) float32 column-major matrices -> the texture's rows of texels: (rows,
    4 * per-row copies, 4) float32, zero-padded. One row when N fits in it."""
    count = len(matrices_gl)
    per_row = min(max(count, 1), MATRICES_PER_ROW)
    height = max((count + MATRICES_PER_ROW - 1) // MATRICES_PER_ROW, 1)
    data = np.zeros((height * per_row, 16), dtype=np.float32)
    data[:count] = matrices_gl
    return data.reshape(height, per_row * 4, 4)


def matrix_texture(matrices_gl):
    """An RGBA32F texture holding ``matrices_gl`` ((N, 16) float32 column-major, see
    ``draw_lists.column_major_stack``) for ``instance_matrix.glsl``."""
    import gpu
    data = pack(matrices_gl)
    height, width = data.shape[:2]
    buffer = gpu.types.Buffer('FLOAT', data.size)
    # One memory copy through the buffer protocol (a Python sequence costs ~100x more).
    np.frombuffer(buffer, dtype=np.float32)[:] = data.ravel()
    return gpu.types.GPUTexture((width, height), format='RGBA32F', data=buffer)


def column_major_f32(matrices):
    """(N, 4, 4) matrices -> (N, 16) float32 in GLSL's column-major order."""
    matrices = np.asarray(matrices, dtype=np.float32)
    return np.ascontiguousarray(matrices.transpose(0, 2, 1).reshape(len(matrices), 16))
