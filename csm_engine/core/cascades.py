"""Cascaded-shadow-map math: splits, slice corners, light matrices, stabilization, culling.

Owns every number the shadow passes need that can be computed on the CPU without Blender:

- ``split_distances``: where the view depth is cut into cascades (uniform, logarithmic, the
  course's hybrid formula, or manual distances);
- ``frustum_slice_corners``: the 8 corners of one depth slice of the camera's projection
  (``camera.CameraProjection``, the same matrix the G-buffer uses, lens shift included);
- ``light_view_matrix`` / ``fit_cascade`` / ``compute_cascades``: the sun's orthographic box
  per cascade, stabilized (bounding sphere + texel snapping) or tight, with the occluder
  margin that pulls the near plane back toward the sun;
- ``aabb_in_cascade`` / ``aabbs_in_cascade``: the conservative caster-culling test;
- ``spot_light_matrices``: the perspective shadow frustum of a spot light;
- ``select_cascade`` / ``blend_weight`` / ``distance_fade``: numpy reference implementations
  of what the lighting shader does per pixel, so tests can check the GLSL against them.

It imports neither ``bpy`` nor ``gpu`` (numpy only) and is unit-tested without Blender.

Conventions (see ``docs/architecture.md``):
- Matrices are numpy float64 4x4 named ``target_from_source``; points are column vectors,
  so ``clip_from_world = clip_from_light @ light_from_world`` reads right to left.
- Blender world space is Z-up and right-handed. Cameras and lights look down their local -Z
  (OpenGL view space), so a point's *view depth* is ``d = -z_view`` (> 0 in front).
- Clip space is OpenGL's (x, y, z all in -1..1). Shadow maps store window depth
  ``z_clip * 0.5 + 0.5`` in 0..1.
- Distances (view depth, margins, texel sizes) are in scene units (metres in Blender);
  resolutions are in texels; angles are in radians.
- The *light direction* is the direction the light travels (for a Blender sun: its local -Z
  axis in world space), not the direction toward the light.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from .camera import CameraProjection, as_projection
from .checks import finite, matrix4, vector3
from .frame_layout import MAX_CASCADES, SPLIT_SCHEMES
from .matrices import ArrayMemo

MIN_CASCADE_RESOLUTION = 64          # texels; halving stops here (see cascade_resolutions)


# --------------------------------------------------------------------------------------
# Input checking helpers (the shared ones are in checks.py)
# --------------------------------------------------------------------------------------

def _count(count):
    try:
        if isinstance(count, bool):
            raise TypeError
        count = operator.index(count)
    except TypeError:
        raise ValueError(f"cascade count must be a whole number 1..{MAX_CASCADES}, "
                         f"got {count!r}") from None
    if not 1 <= count <= MAX_CASCADES:
        raise ValueError(f"cascade count must be 1..{MAX_CASCADES}, got {count}")
    return count


def _resolution(name, value):
    try:
        if isinstance(value, bool):
            raise TypeError
        value = operator.index(value)
    except TypeError:
        raise ValueError(f"{name} must be a whole number of texels, got {value!r}") from None
    if value < 1:
        raise ValueError(f"{name} must be at least 1 texel, got {value}")
    return value


def _bounds(name, bounds):
    """(min, max) world AABB as two float64 (3,) arrays, checked."""
    try:
        low, high = bounds
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (min, max) of 3-vectors, got {bounds!r}") \
            from None
    low, high = vector3(f"{name} min", low), vector3(f"{name} max", high)
    if np.any(low > high):
        raise ValueError(f"{name} min {low.tolist()} exceeds max {high.tolist()}")
    return low, high


# Corner i of a box takes the high side on axis a when bit a of i is set.
_CORNER_PICK = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=bool)


def _box_corners(low, high):
    """The 8 corners of an axis-aligned box, (8, 3)."""
    return np.where(_CORNER_PICK, high, low)


def _transform_points(matrix, points):
    """Affine transform of (N, 3) points by a 4x4 matrix (no perspective divide)."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _project_points(matrix, points):
    """Projective transform of (N, 3) points by a 4x4 matrix, with the divide by w."""
    homogeneous = points @ matrix[:3, :3].T + matrix[:3, 3]
    w = points @ matrix[3, :3] + matrix[3, 3]
    return homogeneous / w[:, None]


# --------------------------------------------------------------------------------------
# Split distances
# --------------------------------------------------------------------------------------

def split_distances(near, far, count, scheme, lam=0.5, manual=None):
    """View depths (scene units) bounding each cascade: an array of ``count + 1`` values.

    ``result[0] == near`` and ``result[-1] == far`` exactly; cascade ``i`` covers view
    depths ``result[i] .. result[i+1]``. Schemes (``i = 0..N``, ``N = count``):

    - ``'UNIFORM'``: ``z_i = n + (i/N) (f - n)``; equal depth ranges (sharp far away,
      blurry near the camera).
    - ``'LOG'``: ``z_i = n (f/n)^(i/N)``; logarithmic, i.e. each slice is the same ratio
      deeper, which gives even texel density on screen. Needs ``near > 0``.
    - ``'HYBRID'``: the course's formula
      ``z_i = lam n (f/n)^(i/N) + (1 - lam) (n + (i/N) (f - n))``;
      ``lam = 0`` is uniform, ``lam = 1`` is logarithmic. Needs ``near > 0`` when ``lam > 0``.
    - ``'MANUAL'``: ``manual`` holds the ``count - 1`` interior distances in scene units,
      strictly increasing and strictly inside ``(near, far)`` (see
      ``manual_splits_from_fractions`` for the settings' fractions).

    Raises ``ValueError`` naming the bad value.
    """
    near, far = finite("near distance", near), finite("far distance", far)
    count = _count(count)
    if not isinstance(scheme, str) or scheme.upper() not in SPLIT_SCHEMES:
        raise ValueError(f"split scheme must be one of {', '.join(SPLIT_SCHEMES)}, "
                         f"got {scheme!r}")
    scheme = scheme.upper()
    if not far > near:
        raise ValueError(f"far distance ({far}) must be greater than near distance ({near})")
    lam = finite("split lambda", lam)
    if scheme == "HYBRID" and not 0.0 <= lam <= 1.0:
        raise ValueError(f"split lambda must be in 0..1, got {lam}")
    if scheme == "LOG":
        lam = 1.0
    elif scheme == "UNIFORM":
        lam = 0.0

    fraction = np.arange(count + 1, dtype=np.float64) / count
    if scheme == "MANUAL":
        interior = _manual_interior(near, far, count, manual)
        splits = np.concatenate([[near], interior, [far]])
    else:
        if lam > 0.0 and not near > 0.0:
            raise ValueError(f"the {scheme.lower()} split scheme needs a near distance above 0, "
                             f"got {near} (use the uniform scheme or raise the clip start)")
        uniform = near + fraction * (far - near)
        if lam > 0.0:
            logarithmic = near * (far / near) ** fraction
            splits = lam * logarithmic + (1.0 - lam) * uniform
        else:
            splits = uniform
    # NOTE: the formulas hit near and far only up to rounding ((f/n)^1 * n may differ from f
    # in the last bit). The shader compares view depth against these values, so the ends are
    # pinned exactly: nothing in front of the shadow distance may fall past the last cascade.
    splits[0], splits[-1] = near, far
    steps = np.diff(splits)
    if not np.all(steps > 0.0):
        bad = int(np.argmin(steps))
        raise ValueError(f"near ({near}) and far ({far}) are too close to split into {count} "
                         f"cascades: split {bad + 1} ({splits[bad + 1]}) does not exceed "
                         f"split {bad} ({splits[bad]})")
    return splits


def _manual_interior(near, far, count, manual):
    wanted = count - 1
    if manual is None:
        raise ValueError(f"manual splits need {wanted} interior distance(s), got none")
    values = np.atleast_1d(np.asarray(manual, dtype=np.float64)).ravel()
    if values.shape[0] != wanted:
        raise ValueError(f"manual splits need exactly {wanted} interior distance(s) for "
                         f"{count} cascades, got {values.shape[0]}: {values.tolist()}")
    previous_name, previous = "the near distance", near
    for index, value in enumerate(values):
        name = f"manual split {index + 1} ({value})"
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite")
        if not value > previous:
            raise ValueError(f"{name} must be greater than {previous_name} ({previous})")
        if not value < far:
            raise ValueError(f"{name} must be less than the far distance ({far})")
        previous_name, previous = f"manual split {index + 1}", value
    return values


def manual_splits_from_fractions(far, fractions, count):
    """Interior split distances (scene units) from the settings' fractions of the shadow
    distance: ``distance_i = fraction_i * far`` for the first ``count - 1`` fractions."""
    far = finite("shadow distance", far)
    count = _count(count)
    values = np.atleast_1d(np.asarray(fractions, dtype=np.float64)).ravel()
    if values.shape[0] < count - 1:
        raise ValueError(f"{count} cascades need {count - 1} manual split fraction(s), "
                         f"got {values.shape[0]}: {values.tolist()}")
    return values[:count - 1] * far


def cascade_resolutions(count, base_resolution=2048, equal_resolution=False):
    """Shadow-map size per cascade in texels: base, base/2, base/4, ... never below
    ``MIN_CASCADE_RESOLUTION`` (64, or the base itself when that is smaller); all equal
    to the base when ``equal_resolution``."""
    count = _count(count)
    base = _resolution("base resolution", base_resolution)
    if equal_resolution:
        return [base] * count
    floor = min(MIN_CASCADE_RESOLUTION, base)
    return [max(base >> index, floor) for index in range(count)]


# --------------------------------------------------------------------------------------
# Camera projection and frustum slices
# --------------------------------------------------------------------------------------

def view_slice_corners(projection, near_d, far_d):
    """The 8 corners of the view-depth slice ``near_d .. far_d`` in *view* space, (8, 3).

    Order: near plane then far plane, each (left, bottom), (right, bottom), (right, top),
    (left, top); so corner ``i`` and ``i + 4`` lie on the same frustum edge.
    """
    projection = as_projection(projection)
    near_d, far_d = finite("slice near depth", near_d), finite("slice far depth", far_d)
    if not far_d > near_d:
        raise ValueError(f"slice far depth ({far_d}) must be greater than slice near depth "
                         f"({near_d})")
    if projection.is_perspective and not near_d > 0.0:
        raise ValueError(f"slice near depth must be above 0 for a perspective camera, "
                         f"got {near_d}")
    left, right, bottom, top = projection.view_window()
    window = np.array([[left, bottom], [right, bottom], [right, top], [left, top]])
    corners = np.empty((8, 3))
    for half, depth in ((0, near_d), (1, far_d)):
        scale = depth if projection.is_perspective else 1.0
        corners[4 * half:4 * half + 4, :2] = window * scale
        corners[4 * half:4 * half + 4, 2] = -depth
    return corners


def frustum_slice_corners(world_from_view, projection, near_d, far_d):
    """The 8 world-space corners (8, 3) of the camera frustum between view depths
    ``near_d`` and ``far_d`` (scene units). ``projection`` is a ``CameraProjection`` or an
    OpenGL ``clip_from_view`` matrix. Corner order as in ``view_slice_corners``."""
    world_from_view = matrix4("world_from_view", world_from_view)
    return _transform_points(world_from_view, view_slice_corners(projection, near_d, far_d))


# --------------------------------------------------------------------------------------
# Light view
# --------------------------------------------------------------------------------------

def light_view_matrix(light_dir_world, up_hint=None):
    """``light_from_world`` rotation (no translation) of a light travelling along
    ``light_dir_world``: light space looks down its -Z along the light, +Y is as close to
    ``up_hint`` as possible.

    ``up_hint`` defaults to world +Y, then world +Z when the light travels (nearly) along Y.
    +Y first because the common case, a sun straight down (0, 0, -1), is then far from the
    degenerate case. For an animated sun pass the sun's own local +Y axis
    (``world_from_sun[:3, 1]``): it is never parallel to the sun's direction and turns with
    it, so the shadow grid never flips.
    """
    forward = vector3("light direction", light_dir_world)
    key = (forward.tobytes(), None if up_hint is None else
           np.asarray(up_hint, dtype=np.float64).tobytes())
    held = _LIGHT_VIEWS.get(key)
    if held is not None:
        return held.copy()
    length = np.linalg.norm(forward)
    if not length > 1e-12:
        raise ValueError(f"light direction must not be zero, got {forward.tolist()}")
    forward = forward / length
    candidates = [] if up_hint is None else [vector3("light up hint", up_hint)]
    candidates += [np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])]
    for up in candidates:
        # NOTE: Gram-Schmidt loses precision as up approaches the light direction; below
        # ~0.1 (sin of ~6 degrees) of independent length fall back to the next hint.
        side = np.cross(forward, up)
        if np.linalg.norm(side) > 0.1 * np.linalg.norm(up):
            break
    x_axis = side / np.linalg.norm(side)
    z_axis = -forward
    y_axis = np.cross(z_axis, x_axis)
    light_from_world = np.eye(4)
    light_from_world[0, :3], light_from_world[1, :3], light_from_world[2, :3] = \
        x_axis, y_axis, z_axis
    if len(_LIGHT_VIEWS) >= _LIGHT_VIEWS_MAX:
        _LIGHT_VIEWS.clear()
    _LIGHT_VIEWS[key] = light_from_world.copy()
    return light_from_world


# (light direction, up hint) as bytes -> light_from_world: the sun rarely turns between
# viewport redraws, and the two cross products cost more than the rest of a cascade.
_LIGHT_VIEWS = {}
_LIGHT_VIEWS_MAX = 64


_IDENTITY3 = np.eye(3)
_BOTTOM_ROW = np.array([0.0, 0.0, 0.0, 1.0])


def _close(a, b, atol):
    """``np.allclose(a, b, atol=atol)`` (rtol 1e-5) for finite arrays, without its
    per-call overhead (~25 us; this runs once per cascade per frame)."""
    return bool((np.abs(a - b) <= atol + 1e-5 * np.abs(b)).all())


def _check_rotation(light_from_world_rot):
    m = matrix4("light_from_world rotation", light_from_world_rot)
    rotation = m[:3, :3]
    if not (_close(rotation @ rotation.T, _IDENTITY3, 1e-6)
            and np.linalg.det(rotation) > 0.0 and _close(m[:3, 3], 0.0, 1e-9)
            and _close(m[3], _BOTTOM_ROW, 1e-8)):
        raise ValueError("light_from_world rotation must be a pure rotation "
                         "(orthonormal, determinant +1, no translation); "
                         "build it with light_view_matrix()")
    return rotation


# --------------------------------------------------------------------------------------
# Bounding sphere
# --------------------------------------------------------------------------------------

def _circumcentres(points, subsets):
    """Centre and radius of the smallest sphere through each subset of points (the
    circumcentre inside the subset's affine hull); ``ok`` is False for degenerate ones."""
    base = points[subsets[:, 0]]                                     # (S, 3)
    spans = points[subsets[:, 1:]] - base[:, None, :]                # (S, k-1, 3)
    gram = spans @ np.swapaxes(spans, 1, 2)                          # (S, k-1, k-1)
    rhs = 0.5 * np.einsum("skk->sk", gram)
    scale = np.maximum(np.einsum("skk->s", gram), 1e-300)
    ok = np.abs(np.linalg.det(gram)) > 1e-10 * scale ** gram.shape[1]
    gram = np.where(ok[:, None, None], gram, np.eye(gram.shape[1]))
    weights = np.linalg.solve(gram, rhs[..., None])[..., 0]          # (S, k-1)
    centres = base + np.einsum("sk,skd->sd", weights, spans)
    radii = np.linalg.norm(centres - base, axis=1)
    return centres, radii, ok


_SUBSETS = {size: np.array(list(combinations(range(8), size))) for size in (2, 3, 4)}


def bounding_sphere(points):
    """The smallest sphere enclosing up to 8 points: (centre (3,), radius).

    Exact: the minimal sphere is the circumsphere of 2, 3 or 4 of the points, so every such
    subset is tried (162 candidates for 8 points, batched) and the smallest one that holds
    all points wins. Depends only on the points' relative positions, so a rigidly moved or
    turned slice gets the same radius.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.shape != (8, 3) or not np.all(np.isfinite(points)):
        raise ValueError(f"bounding_sphere needs 8 finite 3D points, got shape {points.shape}")
    # NOTE: work relative to the centroid so that a slice far from the world origin keeps
    # its full precision in the subtractions below.
    origin = points.mean(axis=0)
    local = points - origin
    best_centre, best_radius = np.zeros(3), np.inf
    extent = np.abs(local).max()
    for size in (2, 3, 4):
        centres, radii, ok = _circumcentres(local, _SUBSETS[size])
        distance = np.linalg.norm(local[None, :, :] - centres[:, None, :], axis=2)
        holds = ok & np.all(distance <= radii[:, None] * (1.0 + 1e-9) + 1e-12 * extent, axis=1)
        if np.any(holds & (radii < best_radius)):
            index = np.flatnonzero(holds)[np.argmin(radii[holds])]
            best_centre, best_radius = centres[index], radii[index]
    # The tolerance above may accept a sphere a hair too small; use the true farthest point.
    best_radius = float(np.linalg.norm(local - best_centre, axis=1).max())
    return best_centre + origin, best_radius


# View-space slice corners -> their bounding sphere. The corners depend only on the
# projection and the split distances, so a viewport redraw where only the camera moves
# asks for the same spheres again; the exact search above costs ~0.5 ms a cascade.
_VIEW_SPHERES_MAX = 64
_view_space_sphere = ArrayMemo(bounding_sphere, _VIEW_SPHERES_MAX)


# (projection, near depth, far depth) -> the slice's view-space corners and, once asked
# for, their bounding sphere: the same for every redraw that only moves the camera.
_VIEW_SLICES = {}


def _view_slice(projection, near_d, far_d, with_sphere):
    key = (projection, float(near_d), float(far_d))
    held = _VIEW_SLICES.get(key)
    if held is None or (with_sphere and held[1] is None):
        corners = view_slice_corners(projection, near_d, far_d) if held is None else held[0]
        corners.setflags(write=False)
        held = (corners, _view_space_sphere(corners) if with_sphere else None)
        if len(_VIEW_SLICES) >= _VIEW_SPHERES_MAX:
            _VIEW_SLICES.clear()
        _VIEW_SLICES[key] = held
    return held


def round_up_radius(radius):
    """Round a cascade's sphere radius up to a step of 1/64 of its leading power of two
    (e.g. 1/64 unit for radii 1..2, 1/4 unit for 16..32).

    NOTE: the sphere radius is constant while the camera turns only up to floating-point
    noise; a texel size that changed in the last bit would rescale the whole shadow map and
    make it shimmer. Rounding up to a coarse, exactly representable step removes the noise.
    A step relative to the radius (not Babylon's fixed 1/16 unit) keeps tiny scenes sharp
    and costs at most ~1.6% of the resolution.
    """
    radius = finite("sphere radius", radius)
    if not radius > 0.0:
        raise ValueError(f"sphere radius must be above 0, got {radius}")
    return _round_up_dyadic(radius * (1.0 + 1e-12), bits=7)


def _round_up_dyadic(value, bits):
    """Smallest number >= value with at most ``bits`` significant binary digits."""
    step = 2.0 ** (math.floor(math.log2(value)) - (bits - 1))
    return math.ceil(value / step) * step


# --------------------------------------------------------------------------------------
# Cascade fitting
# --------------------------------------------------------------------------------------

@dataclass
class CascadeFit:
    """One cascade's shadow box and matrices.

    - ``light_from_world``: the light's view (rotation + translation). Light space looks
      down -Z along the light; its origin sits on the box's near plane, centred in x/y.
    - ``clip_from_light``: OpenGL orthographic projection of the box.
    - ``clip_from_world``: ``clip_from_light @ light_from_world`` (what the shaders use).
    - ``resolution``: shadow-map size in texels (square).
    - ``texel_size_world``: scene units per shadow texel (the larger of x and y; the biases
      are multiples of it).
    - ``box_min``, ``box_max``: the box in light space (scene units); z runs from
      ``-far`` (far plane) to ``-near`` (near plane, toward the light).
    - ``near``, ``far``: distances of the box planes along the light from the light-space
      origin (``near`` is 0 by construction, ``far`` the box depth).
    - ``stabilized``: fitted with a bounding sphere and snapped to whole texels.
    - ``sphere_center_world``, ``sphere_radius``: the slice's bounding sphere (stabilized
      only; radius already rounded up).
    - ``split_near``, ``split_far``: the view-depth slice this cascade covers (filled by
      ``compute_cascades``; NaN when fitted directly).
    """

    light_from_world: np.ndarray
    clip_from_light: np.ndarray
    clip_from_world: np.ndarray
    resolution: int
    texel_size_world: float
    box_min: np.ndarray
    box_max: np.ndarray
    near: float
    far: float
    stabilized: bool
    sphere_center_world: np.ndarray | None = None
    sphere_radius: float = math.nan
    split_near: float = math.nan
    split_far: float = math.nan
    texel_size_xy: np.ndarray = field(default_factory=lambda: np.full(2, math.nan))

    @property
    def world_from_light(self):
        return _rigid_inverse(self.light_from_world)

    @property
    def light_dir_world(self):
        """Direction the light travels, world space (unit)."""
        return -self.light_from_world[2, :3]

    @property
    def depth_range(self):
        """Box depth along the light in scene units (window depth 0..1 spans it)."""
        return self.far - self.near

    @property
    def window_depth_per_unit(self):
        """Window-depth (0..1) change per scene unit along the light: turns a bias in
        scene units into a shadow-map depth offset."""
        return 1.0 / self.depth_range

    def box_corners_world(self):
        """The 8 world-space corners of the shadow box, (8, 3), for drawing frozen cascades.
        Same corner order as ``view_slice_corners`` (near plane first)."""
        low, high = self.box_min, self.box_max
        light = np.array([[low[0], low[1], high[2]], [high[0], low[1], high[2]],
                          [high[0], high[1], high[2]], [low[0], high[1], high[2]],
                          [low[0], low[1], low[2]], [high[0], low[1], low[2]],
                          [high[0], high[1], low[2]], [low[0], high[1], low[2]]])
        return _transform_points(self.world_from_light, light)


def _rigid_inverse(matrix):
    inverse = np.eye(4)
    inverse[:3, :3] = matrix[:3, :3].T
    inverse[:3, 3] = -matrix[:3, :3].T @ matrix[:3, 3]
    return inverse


def orthographic_clip_from_view(left, right, bottom, top, near, far):
    """OpenGL glOrtho: light-space box (z from -near to -far) to clip -1..1."""
    m = np.eye(4)
    m[0, 0] = 2.0 / (right - left)
    m[1, 1] = 2.0 / (top - bottom)
    m[2, 2] = -2.0 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


def perspective_clip_from_view(fov_y, aspect, near, far):
    """OpenGL gluPerspective: symmetric frustum, full vertical angle ``fov_y`` radians."""
    return CameraProjection(kind="PERSP", fov_y=fov_y, aspect=aspect,
                            clip_start=near, clip_end=far).clip_from_view()


def snap_to_texel_grid(value, texel_size):
    """Round light-space coordinates to the nearest whole multiple of ``texel_size``."""
    return np.round(np.asarray(value, dtype=np.float64) / texel_size) * texel_size


def texel_grid_position(cascade):
    """Where the cascade's box centre sits on the light-space texel grid, in texels (x, y).

    For a stabilized cascade these are whole numbers: the box only ever moves by whole
    texels, which is what keeps shadow edges still. Compare two frames' positions to see
    how many texels the box moved.
    """
    # light_from_world's translation is minus the box centre in the light's rotated frame.
    return -cascade.light_from_world[:2, 3] / cascade.texel_size_world


def default_occluder_margin(scene_bounds):
    """Default occluder margin: the length of the scene bounds' diagonal (scene units).

    Any caster inside the scene bounds is at most one diagonal away from any receiver
    inside them, so pulling each cascade's near plane back by that much never clips a
    caster, whatever the light direction. ``None`` (no bounds known) gives 0.
    """
    if scene_bounds is None:
        return 0.0
    low, high = _bounds("scene bounds", scene_bounds)
    return float(np.linalg.norm(high - low))


def fit_cascade(slice_corners_world, light_from_world_rot, resolution, stabilize=True,
                occluder_margin=0.0, scene_bounds=None, bounding_sphere_world=None,
                receiver_box=None):
    """Fit one cascade's orthographic shadow box to a frustum slice.

    - ``slice_corners_world``: (8, 3) world corners (``frustum_slice_corners``).
    - ``light_from_world_rot``: pure rotation from ``light_view_matrix``.
    - ``resolution``: shadow-map size in texels.
    - ``stabilize`` (default on): square box around the slice's bounding sphere, radius
      rounded up and centre snapped to whole texels, so the map neither rescales when the
      camera turns nor slides by fractions of a texel when it moves. Off: the tight
      light-space AABB of the corners, cut to ``receiver_box`` when one is given (more
      resolution, but edges swim).
    - ``occluder_margin``: scene units the near plane is pulled back toward the light so
      casters outside the slice still cast into it.
    - ``scene_bounds``: optional world AABB ``(min, max)``; the near plane then also reaches
      the scene's corner nearest to the light, so no caster in the scene is ever clipped.
    - ``bounding_sphere_world``: optional precomputed ``(centre, radius)``;
      ``compute_cascades`` computes it in view space, where it is exactly the same for
      every camera orientation.
    - ``receiver_box``: optional ``(centre_xy, half_width)`` in the rotated light frame:
      the square the visible receivers of this slice need (``receiver_square``), used
      instead of the sphere when it is smaller (sample-distribution shadow maps). Its half
      width is already quantized, so with ``stabilize`` the texel size still only changes
      in coarse steps, and the centre is snapped to texels as the sphere's is. Without
      ``stabilize`` it is exact, and the box is the corners' box cut to it.

    The far plane is the slice's far side: receivers only exist inside the slice.
    """
    corners = _slice_corners(slice_corners_world)
    rotation = _check_rotation(light_from_world_rot)
    resolution = _resolution("cascade resolution", resolution)
    if resolution < 2:
        raise ValueError(f"cascade resolution must be at least 2 texels, got {resolution}")
    margin = finite("occluder margin", occluder_margin)
    if margin < 0.0:
        raise ValueError(f"occluder margin must not be negative, got {margin}")
    if stabilize and bounding_sphere_world is not None:
        bounding_sphere_world = (vector3("bounding sphere centre", bounding_sphere_world[0]),
                                 finite("bounding sphere radius", bounding_sphere_world[1]))
    scene_near = None if scene_bounds is None else \
        _scene_near_depth(_bounds("scene bounds", scene_bounds), rotation)
    return _fit_checked(corners, rotation, resolution, stabilize, margin, scene_near,
                        bounding_sphere_world, receiver_box)


def _slice_corners(slice_corners_world):
    corners = np.asarray(slice_corners_world, dtype=np.float64)
    if corners.shape != (8, 3) or not np.isfinite(corners).all():
        raise ValueError(f"slice corners must be 8 finite 3D points, got shape {corners.shape}")
    return corners


def _scene_near_depth(scene_box, rotation):
    """Depth along the light (rotated light frame) of the scene box's corner nearest the
    light: the near plane reaches at least there, so no caster is clipped."""
    return float(-(_box_corners(*scene_box) @ rotation[2]).max())


def _fit_checked(corners, rotation, resolution, stabilize, margin, scene_near,
                 bounding_sphere_world, receiver_box):
    """``fit_cascade`` on checked inputs: (8, 3) corners, a 3x3 rotation, an int
    resolution, a float margin, the scene's ``_scene_near_depth`` or None, a (centre,
    radius) sphere or None. ``compute_cascades`` checks its inputs once per frame and calls
    this per cascade (the checks cost as much as the fit)."""
    # Rotated light frame ("rot"): light axes, world origin. Depth along the light is -z.
    if stabilize:
        if bounding_sphere_world is None:
            centre_world, radius = bounding_sphere(corners)
        else:
            centre_world, radius = bounding_sphere_world
        radius = round_up_radius(max(radius, 1e-9))
        depth_radius = radius
        radius_xy = np.array([radius, radius])
        if receiver_box is not None and np.any(np.asarray(receiver_box[1]) < radius):
            # The receivers' rectangle: its centre, and its half widths as per-axis "radii"
            # (the depth range below still comes from the sphere, which holds every
            # receiver of the slice).
            centre_rot_xy = np.asarray(receiver_box[0], dtype=np.float64)
            centre_world = rotation.T @ np.array([centre_rot_xy[0], centre_rot_xy[1],
                                                  (rotation @ centre_world)[2]])
            radius_xy = np.minimum(np.asarray(receiver_box[1], dtype=np.float64), radius)
        # NOTE: one texel of slack: the snapped centre may sit up to half a texel from the
        # sphere's centre on each axis, so the box is at least 2r + 1 texel wide and the
        # sphere always fits. The texel size is then rounded up to 9 significant bits, so
        # it is exactly representable and whole multiples of it (the snapped centres) are
        # exact too. It depends only on the rounded radius and the resolution, so it is
        # constant while the camera turns.
        texel = np.array([_round_up_dyadic(2.0 * r / (resolution - 1), bits=9)
                          for r in radius_xy])
        half = 0.5 * resolution * texel
        centre_rot = rotation @ centre_world
        # NOTE: snap the box centre to whole texels of a grid fixed in light space (anchored
        # at the world origin). When the camera moves, the box then moves by whole texels,
        # so every world point keeps rasterizing at the same spot inside its texel and
        # shadow edges do not crawl ("shimmer").
        centre_xy = snap_to_texel_grid(centre_rot[:2], texel)
        low_xy, high_xy = centre_xy - half, centre_xy + half
        nearest_depth = -centre_rot[2] - depth_radius    # along the light, slice side
        farthest_depth = -centre_rot[2] + depth_radius
        if receiver_box is not None:
            # NOTE: the sphere follows the camera, so its depth range moves with every
            # step; widened to a coarse grid (1/16 of the radius), it stays put while the
            # receivers' rectangle does, and so does the whole shadow map.
            step = _round_up_dyadic(depth_radius / 16.0, bits=1)
            nearest_depth = math.floor(nearest_depth / step) * step
            farthest_depth = math.ceil(farthest_depth / step) * step
        texel_xy = texel
        sphere_centre = centre_world
    else:
        corners_rot = corners @ rotation.T
        low_xy, high_xy = corners_rot[:, :2].min(axis=0), corners_rot[:, :2].max(axis=0)
        if receiver_box is not None:
            # Only the part of the slice's box that holds visible receivers: the tightest
            # fit, for a still image (it moves and rescales with every camera step).
            centre_box = np.asarray(receiver_box[0], dtype=np.float64)
            half_box = np.asarray(receiver_box[1], dtype=np.float64)
            cut_low = np.maximum(low_xy, centre_box - half_box)
            cut_high = np.minimum(high_xy, centre_box + half_box)
            if np.all(cut_high > cut_low):
                low_xy, high_xy = cut_low, cut_high
        # A slice seen edge-on by the light is flat in one axis; keep the box non-empty.
        spread = max(float(np.max(high_xy - low_xy)), 1e-9)
        pad = np.maximum(0.0, 1e-6 * spread - (high_xy - low_xy)) * 0.5
        low_xy, high_xy = low_xy - pad, high_xy + pad
        centre_xy = 0.5 * (low_xy + high_xy)
        nearest_depth = float(-corners_rot[:, 2].max())
        farthest_depth = float(-corners_rot[:, 2].min())
        texel_xy = (high_xy - low_xy) / resolution
        sphere_centre, radius = None, math.nan

    near_depth = nearest_depth - margin
    if scene_near is not None:
        near_depth = min(near_depth, scene_near)
    if not farthest_depth > near_depth:
        farthest_depth = near_depth + 1e-6 * max(1.0, abs(near_depth))

    # NOTE: light_from_world is formed directly from the rotation and the snapped centre
    # (as Bevy does) rather than by inverting world_from_light, so its translation stays an
    # exact multiple of the texel size.
    light_from_world = np.eye(4)
    light_from_world[:3, :3] = rotation
    light_from_world[:3, 3] = (-centre_xy[0], -centre_xy[1], near_depth)
    half_xy = 0.5 * (high_xy - low_xy)
    depth = farthest_depth - near_depth
    clip_from_light = orthographic_clip_from_view(-half_xy[0], half_xy[0], -half_xy[1],
                                                  half_xy[1], 0.0, depth)
    return CascadeFit(
        light_from_world=light_from_world,
        clip_from_light=clip_from_light,
        clip_from_world=clip_from_light @ light_from_world,
        resolution=resolution,
        texel_size_world=float(texel_xy.max()),
        box_min=np.array([-half_xy[0], -half_xy[1], -depth]),
        box_max=np.array([half_xy[0], half_xy[1], 0.0]),
        near=0.0, far=float(depth), stabilized=bool(stabilize),
        sphere_center_world=sphere_centre, sphere_radius=radius,
        texel_size_xy=texel_xy)


@dataclass
class CascadeSet:
    """All cascades of one frame: ``cascades[i]`` covers view depths
    ``splits[i] .. splits[i+1]`` (scene units); ``scheme`` is the split scheme actually
    used and ``notes`` say which requested settings were replaced and why."""

    cascades: list
    splits: np.ndarray
    scheme: str
    notes: tuple = ()

    @property
    def shadow_distance(self):
        return float(self.splits[-1])


def compute_cascades(world_from_view, projection, light_dir, count=3, scheme="HYBRID",
                     lam=0.5, manual=None, shadow_distance=None, base_resolution=2048,
                     equal_resolution=False, stabilize=True, occluder_margin=None,
                     scene_bounds=None, up_hint=None, blend_band=0.0, depth_range=None,
                     depth_blocks=None, previous_squares=None):
    """Splits and shadow boxes for one camera and one sun.

    - ``projection``: ``CameraProjection`` or an OpenGL ``clip_from_view`` matrix.
    - ``light_dir``: world direction the sunlight travels; ``up_hint`` see
      ``light_view_matrix``.
    - ``manual``: interior split distances in scene units (scheme ``'MANUAL'``).
    - ``shadow_distance``: view depth (scene units) where shadows end; ``None`` or 0 means
      the camera's far clip, larger values are clamped to it.
    - ``base_resolution`` / ``equal_resolution``: see ``cascade_resolutions``.
    - ``occluder_margin``: scene units; ``None`` means ``default_occluder_margin(scene_bounds)``.
    - ``blend_band``: scene units (see ``blend_band_widths``). Cascade ``i+1`` is fitted from
      ``splits[i+1] - band`` on, because the shader samples it inside that band too.

    - ``depth_range``: (nearest, farthest) view depth of what the camera actually sees
      (sample-distribution shadow maps, see ``visible_depth_range``): the splits then
      divide that range instead of clip start .. shadow distance, so no cascade is spent
      on empty depth. Clamped to the clip start .. shadow distance.
    - ``depth_blocks``: the visible receivers per screen block (see ``receiver_square``):
      each cascade then covers only the rectangle its receivers need (stabilized: rounded
      and held; unstabilized: exactly), when that is
      smaller than its slice's sphere; ``previous_squares`` (per cascade, the half widths
      of the last frame) hold those squares still while they fit.

    An orthographic view whose clip start is not above 0 (Blender's orthographic viewport
    clips from behind the eye) cannot use logarithmic splits; it falls back to uniform
    splits and says so in ``notes``.
    """
    world_from_view = matrix4("world_from_view", world_from_view)
    projection = as_projection(projection)
    near, clip_end = projection.clip_start, projection.clip_end
    far = clip_end
    if shadow_distance is not None:
        shadow_distance = finite("shadow distance", shadow_distance)
        if shadow_distance < 0.0:
            raise ValueError(f"shadow distance must not be negative, got {shadow_distance}")
        if shadow_distance > 0.0:
            far = min(shadow_distance, clip_end)
            if not far > near:
                raise ValueError(f"shadow distance ({shadow_distance}) must be greater than "
                                 f"the camera's clip start ({near})")
    scheme = scheme.upper() if isinstance(scheme, str) else scheme
    notes = []
    if scheme in ("LOG", "HYBRID") and not near > 0.0 and not projection.is_perspective:
        notes.append(f"{scheme.lower()} splits need a clip start above 0; this orthographic "
                     f"view clips from {near}, so uniform splits are used")
        scheme = "UNIFORM"
    first, last = near, far
    # NOTE: manual splits are distances the user typed: they are kept as typed (only the
    # cascades' rectangles are fitted to the receivers, below).
    if depth_range is not None and scheme != "MANUAL":
        low, high = (finite("depth range", v) for v in depth_range)
        first = min(max(low, near), far)
        last = min(max(high, first), far)
        if not last > first:
            last = min(far, first + max(1e-3 * first, 1e-6))
    splits = split_distances(first, last, count, scheme, lam=lam, manual=manual)
    resolutions = cascade_resolutions(len(splits) - 1, base_resolution, equal_resolution)
    rotation = light_view_matrix(light_dir, up_hint)
    scene_box = None if scene_bounds is None else _bounds("scene bounds", scene_bounds)
    if occluder_margin is None:
        occluder_margin = 0.0 if scene_box is None else \
            float(np.linalg.norm(scene_box[1] - scene_box[0]))    # default_occluder_margin
    # Checked once here rather than per cascade in fit_cascade (a viewport redraw runs this
    # for every camera move). light_view_matrix builds a pure rotation by construction.
    margin = finite("occluder margin", occluder_margin)
    if margin < 0.0:
        raise ValueError(f"occluder margin must not be negative, got {margin}")
    scene_near = None if scene_box is None else \
        _scene_near_depth(scene_box, rotation[:3, :3])
    if min(resolutions) < 2:
        raise ValueError(f"cascade resolution must be at least 2 texels, "
                         f"got {min(resolutions)}")

    bands = blend_band_widths(splits, blend_band)
    cascades = []
    for index, resolution in enumerate(resolutions):
        slice_near = splits[index] - (bands[index - 1] if index > 0 else 0.0)
        view_corners, view_sphere = _view_slice(projection, slice_near, splits[index + 1],
                                                stabilize)
        corners = _transform_points(world_from_view, view_corners)
        sphere = None
        if stabilize:
            # NOTE: the sphere is fitted in view space, where the slice does not depend on
            # the camera's position or orientation at all, so its radius (and the texel
            # size) is bit-for-bit the same while the camera turns.
            centre_view, radius = view_sphere
            sphere = (_transform_points(world_from_view, centre_view[None])[0], radius)
        square = None
        if depth_blocks is not None:
            previous = previous_squares[index] if stabilize and previous_squares is not None \
                and index < len(previous_squares) else None
            square = receiver_square(world_from_view, projection, depth_blocks, slice_near,
                                     splits[index + 1], rotation, previous,
                                     exact=not stabilize)
        fit = _fit_checked(_slice_corners(corners), rotation[:3, :3], resolution,
                           stabilize, margin, scene_near, sphere, square)
        fit.receiver_rectangle = square
        fit.split_near, fit.split_far = float(splits[index]), float(splits[index + 1])
        cascades.append(fit)
    return CascadeSet(cascades=cascades, splits=splits, scheme=scheme, notes=tuple(notes))


# --------------------------------------------------------------------------------------
# Caster culling
# --------------------------------------------------------------------------------------

# The last frame's per-block terms (``_receiver_terms``): (blocks, key, terms). Each
# cascade of a frame asks for them with the same blocks and camera.
_RECEIVER_TERMS = [None, None, None]


# The last blocks' view-window ends (``_block_window``): (ndc_low, ndc_high, projection,
# (x_lo, x_hi, y_lo, y_hi)).
_BLOCK_WINDOW = [None, None, None, None]


def _block_window(projection, ndc_low, ndc_high):
    """Each block's x and y ends on the view window (at depth 1 for perspective):
    (x_lo, x_hi, y_lo, y_hi). Kept while the corner arrays are the same objects and the
    projection is the same: a view the scene fills has the same held corner arrays every
    redraw (``shadow_plan.depth_blocks_from_reduction``), read-only."""
    held = _BLOCK_WINDOW
    if held[0] is ndc_low and held[1] is ndc_high and held[2] == projection:
        return held[3]
    left, right, bottom, top = projection.view_window()
    window = (left + (ndc_low[:, 0] + 1.0) * 0.5 * (right - left),
              left + (ndc_high[:, 0] + 1.0) * 0.5 * (right - left),
              bottom + (ndc_low[:, 1] + 1.0) * 0.5 * (top - bottom),
              bottom + (ndc_high[:, 1] + 1.0) * 0.5 * (top - bottom))
    # Only arrays that cannot change in place are worth holding on to.
    if not (ndc_low.flags.writeable or ndc_high.flags.writeable):
        held[:] = [ndc_low, ndc_high, projection, window]
    return window


def _receiver_terms(world_from_view, projection, blocks, light_from_world_rot):
    """Per screen block and light-frame axis: the least and greatest of a x + b y (- c)
    over the block's x and y ends, where (a, b, c) is that axis's row of the linear map from
    view space, and the offset of the map.

    NOTE: a block's corner is (x d, y d, -d) in view space (perspective; orthographic:
    (x, y, -d)) for x, y and d each at one of its two ends, and its light-frame xy is
    linear in it. So each axis's extreme over a block's 8 corners follows from the
    extremes of each term (bilinear in d for perspective) without forming the corners:
    the same bounds as transforming every corner, at a fraction of the work."""
    world_from_view = np.asarray(world_from_view, dtype=np.float64)
    key = (world_from_view.tobytes(),
           np.asarray(light_from_world_rot, dtype=np.float64).tobytes(), projection)
    if _RECEIVER_TERMS[0] is blocks and _RECEIVER_TERMS[1] == key:
        return _RECEIVER_TERMS[2]
    rotation_xy = _check_rotation(light_from_world_rot)[:2]
    x_lo, x_hi, y_lo, y_hi = _block_window(projection, blocks[0], blocks[1])
    linear = rotation_xy @ world_from_view[:3, :3]            # (2, 3)
    offset = rotation_xy @ world_from_view[:3, 3]
    is_perspective = bool(projection.is_perspective)
    rows = []
    for a, b, c in linear:
        # x_lo <= x_hi, so a x is least at x_lo when a >= 0, else at x_hi (the same
        # products a minimum of both would pick, at half the work); likewise b y.
        ax_lo, ax_hi = (a * x_lo, a * x_hi) if a >= 0.0 else (a * x_hi, a * x_lo)
        by_lo, by_hi = (b * y_lo, b * y_hi) if b >= 0.0 else (b * y_hi, b * y_lo)
        g_lo = ax_lo + by_lo
        g_hi = ax_hi + by_hi
        if is_perspective:
            g_lo, g_hi = g_lo - c, g_hi - c
        rows += [g_lo, g_hi]
    # x least, x greatest, y least, y greatest (1-D each: numpy's 2-D reductions and
    # broadcasts cost several times more here); and c of each axis.
    held = (rows, linear[:, 2].copy(), offset, is_perspective)
    _RECEIVER_TERMS[:] = [blocks, key, held]
    return held


def receiver_square(world_from_view, projection, blocks, near_depth, far_depth,
                    light_from_world_rot, previous=None, shrink_below=0.7, exact=False):
    """The rectangle (centre_xy, half_widths_xy) in the rotated light frame that holds every
    visible receiver between view depths ``near_depth`` and ``far_depth``, or None when no
    receiver is there.

    ``blocks``: (ndc_low (N, 2), ndc_high (N, 2), nearest (N,), farthest (N,)): screen
    blocks and the view-depth range of what each shows (the G-buffer reduced on the GPU).
    Each block's part of the slice is a small frustum piece; its 8 corners bound it.
    NOTE: each half width is rounded up to 1/32 of its leading power of two, and the
    ``previous`` rectangle (centre, half widths) is kept while the receivers still fit in
    it and it is less than 1/``shrink_below`` of what they need: small camera moves then
    leave the cascade where it was, and the texel size changes rarely, by whole steps.
    ``exact``: the receivers' own extent, neither rounded nor held (unstabilized
    cascades)."""
    _ndc_low, _ndc_high, nearest, farthest = blocks
    # Indices, not a mask: ``take`` is several times faster than boolean indexing here.
    inside = np.flatnonzero((farthest >= near_depth) & (nearest <= far_depth))
    if not len(inside):
        return None
    d0 = np.maximum(nearest.take(inside), near_depth)
    d1 = np.minimum(farthest.take(inside), far_depth)
    terms, c, offset, is_perspective = _receiver_terms(world_from_view, projection, blocks,
                                                       light_from_world_rot)
    positive = is_perspective and d0.min() > 0.0     # d1 >= d0 for a block inside
    # NOTE: the few numbers per axis below are Python floats (the same IEEE arithmetic as
    # numpy's, without its per-call cost on 2-element arrays).
    low, high = [], []
    for axis in range(2):
        g_lo, g_hi = terms[2 * axis].take(inside), terms[2 * axis + 1].take(inside)
        if positive:
            # d g is least at d0 or d1 times g's least, greatest at d0 or d1 times its
            # greatest, as d > 0.
            least = min((d0 * g_lo).min(), (d1 * g_lo).min())
            greatest = max((d0 * g_hi).max(), (d1 * g_hi).max())
        elif is_perspective:
            # Bilinear in (d, g): the extremes are at d0 or d1 times g's least or greatest.
            products = (d0 * g_lo, d1 * g_lo, d0 * g_hi, d1 * g_hi)
            least = min(float(p.min()) for p in products)
            greatest = max(float(p.max()) for p in products)
        else:
            depth = (-c[axis] * d0, -c[axis] * d1)
            least = (g_lo + np.minimum(*depth)).min()
            greatest = (g_hi + np.maximum(*depth)).max()
        low.append(float(least) + float(offset[axis]))
        high.append(float(greatest) + float(offset[axis]))
    centre = [0.5 * (lo + hi) for lo, hi in zip(low, high)]
    if exact:
        return np.array(centre), np.array([max(0.5 * (hi - lo), 1e-9)
                                           for lo, hi in zip(low, high)])
    half = [_round_up_dyadic(max(0.5 * (hi - lo), 1e-9), bits=6) for lo, hi in zip(low, high)]
    if previous is not None:
        old_centre, old_half = (np.asarray(v, dtype=np.float64) for v in previous)
        # The whole previous rectangle, while it holds every receiver and is not much too
        # big: the cascade then does not move at all (its shadow map can be kept).
        if all(lo >= oc - oh and hi <= oc + oh and oh < h / shrink_below
               for lo, hi, oc, oh, h in zip(low, high, old_centre.tolist(),
                                            old_half.tolist(), half)):
            return old_centre, old_half
    return np.array(centre), np.array(half)


def visible_depth_range(nearest, farthest, previous=None, steps_per_octave=8,
                        shrink_below=0.75):
    """The depth range sample-distribution shadow maps fit the cascades to, from the
    nearest and farthest view depth the G-buffer holds.

    NOTE: quantized outwards to a geometric grid (``steps_per_octave`` per doubling), and
    the ``previous`` range is kept while it still holds the new one and the new one's
    logarithmic span is not below ``shrink_below`` of it: small camera moves then leave the
    cascades exactly where they were (stabilized edges stay still, no re-rendered tiles),
    and a range that only grows or shrinks a little does not pop. Returns (near, far) or
    None when nothing is visible."""
    if not (np.isfinite(nearest) and np.isfinite(farthest)) or not 0.0 < nearest <= farthest:
        return None
    step = math.log(2.0) / steps_per_octave
    low = math.exp(math.floor(math.log(nearest) / step) * step)
    high = math.exp(math.ceil(math.log(farthest) / step + 1e-9) * step)
    if previous is not None:
        old_low, old_high = previous
        if old_low <= low and old_high >= high and \
                math.log(high / low) >= shrink_below * math.log(old_high / old_low):
            return previous
    return (low, high)


def aabbs_in_cascade(aabb_min_world, aabb_max_world, cascade, checked=False, rotated=None):
    """Which of N world AABBs may cast into the cascade: (N, 3), (N, 3) -> (N,) bool.

    Conservative: each box is taken to light space as the AABB of its 8 transformed corners
    (computed exactly as centre + |rotation| * half-extent), and it is kept when that
    overlaps the shadow box in x and y and its nearest-to-light point is not beyond the far
    plane. Anything between the light and the box stays: it can shadow the slice.
    ``checked``: the boxes are known to be finite float64 (N, 3) pairs with min <= max
    (``boxes_are_valid``), so they are not checked again for every cascade.
    ``rotated``: ``boxes_in_light_frame`` of these boxes for a light with this cascade's
    rotation (the cascades of one sun share it), so it is not computed again.
    """
    low = np.asarray(aabb_min_world, dtype=np.float64)
    high = np.asarray(aabb_max_world, dtype=np.float64)
    if not checked:
        _check_boxes(low, high)
    return _boxes_in_cascade(low, high, cascade, rotated)


def boxes_in_light_frame(aabb_min_world, aabb_max_world, light_from_world):
    """The part of culling (N, 3) world boxes that depends only on the light's rotation:
    their centres turned into the light's axes (before its translation) and their half
    extents along those axes, as ``aabbs_in_cascade`` computes them."""
    low = np.asarray(aabb_min_world, dtype=np.float64)
    high = np.asarray(aabb_max_world, dtype=np.float64)
    rotation = light_from_world[:3, :3]
    return 0.5 * (low + high) @ rotation.T, 0.5 * (high - low) @ np.abs(rotation).T


def boxes_are_valid(aabb_min_world, aabb_max_world):
    """Whether (N, 3) mins and maxs are what ``aabbs_in_cascade`` accepts."""
    try:
        _check_boxes(np.asarray(aabb_min_world, dtype=np.float64),
                     np.asarray(aabb_max_world, dtype=np.float64))
    except ValueError:
        return False
    return True


def _check_boxes(low, high):
    if low.ndim != 2 or low.shape[1] != 3 or low.shape != high.shape:
        raise ValueError(f"AABB mins and maxs must both be (N, 3), got {low.shape} "
                         f"and {high.shape}")
    bad = ~(np.all(np.isfinite(low), axis=1) & np.all(np.isfinite(high), axis=1)) | \
        np.any(low > high, axis=1)
    if np.any(bad):
        index = int(np.flatnonzero(bad)[0])
        raise ValueError(f"AABB {index} is not a box: min {low[index].tolist()}, "
                         f"max {high[index].tolist()}")


def _boxes_in_cascade(low, high, cascade, rotated=None):
    matrix = cascade.light_from_world
    if rotated is None:
        rotated = boxes_in_light_frame(low, high, matrix)
    centre_turned, extent = rotated
    centre = centre_turned + matrix[:3, 3]      # _transform_points, the rotation done
    near_low, near_high = centre - extent, centre + extent
    # NOTE: a relative tolerance keeps boxes that merely touch the shadow box (or sit a
    # rounding error away) in: wrongly culling a caster is visible, drawing one is not.
    slack = 1e-9 * (np.abs(cascade.box_max - cascade.box_min).max() + np.abs(centre).max(
        axis=1, initial=0.0))
    box_low, box_high = cascade.box_min, cascade.box_max
    overlap_xy = np.all((near_high[:, :2] >= box_low[:2] - slack[:, None])
                        & (near_low[:, :2] <= box_high[:2] + slack[:, None]), axis=1)
    # Light looks down -z: the point nearest the light has the largest z.
    before_far = near_high[:, 2] >= box_low[2] - slack
    return overlap_xy & before_far


def aabb_in_cascade(aabb_min_world, aabb_max_world, cascade):
    """Whether one world AABB may cast into the cascade (see ``aabbs_in_cascade``)."""
    low = vector3("AABB min", aabb_min_world)
    high = vector3("AABB max", aabb_max_world)
    return bool(aabbs_in_cascade(low[None], high[None], cascade)[0])


# --------------------------------------------------------------------------------------
# Spot lights
# --------------------------------------------------------------------------------------

def spot_light_matrices(world_from_light, spot_angle_rad, clip_start, clip_end):
    """``(light_from_world, clip_from_light)`` of a spot light's perspective shadow map.

    The spot looks down its local -Z; ``spot_angle_rad`` is the full cone angle (Blender's
    ``spot_size``), used as the vertical and horizontal field of view of a square map, so
    the cone fits the map's inscribed circle. Object scale is ignored: only the position
    and orientation of ``world_from_light`` count.
    """
    world_from_light = matrix4("spot world_from_light", world_from_light)
    angle = finite("spot angle", spot_angle_rad)
    if not 0.0 < angle < math.pi:
        raise ValueError(f"spot angle must be between 0 and pi radians (180 degrees) for a "
                         f"shadow map, got {angle}")
    clip_start, clip_end = finite("spot clip start", clip_start), \
        finite("spot clip end", clip_end)
    if not clip_start > 0.0:
        raise ValueError(f"spot clip start must be above 0, got {clip_start}")
    if not clip_end > clip_start:
        raise ValueError(f"spot clip end ({clip_end}) must be greater than clip start "
                         f"({clip_start})")
    # Remove scale and shear: Gram-Schmidt on the z (aim) axis first, so the aim is exact.
    z_axis = world_from_light[:3, 2]
    y_axis = world_from_light[:3, 1]
    if np.linalg.norm(z_axis) < 1e-12:
        raise ValueError("spot world_from_light has a zero Z axis (object scaled to 0)")
    z_axis = z_axis / np.linalg.norm(z_axis)
    x_axis = np.cross(y_axis, z_axis)
    if np.linalg.norm(x_axis) < 1e-12:
        x_axis = np.cross(np.array([0.0, 1.0, 0.0]) if abs(z_axis[1]) < 0.9
                          else np.array([1.0, 0.0, 0.0]), z_axis)
    x_axis = x_axis / np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    rigid = np.eye(4)
    rigid[:3, 0], rigid[:3, 1], rigid[:3, 2], rigid[:3, 3] = \
        x_axis, y_axis, z_axis, world_from_light[:3, 3]
    light_from_world = _rigid_inverse(rigid)
    clip_from_light = perspective_clip_from_view(angle, 1.0, clip_start, clip_end)
    return light_from_world, clip_from_light


# A point light's six cube faces, in the order the lighting shader picks them: the axis
# (0 x, 1 y, 2 z) and the sign of the direction from the light each face looks along.
POINT_LIGHT_FACES = ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0))


def point_light_face_angle(resolution, margin_texels):
    """Full field of view (radians) of one cube face of ``resolution`` texels: 90 degrees
    plus ``margin_texels`` on every side, so a filter's taps near a face's edge still read
    rendered texels (the shader picks the face by the largest axis, i.e. inside 90)."""
    return 2.0 * math.atan(1.0 / (1.0 - 2.0 * margin_texels / resolution))


def point_light_face_matrices(position, face, angle_rad, clip_start, clip_end):
    """``(light_from_world, clip_from_light)`` of cube face ``face`` (an index into
    POINT_LIGHT_FACES) of a point light at ``position``: a square perspective map looking
    from the light along that axis."""
    axis, sign = POINT_LIGHT_FACES[face]
    look = np.zeros(3)
    look[axis] = sign
    # Any up vector not along the look axis; the map's orientation does not matter.
    up = np.array([0.0, 0.0, 1.0]) if axis != 2 else np.array([0.0, 1.0, 0.0])
    z_axis = -look                 # lights look down their local -Z
    x_axis = np.cross(up, z_axis)
    y_axis = np.cross(z_axis, x_axis)
    world_from_light = np.eye(4)
    world_from_light[:3, 0], world_from_light[:3, 1], world_from_light[:3, 2] = \
        x_axis, y_axis, z_axis
    world_from_light[:3, 3] = np.asarray(position, dtype=np.float64)
    return spot_light_matrices(world_from_light, angle_rad, clip_start, clip_end)


def aabbs_in_point_light_face(lo, hi, position, face, reach):
    """Which (N, 3) boxes ``lo``..``hi`` may hold casters for cube face ``face`` of a point
    light at ``position`` whose light ends at ``reach``: the box meets the sphere of that
    radius and the face's pyramid (conservative: each of the pyramid's four planes through
    the light has some corner of the box on its inner side)."""
    lo = np.asarray(lo, dtype=np.float64) - position
    hi = np.asarray(hi, dtype=np.float64) - position
    nearest = np.clip(0.0, lo, hi)
    inside = np.einsum("ij,ij->i", nearest, nearest) <= reach * reach
    axis, sign = POINT_LIGHT_FACES[face]
    # Along the look axis, the box's farthest reach in the face's direction.
    along = hi[:, axis] if sign > 0 else -lo[:, axis]
    inside &= along > 0.0
    for other in (a for a in range(3) if a != axis):
        # sign * d[axis] >= +-d[other] somewhere in the box.
        inside &= along - lo[:, other] >= 0.0
        inside &= along + hi[:, other] >= 0.0
    return inside


def spot_texel_size(spot_angle_rad, resolution, distance):
    """Scene units covered by one spot shadow-map texel at ``distance`` along the aim."""
    return 2.0 * math.tan(0.5 * spot_angle_rad) * distance / resolution


# --------------------------------------------------------------------------------------
# Shader reference: cascade selection, blend band, far fade
# --------------------------------------------------------------------------------------

def select_cascade(view_depth, splits):
    """Cascade index per view depth (scene units), as the lighting shader picks it.

    Cascade ``i`` covers ``splits[i] <= d < splits[i+1]``; depths before the first split
    use cascade 0, depths at or beyond the shadow distance (``splits[-1]``) and NaN give -1
    (unshadowed). Works on scalars and arrays.
    """
    depth = np.asarray(view_depth, dtype=np.float64)
    splits = np.asarray(splits, dtype=np.float64)
    index = np.searchsorted(splits[1:], depth, side="right")
    index = np.where((depth >= splits[-1]) | np.isnan(depth), -1, index)
    return index.astype(np.int64) if index.ndim else int(index)


def blend_band_widths(splits, blend_band):
    """Blend band per cascade (scene units): ``blend_band`` capped at half of that
    cascade's depth range, so a band never reaches back past the middle of its cascade.
    The last cascade has no band (0): the far fade handles the shadow distance."""
    splits = np.asarray(splits, dtype=np.float64)
    band = finite("blend band", blend_band)
    if band < 0.0:
        raise ValueError(f"blend band must not be negative, got {band}")
    widths = np.minimum(band, 0.5 * np.diff(splits))
    widths[-1] = 0.0
    return widths


def blend_weight(view_depth, splits, blend_band):
    """Weight (0..1) of the *next* cascade at each view depth, as the shader mixes them.

    The band lies on the near side of each split, inside the nearer cascade ``i``: it
    starts at ``splits[i+1] - band`` (weight 0) and ends at the split (weight 1, linear),
    where cascade ``i+1`` takes over alone; so the farther cascade fades in *before* the
    split and the switch at the split is seamless. The shader computes
    ``mix(shadow_i, shadow_next, weight)``. 0 outside bands and for the last cascade.
    """
    depth = np.asarray(view_depth, dtype=np.float64)
    splits = np.asarray(splits, dtype=np.float64)
    widths = blend_band_widths(splits, blend_band)
    index = np.atleast_1d(select_cascade(depth, splits))
    flat_depth = np.atleast_1d(depth)
    safe = np.clip(index, 0, len(widths) - 1)
    width = widths[safe]
    start = splits[safe + 1] - width
    with np.errstate(divide="ignore", invalid="ignore"):
        weight = np.where(width > 0.0, (flat_depth - start) / width, 0.0)
    weight = np.where(index >= 0, np.clip(weight, 0.0, 1.0), 0.0)
    return weight.reshape(depth.shape) if depth.ndim else float(weight[0])


def distance_fade(view_depth, shadow_distance, fade_fraction):
    """Shadow strength (1 = full, 0 = none) fading out over the last ``fade_fraction`` of
    the shadow distance, linearly, reaching 0 at the shadow distance. ``fade_fraction`` 0
    is a hard cut."""
    depth = np.asarray(view_depth, dtype=np.float64)
    far = finite("shadow distance", shadow_distance)
    fraction = finite("fade fraction", fade_fraction)
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fade fraction must be in 0..1, got {fraction}")
    if fraction == 0.0:
        strength = np.where(depth < far, 1.0, 0.0)
    else:
        strength = np.clip((far - depth) / (fraction * far), 0.0, 1.0)
    return strength if depth.ndim else float(strength)
