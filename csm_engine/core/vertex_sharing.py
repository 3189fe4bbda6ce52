"""Which corners of a mesh can share one GPU vertex.

Owns ``share_vertices``: Blender gives every corner (loop) its own normal and UV; a GPU
vertex is needed per distinct (vertex, normal, UV, tangent), not per corner. On a smooth
mesh without seams every corner of a vertex carries the same values, so the mesh draws
from one GPU vertex per mesh vertex (a quad mesh has four corners a vertex: a quarter of
the vertex data, and llvmpipe shades each index once per cached run instead of up to four
times). Corners that differ from their vertex's first corner (flat faces, UV seams, sharp
edges) keep a vertex of their own, so nothing is averaged away. Numpy only.
"""

import numpy as np


def share_vertices(corner_verts, vertex_count, corner_arrays):
    """Map corners to shared vertices.

    ``corner_verts``: (L,) the mesh vertex of each corner. ``corner_arrays``: per-corner
    arrays (L, k) that must be equal for two corners to share a vertex (normal, UV,
    tangent...). Returns (``first``, ``vertex_of_corner``): ``first`` (V',) is the corner
    each output vertex takes its values from (index the per-corner arrays with it), and
    ``vertex_of_corner`` (L,) the output vertex of each corner (index triangles' corners
    with it). Mesh vertices no corner uses get no output vertex."""
    corner_verts = np.asarray(corner_verts, dtype=np.int64)
    corners = len(corner_verts)
    if corners == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    # The first corner of each mesh vertex: a reversed scatter leaves the lowest index.
    first_of_vertex = np.full(vertex_count, -1, dtype=np.int64)
    first_of_vertex[corner_verts[::-1]] = np.arange(corners - 1, -1, -1)
    leader = first_of_vertex[corner_verts]
    same = np.ones(corners, dtype=bool)
    for array in corner_arrays:
        if array is None:
            continue
        array = np.asarray(array).reshape(corners, -1)
        same &= (array == array[leader]).all(axis=1)
    # Output vertices: the used mesh vertices (in vertex order), then every corner that
    # differs from its vertex's first corner, each on its own.
    used = first_of_vertex >= 0
    vertex_slot = np.cumsum(used) - 1
    own = np.nonzero(~same)[0]
    shared_count = int(used.sum())
    vertex_of_corner = vertex_slot[corner_verts]
    vertex_of_corner[own] = shared_count + np.arange(len(own))
    first = np.concatenate([first_of_vertex[used], own])
    return first, vertex_of_corner
