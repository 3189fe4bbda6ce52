"""Shadow volumes: the closed solids behind each caster, away from a light, as triangles.

Owns the geometry of the Exact shadow filter (``render/shadow_volumes.py`` counts it per
pixel): a mesh's topology (``mesh_topology``: welded corners, edges and whether the mesh is
closed) and its volume for the sun (``sun_volume``: extrusion along the light's direction)
or for a point or spot light (``point_volume``: extrusion along the rays from the light).

A volume is the sum of one prism per casting triangle: the triangle itself (near cap,
turned to face the light), the triangle pushed away from the light (far cap), and a side
quad per edge. Where two casting triangles share an edge with opposite windings their side
quads cancel, so only silhouette edges are extruded; an edge left with a net multiplicity
of two (non-manifold meshes) is extruded twice. Which triangles cast:
- a closed mesh (every edge shared by two triangles wound oppositely): the triangles facing
  away from the light. Their caps lie on surfaces the light does not reach, so no lit
  surface of the caster lies on its own volume's boundary (no self-shadowing speckle);
- any other mesh (planes, cards, scans with holes, non-manifold edges): every triangle,
  each turned to face the light (per-triangle volumes with generalized silhouettes).
Faces are turned by the world-space winding, with a mirrored matrix (negative
determinant) turning every winding around. Triangles whose corners weld together
(repeated vertices) are dropped; flat triangles with three distinct corners are kept, their
prisms are empty and their sides cancel.

Every prism is oriented outward: a depth-fail counter adds one for each volume face seen
from inside (back-facing) and subtracts one for each seen from outside (front-facing),
behind the visible surface; a sum above zero is in shadow. numpy only, pure.
"""

from typing import NamedTuple

import numpy as np


class MeshTopology(NamedTuple):
    """A mesh's corners welded by position (object space) and its edges."""
    positions: np.ndarray       # (V, 3) float64, distinct positions
    triangles: np.ndarray       # (T, 3) int64 indices into positions, no repeated corner
    edges: np.ndarray           # (E, 2) int64, each undirected edge once, first < second
    triangle_edges: np.ndarray  # (T, 3) index of edge (0-1, 1-2, 2-0) of each triangle
    edge_signs: np.ndarray      # (T, 3) +1 where the triangle runs its edge first->second
    closed: bool                # every edge in exactly two triangles, wound oppositely


def mesh_topology(positions, triangles):
    """The ``MeshTopology`` of ``positions`` (N, 3) and ``triangles`` (T, 3) indices:
    corners at one position welded (a GPU mesh splits them at UV seams and sharp edges),
    triangles with a repeated corner dropped."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(positions) == 0 or len(triangles) == 0:
        empty = np.zeros((0, 3), dtype=np.int64)
        return MeshTopology(np.zeros((0, 3)), empty, np.zeros((0, 2), dtype=np.int64),
                            empty, empty, False)
    welded, first = np.unique(positions, axis=0, return_inverse=True)
    tris = first.reshape(-1)[triangles]
    keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & \
        (tris[:, 2] != tris[:, 0])
    tris = tris[keep]
    directed = np.stack([tris, np.roll(tris, -1, axis=1)], axis=2).reshape(-1, 2)
    low = directed.min(axis=1)
    high = directed.max(axis=1)
    signs = np.where(directed[:, 0] == low, 1, -1).astype(np.int64)
    keys = low * len(welded) + high
    unique_keys, edge_of, uses = np.unique(keys, return_inverse=True, return_counts=True)
    edge_of = edge_of.reshape(-1)
    edges = np.stack([unique_keys // len(welded), unique_keys % len(welded)], axis=1)
    net = np.bincount(edge_of, weights=signs, minlength=len(unique_keys))
    closed = bool(len(tris)) and bool(np.all(uses == 2)) and bool(np.all(net == 0))
    return MeshTopology(welded, tris, edges, edge_of.reshape(-1, 3), signs.reshape(-1, 3),
                        closed)


def _world(topology, world_from_object):
    m = np.asarray(world_from_object, dtype=np.float64)
    world = topology.positions @ m[:3, :3].T + m[:3, 3]
    mirrored = np.linalg.det(m[:3, :3]) < 0.0
    return world, mirrored


def _casting(topology, world, mirrored, facing_light):
    """Which triangles cast (see the module docstring) and which must be turned around to
    face the light; ``facing_light(corners, normals)``: per triangle, how much its
    world-space winding faces the light (positive: towards it)."""
    tris = topology.triangles
    a, b, c = world[tris[:, 0]], world[tris[:, 1]], world[tris[:, 2]]
    normals = np.cross(b - a, c - a)
    facing = facing_light(a, normals)
    if topology.closed:
        # A mirror turns every winding around: the mesh's outside is the other side.
        casting = (facing > 0.0) if mirrored else (facing < 0.0)
    else:
        casting = facing != 0.0
    # Turned by the world-space winding, which is what the counter sees.
    return casting, facing < 0.0


class Volume(NamedTuple):
    """A shadow volume as indexed triangles: ``vertices`` (N, 3) float32 world positions
    (each welded corner, then each corner pushed away from the light) and ``triangles``
    (M, 3) int32 indices into them, wound outward. Indexed, so each corner is transformed
    once however many caps and sides share it."""
    vertices: np.ndarray
    triangles: np.ndarray

    def soup(self):
        """The triangles as (3 M, 3) float32 corners, three rows per triangle."""
        return self.vertices[self.triangles].reshape(-1, 3)


def _prisms(topology, world, casting, turned, far):
    """The casting triangles' prisms with shared sides cancelled, as a ``Volume``;
    ``far``: (V, 3) each welded corner pushed away from the light."""
    count = len(world)
    tris = topology.triangles[casting]
    turned = turned[casting]
    # Wound to face the light: the near cap's outward side is towards it.
    oriented = np.where(turned[:, None], tris[:, [0, 2, 1]], tris)
    far_caps = oriented[:, [0, 2, 1]] + count
    # Net winding of each edge over the casting triangles: +1 per run first->second.
    signs = topology.edge_signs[casting] * np.where(turned, -1, 1)[:, None]
    net = np.bincount(topology.triangle_edges[casting].reshape(-1),
                      weights=signs.reshape(-1).astype(np.float64),
                      minlength=len(topology.edges)).astype(np.int64)
    used = np.nonzero(net)[0]
    counts = np.abs(net[used])
    runs = topology.edges[used]
    runs = np.where((net[used] > 0)[:, None], runs, runs[:, ::-1])
    runs = np.repeat(runs, counts, axis=0)
    p, q = runs[:, 0], runs[:, 1]
    # For a near-cap edge p->q (counter-clockwise seen from the light), the outward side
    # quad is q, p, p', q'.
    sides = np.stack([np.stack([q, p, p + count], axis=1),
                      np.stack([q, p + count, q + count], axis=1)], axis=1).reshape(-1, 3)
    vertices = np.concatenate([world, far]).astype(np.float32)
    triangles = np.concatenate([oriented, far_caps, sides]).astype(np.int32)
    return Volume(vertices, np.ascontiguousarray(triangles))


def _sun_far_plane(world, away, lo, hi):
    """How far along ``away`` (unit, away from the sun) a plane across it must lie so that
    every ray from the box around ``world`` has left the scene box [``lo``, ``hi``]
    before reaching it: for each face a ray can leave through, its exit distance is an
    affine bound, largest at a corner of the instance's box; the exit is the nearest face's."""
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    corners = world.min(axis=0) + corners * (world.max(axis=0) - world.min(axis=0))
    along = corners @ away
    bounds = []
    for axis in range(3):
        step = away[axis]
        if abs(step) < 1e-12:
            continue
        face = hi[axis] if step > 0.0 else lo[axis]
        bounds.append(float(np.max(along + (face - corners[:, axis]) / step)))
    return min(bounds) if bounds else float(along.max())


def sun_volume(topology, world_from_object, to_light, scene_bounds):
    """The shadow volume of one mesh instance under the sun (a ``Volume`` in world space).
    ``to_light``: unit vector towards the sun; ``scene_bounds``: (lo, hi), a box holding
    every receiver. The far caps lie in one plane across the light, just past where the
    rays from the instance leave that box (so a caster above the ground is extruded a
    little way through it, not across the scene: the volume's fill is what it costs)."""
    to_light = np.asarray(to_light, dtype=np.float64)
    world, mirrored = _world(topology, world_from_object)
    casting, turned = _casting(topology, world, mirrored,
                               lambda corners, normals: normals @ to_light)
    if not len(world):
        return _prisms(topology, world, casting, turned, world)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in scene_bounds)
    away = -to_light
    margin = 1e-3 * float(np.linalg.norm(hi - lo)) + 1e-4
    plane = _sun_far_plane(world, away, lo - margin, hi + margin) + margin
    far = world + (plane - world @ away)[:, None] * away
    return _prisms(topology, world, casting, turned, far)


# A far cap whose plane passes closer to the light than this share of its corners'
# distance is pushed out no further (a triangle seen almost edge-on from the light: its
# volume is a sliver).
_MIN_FAR_CAP_SHARE = 1e-3


def point_volume(topology, world_from_object, light_position, reach):
    """The shadow volume of one mesh instance under a point or spot light at
    ``light_position`` (a ``Volume`` in world space). ``reach``: the farthest
    distance from the light (scene units) a receiver can be (the scene bounds' farthest
    corner). Corners are pushed along the rays from the light to a common distance, far
    enough that every far cap's plane is beyond ``reach`` (a far cap is a chord of that
    sphere, nearer the light in its middle than at its corners)."""
    light = np.asarray(light_position, dtype=np.float64)
    world, mirrored = _world(topology, world_from_object)
    rays = world - light
    distances = np.linalg.norm(rays, axis=1)
    scale = max(float(reach), float(distances.max(initial=0.0)), 1e-9)
    touching = distances <= 1e-9 * scale
    directions = rays / np.where(touching, 1.0, distances)[:, None]
    casting, turned = _casting(topology, world, mirrored,
                               lambda corners, normals: np.einsum(
                                   "ij,ij->i", normals, light - corners))
    # A triangle through the light's own position casts no shadow it could be drawn with.
    casting &= ~touching[topology.triangles].any(axis=1)
    tris = topology.triangles[casting]
    share = 1.0
    if len(tris):
        ua, ub, uc = directions[tris[:, 0]], directions[tris[:, 1]], directions[tris[:, 2]]
        plane = np.cross(ub - ua, uc - ua)
        length = np.linalg.norm(plane, axis=1)
        ok = length > 0.0
        if ok.any():
            heights = np.abs(np.einsum("ij,ij->i", plane[ok], ua[ok])) / length[ok]
            share = max(float(heights.min()), _MIN_FAR_CAP_SHARE)
    far = light + directions * (scale / share * 1.01)
    return _prisms(topology, world, casting, turned, far)
