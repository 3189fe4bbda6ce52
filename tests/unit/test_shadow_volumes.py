"""Shadow-volume geometry (core/shadow_volumes.py): closed solids whose winding number
is the number of casters between a point and the light, checked against a direct ray test
of the mesh."""

import numpy as np
import pytest

from csm_engine.core import shadow_volumes as sv


# The receivers' box the sun's volumes reach through (every test point lies in it).
BOX = (np.full(3, -5.0), np.full(3, 5.0))


def _box(lo=(-1.0, -1.0, -1.0), hi=(1.0, 1.0, 1.0)):
    """A closed box, outward winding, 8 corners split into 24 (as a GPU mesh splits
    corners at sharp edges) to check welding."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    corners = lo + corners * (hi - lo)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
             (1, 5, 7, 3)]
    positions, triangles = [], []
    for quad in quads:
        base = len(positions)
        positions.extend(corners[list(quad)])
        triangles += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(positions), np.array(triangles)


def _plane(size=1.0, z=0.0, n=2):
    """An open grid of n x n quads in the plane z (winding up)."""
    xs = np.linspace(-size, size, n + 1)
    grid = np.array([[x, y, z] for y in xs for x in xs])
    tris = []
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            tris += [(a, a + 1, a + n + 2), (a, a + n + 2, a + n + 1)]
    return grid, np.array(tris)


def _winding_number(soup, points):
    """Generalized winding number of the triangle soup (3 rows per triangle) at each point
    (Van Oosterom and Strackee's solid angle)."""
    tri = soup.astype(np.float64).reshape(-1, 3, 3)
    out = []
    for p in points:
        a, b, c = tri[:, 0] - p, tri[:, 1] - p, tri[:, 2] - p
        la, lb, lc = (np.linalg.norm(v, axis=1) for v in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        div = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + \
            np.einsum("ij,ij->i", a, c) * lb + np.einsum("ij,ij->i", b, c) * la
        out.append(np.arctan2(det, div).sum() * 2.0 / (4.0 * np.pi))
    return np.array(out)


def _hits(positions, triangles, matrix, origins, directions, max_t=np.inf):
    """Whether each ray origin + t * direction (0 < t < max_t) crosses a triangle."""
    world = positions @ matrix[:3, :3].T + matrix[:3, 3]
    a, b, c = (world[triangles[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    hits = []
    for o, d, limit in zip(origins, directions, np.broadcast_to(max_t, len(origins))):
        pv = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, pv)
        ok = np.abs(det) > 1e-12
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        tv = o - a
        u = np.einsum("ij,ij->i", tv, pv) * inv
        qv = np.cross(tv, e1)
        v = (qv @ d) * inv
        t = np.einsum("ij,ij->i", e2, qv) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9) & (t < limit)
        hits.append(bool(hit.any()))
    return np.array(hits)


def _soup_is_closed(soup):
    """Every directed edge of the soup is matched by the reverse edge, as often."""
    tri = np.round(soup.astype(np.float64).reshape(-1, 3, 3), 5)
    edges = {}
    for t in tri:
        for k in range(3):
            key = (tuple(t[k]), tuple(t[(k + 1) % 3]))
            edges[key] = edges.get(key, 0) + 1
    return all(edges.get((b, a), 0) == n for (a, b), n in edges.items())


def test_a_box_is_closed_and_welded():
    positions, triangles = _box()
    topo = sv.mesh_topology(positions, triangles)
    assert topo.closed
    assert len(topo.positions) == 8 and len(topo.edges) == 18 and len(topo.triangles) == 12


def test_a_plane_is_open_and_a_repeated_corner_is_dropped():
    positions, triangles = _plane()
    triangles = np.vstack([triangles, [[0, 0, 1]]])
    topo = sv.mesh_topology(positions, triangles)
    assert not topo.closed
    assert len(topo.triangles) == 8


def test_box_under_the_sun_extrudes_only_its_silhouette():
    positions, triangles = _box()
    topo = sv.mesh_topology(positions, triangles)
    soup = sv.sun_volume(topo, np.eye(4), np.array([0.0, 0.0, 1.0]), BOX).soup()
    # Bottom face: 2 near caps + 2 far caps; 4 silhouette edges: 8 side triangles.
    assert len(soup) == 3 * (2 + 2 + 8)
    assert _soup_is_closed(soup)
    # A sun from a corner: 3 faces away, a 6-edge silhouette.
    soup = sv.sun_volume(topo, np.eye(4), np.array([1.0, 1.0, 1.0]) / np.sqrt(3), BOX).soup()
    assert len(soup) == 3 * (6 + 6 + 12)
    assert _soup_is_closed(soup)


MATRICES = {
    "identity": np.eye(4),
    "mirrored": np.diag([-1.0, 1.0, 1.0, 1.0]),
    "mirrored_scaled_moved": np.array([[0.0, 2.0, 0.0, 0.5], [1.0, 0.0, 0.0, -0.3],
                                       [0.0, 0.0, -0.5, 2.0], [0.0, 0.0, 0.0, 1.0]]),
}


def _outside(positions, matrix, points):
    """Points outside the mesh's world bounding box (a closed caster's inside is no
    receiver: its volume starts at the faces turned away from the light)."""
    world = positions @ matrix[:3, :3].T + matrix[:3, 3]
    inside = np.all((points >= world.min(axis=0)) & (points <= world.max(axis=0)), axis=1)
    return points[~inside]


def _check_counts(positions, triangles, matrix, soup, points, to_light=None, light=None):
    points = _outside(positions, matrix, points)
    winding = _winding_number(soup, points)
    assert np.all(winding > -0.01), "a volume wound inside out"
    if to_light is not None:
        directions = np.broadcast_to(to_light, points.shape)
        shadowed = _hits(positions, triangles, matrix, points, directions)
    else:
        directions = light - points
        shadowed = _hits(positions, triangles, matrix, points, directions, max_t=1.0)
    np.testing.assert_array_equal(winding > 0.5, shadowed)


@pytest.mark.parametrize("matrix", MATRICES.values(), ids=MATRICES.keys())
@pytest.mark.parametrize("mesh", ["box", "plane"])
def test_sun_volume_counts_what_a_ray_to_the_sun_hits(matrix, mesh):
    positions, triangles = _box() if mesh == "box" else _plane()
    topo = sv.mesh_topology(positions, triangles)
    rng = np.random.default_rng(3)
    to_light = np.array([0.3, -0.4, 0.85])
    to_light /= np.linalg.norm(to_light)
    soup = sv.sun_volume(topo, matrix, to_light, BOX).soup()
    assert _soup_is_closed(soup)
    points = rng.uniform(-5.0, 5.0, size=(300, 3))
    _check_counts(positions, triangles, matrix, soup, points, to_light=to_light)


@pytest.mark.parametrize("matrix", MATRICES.values(), ids=MATRICES.keys())
@pytest.mark.parametrize("mesh", ["box", "plane"])
def test_point_volume_counts_what_a_ray_to_the_light_hits(matrix, mesh):
    positions, triangles = _box() if mesh == "box" else _plane(size=3.0, n=3)
    topo = sv.mesh_topology(positions, triangles)
    rng = np.random.default_rng(4)
    light = np.array([0.4, 0.2, 3.5])
    points = rng.uniform(-5.0, 5.0, size=(300, 3))
    reach = np.linalg.norm(points - light, axis=1).max()
    soup = sv.point_volume(topo, matrix, light, reach).soup()
    assert _soup_is_closed(soup)
    _check_counts(positions, triangles, matrix, soup, points, light=light)


def test_a_plane_wide_under_a_near_light_keeps_its_far_caps_beyond_reach():
    """A floor 40 units wide, 0.5 under the light: its far caps are chords of the sphere
    the corners are pushed to; points under the floor are still inside."""
    positions, triangles = _plane(size=20.0, n=1)
    topo = sv.mesh_topology(positions, triangles)
    light = np.array([0.0, 0.0, 0.5])
    points = np.array([[x, 0.0, z] for x in (-15.0, 0.0, 3.0, 15.0) for z in (-0.5, -3.0)])
    soup = sv.point_volume(topo, np.eye(4), light, 25.0).soup()
    np.testing.assert_array_less(0.5, _winding_number(soup, points))


def test_two_boxes_overlapping_count_two():
    p1, t1 = _box()
    p2, t2 = _box((-0.5, -0.5, 2.0), (0.5, 0.5, 3.0))
    positions = np.vstack([p1, p2])
    triangles = np.vstack([t1, t2 + len(p1)])
    topo = sv.mesh_topology(positions, triangles)
    assert topo.closed
    soup = sv.sun_volume(topo, np.eye(4), np.array([0.0, 0.0, 1.0]), BOX).soup()
    np.testing.assert_allclose(_winding_number(soup, np.array([[0.0, 0.0, -2.0]])), [2.0],
                               atol=1e-6)


def test_a_non_manifold_edge_is_extruded_with_its_multiplicity():
    """Three fins on one edge (an open, non-manifold mesh): each casts."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0.2], [0.5, -1, 0.2],
                          [0.5, 0.2, 1]], float)
    triangles = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    topo = sv.mesh_topology(positions, triangles)
    assert not topo.closed
    to_light = np.array([0.0, 0.0, 1.0])
    soup = sv.sun_volume(topo, np.eye(4), to_light, BOX).soup()
    assert _soup_is_closed(soup)
    points = np.random.default_rng(5).uniform(-1.5, 1.5, size=(200, 3))
    _check_counts(positions, triangles, np.eye(4), soup, points, to_light=to_light)


def test_sun_volumes_end_just_past_the_receivers_box():
    """A box a little above the floor of the receivers' box: its far cap lies just below
    that floor, not across the scene, and points on the floor in its shadow count."""
    positions, triangles = _box((-0.5, -0.5, 0.5), (0.5, 0.5, 1.5))
    topo = sv.mesh_topology(positions, triangles)
    to_light = np.array([0.2, 0.1, 1.0]) / np.linalg.norm([0.2, 0.1, 1.0])
    scene = (np.array([-20.0, -20.0, 0.0]), np.array([20.0, 20.0, 3.0]))
    volume = sv.sun_volume(topo, np.eye(4), to_light, scene)
    assert volume.vertices[:, 2].min() > -1.0      # the plane across the light is tilted
    below = np.array([[-0.3, -0.1, 0.0], [0.0, 0.0, 0.0], [0.2, 0.1, 0.0]])
    np.testing.assert_array_less(0.5, _winding_number(volume.soup(), below))


def test_empty_mesh_gives_no_volume():
    topo = sv.mesh_topology(np.zeros((0, 3)), np.zeros((0, 3), dtype=int))
    assert sv.sun_volume(topo, np.eye(4), np.array([0, 0, 1.0]), BOX).soup().shape == (0, 3)
