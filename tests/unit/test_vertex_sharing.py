"""Corners that agree share one GPU vertex; corners that differ keep theirs."""
import numpy as np
from hypothesis import given, settings, strategies as st

from csm_engine.core.vertex_sharing import share_vertices


def _expand(first, vertex_of_corner, array):
    """What each corner draws with after sharing."""
    return np.asarray(array)[first][vertex_of_corner]


def test_a_smooth_quad_strip_draws_from_one_vertex_per_mesh_vertex():
    # Two quads sharing an edge: 6 vertices, 8 corners, one normal and UV per vertex.
    corner_verts = np.array([0, 1, 4, 3, 1, 2, 5, 4])
    normals = np.tile([0.0, 0.0, 1.0], (8, 1))
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [1, 0], [2, 0], [2, 1], [1, 1]], float)
    first, vertex_of_corner = share_vertices(corner_verts, 6, (normals, uvs))
    assert len(first) == 6
    assert np.array_equal(corner_verts[first][vertex_of_corner], corner_verts)
    assert np.array_equal(_expand(first, vertex_of_corner, uvs), uvs)


def test_flat_faces_and_uv_seams_keep_their_own_vertices():
    corner_verts = np.array([0, 1, 4, 3, 1, 2, 5, 4])
    normals = np.array([[0, 0, 1]] * 4 + [[0, 1, 0]] * 4, float)   # a crease at 1-4
    uvs = np.zeros((8, 2))
    first, vertex_of_corner = share_vertices(corner_verts, 6, (normals, uvs))
    assert len(first) == 8          # the crease's two vertices are split, the rest shared
    assert np.array_equal(_expand(first, vertex_of_corner, normals), normals)
    seam = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0], [2, 0], [2, 1], [0.5, 1]])
    first, vertex_of_corner = share_vertices(corner_verts, 6, (np.tile([0, 0, 1.0], (8, 1)),
                                                               seam))
    assert len(first) == 8
    assert np.array_equal(_expand(first, vertex_of_corner, seam), seam)


def test_unused_vertices_and_empty_meshes():
    first, vertex_of_corner = share_vertices(np.array([2, 2, 5]), 8, ())
    assert len(first) == 2 and np.array_equal(vertex_of_corner, [0, 0, 1])
    first, vertex_of_corner = share_vertices(np.zeros(0, int), 4, ())
    assert len(first) == 0 and len(vertex_of_corner) == 0


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_every_corner_draws_exactly_its_own_values(data):
    vertex_count = data.draw(st.integers(1, 12))
    corners = data.draw(st.integers(0, 40))
    corner_verts = np.array(data.draw(st.lists(st.integers(0, vertex_count - 1),
                                               min_size=corners, max_size=corners)), int)
    values = np.array(data.draw(st.lists(st.integers(0, 2), min_size=corners,
                                         max_size=corners)), float).reshape(-1, 1)
    first, vertex_of_corner = share_vertices(corner_verts, vertex_count, (values, None))
    assert np.array_equal(corner_verts[first][vertex_of_corner], corner_verts)
    assert np.array_equal(_expand(first, vertex_of_corner, values), values)
    assert len(first) <= max(corners, 0)
    assert len(first) >= len(set(corner_verts.tolist()))
