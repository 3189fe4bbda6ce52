"""Fitting each cascade's orthographic shadow box to its slice of the camera's frustum.

Owns ``CascadeFit`` (one cascade's box and matrices), ``CascadeSet`` (one frame's),
``fit_cascade`` (one box: the stabilized square around the slice's bounding sphere, that
square narrowed to the slice's visible receivers, or the tight unstabilized box) and
``compute_cascades`` (splits, rotation, checks and every cascade of one camera and one
sun), with the occluder margin that pulls each near plane back toward the sun.
numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..camera import as_projection
from ..checks import finite, matrix4, vector3
from ..memo import ValueMemo
from .holding import CascadeNeed, hold_cascade, lead_box
from .quantizing import quantized_box, quantized_depths
from .receivers import ReceiverTermsCache, receiver_square, rounded_square
from .spaces import (_bounds, _box_corners, _check_rotation, _rigid_inverse,
                     _transform_points, light_view_matrix, orthographic_clip_from_view,
                     view_slice_corners)
from .splits import _resolution, blend_band_widths, cascade_resolutions, split_distances
from .stabilization import (_round_up_dyadic, _view_space_sphere, bounding_sphere,
                            round_up_radius, snap_to_texel_grid)


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
    - ``receiver_rectangle``: the (centre_xy, half widths) of the slice's visible
      receivers the box was narrowed to (``receivers.receiver_square``), or None.
    - ``need_centre_xy``, ``need_half_xy``: the centre and half widths of what the box had
      to hold when it was fitted (``holding.CascadeNeed``, rotated light frame; stabilized
      only): a box fitted later is put ahead of where that moved (``holding.lead_box``),
      with more room on an axis where it grew.
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
    receiver_rectangle: tuple | None = None
    need_centre_xy: np.ndarray | None = None
    need_half_xy: np.ndarray | None = None

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


# The slice's view-space corners for (projection, near depth, far depth): the same for
# every redraw that only moves the camera.
_view_slice_corners = ValueMemo(
    view_slice_corners, 64,
    key=lambda projection, near_d, far_d: (projection, float(near_d), float(far_d)))


def _view_slice(projection, near_d, far_d, with_sphere):
    """The slice's view-space corners and, ``with_sphere``, their bounding sphere (in
    view space, where it is exactly the same for every camera position and turn)."""
    corners = _view_slice_corners(projection, near_d, far_d)
    return corners, _view_space_sphere(corners) if with_sphere else None


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


class _LightBox(NamedTuple):
    """What a fit decides, in the rotated light frame (light axes, world origin; depth
    along the light is -z): the box's x/y extent and centre, the depths (along the light)
    of the receivers' nearest and farthest points, the texel size per axis and, for
    stabilized fits, the sphere the box was built around."""
    centre_xy: np.ndarray
    low_xy: np.ndarray
    high_xy: np.ndarray
    nearest_depth: float
    farthest_depth: float
    texel_xy: np.ndarray
    sphere_centre: np.ndarray | None
    sphere_radius: float


def _fit_checked(corners, rotation, resolution, stabilize, margin, scene_near,
                 bounding_sphere_world, receiver_box, held=None, receivers=None,
                 quantize=False):
    """``fit_cascade`` on checked inputs: (8, 3) corners, a 3x3 rotation, an int
    resolution, a float margin, the scene's ``_scene_near_depth`` or None, a (centre,
    radius) sphere or None. ``compute_cascades`` checks its inputs once per frame and calls
    this per cascade (the checks cost as much as the fit).
    ``held``: the ``CascadeFit`` this cascade had the frame before (stabilized only): kept
    while it holds this frame's receivers (``holding.hold_cascade``); a refitted box is
    put ahead of them in the direction they moved (``holding.lead_box``). ``receivers``:
    the receivers' own rectangle (unrounded) that ``receiver_box`` was widened from; the
    box must hold it (None: ``receiver_box`` itself). ``quantize`` (stabilized only): the
    box is ``_quantized_box`` of the receivers, whatever ``held``."""
    if not stabilize:
        box = _tight_box(corners, rotation, resolution, receiver_box)
        return _cascade_from_box(box, rotation, resolution, stabilize, margin, scene_near)
    if bounding_sphere_world is None:
        centre_world, radius = bounding_sphere(corners)
    else:
        centre_world, radius = bounding_sphere_world
    radius = round_up_radius(max(radius, 1e-9))
    if quantize:
        box = _quantized_box(corners, rotation, resolution, centre_world, radius,
                             receiver_box if receivers is None else receivers, margin,
                             scene_near)
        return _cascade_from_box(box, rotation, resolution, stabilize, 0.0, None)
    if receiver_box is None:
        box = _sphere_box(centre_world, radius, rotation, resolution)
    else:
        box = _receiver_box(centre_world, radius, rotation, resolution, receiver_box)
    need = _need(corners, rotation, receiver_box if receivers is None else receivers, box,
                 margin, scene_near)
    compatible = held is not None and held.resolution == resolution and held.stabilized \
        and held.light_from_world[:3, :3].tobytes() == rotation.tobytes()
    centre_xy = lead_box(box.centre_xy, 0.5 * (box.high_xy - box.low_xy), box.texel_xy, need,
                         held.need_centre_xy if compatible else None)
    if centre_xy is not box.centre_xy:
        shift = centre_xy - box.centre_xy
        box = box._replace(centre_xy=centre_xy, low_xy=box.low_xy + shift,
                           high_xy=box.high_xy + shift)
    fresh = _cascade_from_box(box, rotation, resolution, stabilize, margin, scene_near)
    fresh.need_centre_xy = 0.5 * (need.low_xy + need.high_xy)
    fresh.need_half_xy = 0.5 * (need.high_xy - need.low_xy)
    return hold_cascade(held, fresh, need) if compatible else fresh


def _quantized_box(corners, rotation, resolution, centre_world, radius, receivers, margin,
                   scene_near):
    """The stabilized fit of a final render (``quantizing.quantized_box``): the box around
    the slice's sphere (``radius`` rounded up), or around the receivers' rectangle
    (unrounded) where that is smaller, its depths from the occluder margin before the
    sphere to the sphere's far side, each on a coarse grid. Its near plane is final (the
    margin is in it)."""
    if receivers is None:
        centre_xy = (rotation @ centre_world)[:2]
        low, high = centre_xy - radius, centre_xy + radius
    else:
        low, high = _receivers_rectangle(corners, rotation, receivers)
    centre_xy, texel = quantized_box(low, high, resolution, largest_half=radius)
    half = 0.5 * resolution * texel
    sphere_depth = -float(rotation[2] @ centre_world)
    near_depth = sphere_depth - radius - margin
    if scene_near is not None:
        near_depth = min(near_depth, scene_near)
    near_depth, far_depth = quantized_depths(near_depth, sphere_depth + radius,
                                             2.0 * radius + margin)
    return _LightBox(centre_xy, centre_xy - half, centre_xy + half, near_depth, far_depth,
                     texel, centre_world, radius)


def _receivers_rectangle(corners, rotation, receiver_box):
    """(low, high) in the rotated light frame of the slice's corners' rectangle, cut to
    the receivers' (``receiver_box``: centre and half widths) when there is one."""
    corners_xy = corners @ rotation[:2].T
    low, high = corners_xy.min(axis=0), corners_xy.max(axis=0)
    if receiver_box is not None:
        centre = np.asarray(receiver_box[0], dtype=np.float64)
        half = np.asarray(receiver_box[1], dtype=np.float64)
        cut_low, cut_high = np.maximum(low, centre - half), np.minimum(high, centre + half)
        if np.all(cut_high >= cut_low):
            low, high = cut_low, cut_high
    return low, high


def _need(corners, rotation, receiver_box, box, margin, scene_near):
    """The ``holding.CascadeNeed`` of a stabilized fit: the slice's corners' rectangle in
    the rotated light frame, cut to the receivers' (``receiver_box``) when there is one;
    the depths the sphere's box spans (its near side pulled back by the margin)."""
    low, high = _receivers_rectangle(corners, rotation, receiver_box)
    sphere_depth = -float(rotation[2] @ box.sphere_centre)
    near_depth = sphere_depth - box.sphere_radius - margin
    if scene_near is not None:
        near_depth = min(near_depth, scene_near)
    return CascadeNeed(low, high, near_depth, sphere_depth + box.sphere_radius,
                       3.0 * _depth_step(box.sphere_radius))


def _depth_step(radius):
    """The grid a stabilized box's depths are widened to: 1/16 of the sphere's radius,
    rounded up to a power of two."""
    return _round_up_dyadic(radius / 16.0, bits=1)


def _sphere_box(centre_world, radius, rotation, resolution, radius_xy=None):
    """The stabilized fit: a box around the slice's bounding sphere (``radius`` already
    rounded up), snapped to whole texels. ``radius_xy``: per-axis half widths narrower
    than the sphere (``_receiver_box``); the depth range still comes from the sphere."""
    if radius_xy is None:
        radius_xy = np.array([radius, radius])
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
    # NOTE: the sphere follows the camera, so its far side moves with every step; widened
    # to a coarse grid (1/16 of the radius) and one step more, the far plane stays put for
    # a while, and a box kept from the frame before (``holding.hold_cascade``) keeps its
    # depths while the sphere's far side is inside them. The near side is where the
    # occluder margin is measured from: it stays exact.
    step = _depth_step(radius)
    return _LightBox(centre_xy, centre_xy - half, centre_xy + half,
                     nearest_depth=-centre_rot[2] - radius,
                     farthest_depth=math.ceil((-centre_rot[2] + radius) / step) * step + step,
                     texel_xy=texel, sphere_centre=centre_world, sphere_radius=radius)


def _receiver_box(centre_world, radius, rotation, resolution, receiver_box):
    """The stabilized fit narrowed to the slice's visible receivers (sample-distribution
    shadow maps): the receivers' rectangle where it is smaller than the sphere, its depth
    range widened to a coarse grid."""
    radius_xy = None
    if np.any(np.asarray(receiver_box[1]) < radius):
        # The receivers' rectangle: its centre, and its half widths as per-axis "radii"
        # (the depth range below still comes from the sphere, which holds every
        # receiver of the slice).
        centre_rot_xy = np.asarray(receiver_box[0], dtype=np.float64)
        centre_world = rotation.T @ np.array([centre_rot_xy[0], centre_rot_xy[1],
                                              (rotation @ centre_world)[2]])
        radius_xy = np.minimum(np.asarray(receiver_box[1], dtype=np.float64), radius)
    box = _sphere_box(centre_world, radius, rotation, resolution, radius_xy)
    # NOTE: the sphere's near side moves with every camera step too; on a coarse grid
    # (the far side's), it stays put while the receivers' rectangle does.
    step = _depth_step(radius)
    return box._replace(nearest_depth=math.floor(box.nearest_depth / step) * step)


def _tight_box(corners, rotation, resolution, receiver_box):
    """The unstabilized fit: the light-space box of the slice's corners, cut to the
    receivers' rectangle when one is given. The most resolution for a still image; it
    moves and rescales with every camera step, so its edges swim."""
    corners_rot = corners @ rotation.T
    low_xy, high_xy = corners_rot[:, :2].min(axis=0), corners_rot[:, :2].max(axis=0)
    if receiver_box is not None:
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
    return _LightBox(0.5 * (low_xy + high_xy), low_xy, high_xy,
                     nearest_depth=float(-corners_rot[:, 2].max()),
                     farthest_depth=float(-corners_rot[:, 2].min()),
                     texel_xy=(high_xy - low_xy) / resolution,
                     sphere_centre=None, sphere_radius=math.nan)


def _cascade_from_box(box, rotation, resolution, stabilize, margin, scene_near):
    """The ``CascadeFit`` of a fitted box: its near plane pulled back toward the light by
    the occluder margin (and to the scene's nearest corner), its far plane the slice's
    far side (receivers only exist inside the slice)."""
    centre_xy, low_xy, high_xy = box.centre_xy, box.low_xy, box.high_xy
    near_depth = box.nearest_depth - margin
    if scene_near is not None:
        near_depth = min(near_depth, scene_near)
    farthest_depth = box.farthest_depth
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
        texel_size_world=float(box.texel_xy.max()),
        box_min=np.array([-half_xy[0], -half_xy[1], -depth]),
        box_max=np.array([half_xy[0], half_xy[1], 0.0]),
        near=0.0, far=float(depth), stabilized=bool(stabilize),
        sphere_center_world=box.sphere_centre, sphere_radius=box.sphere_radius,
        texel_size_xy=box.texel_xy)


# NOTE: a stabilized cascade refitted to its visible receivers in a view that had a box
# the frame before is this much wider than they are on each side (a share of their half
# width): room to drift into while the camera moves, so the box (and its shadow map) is
# kept for a while (``holding``). Texel density costs as much. A view's first fit (a
# single render) has none: it is the sharpest.
RECEIVER_ROOM = 1.0 / 32.0


def _room(receivers, before):
    """Per axis, the share of the receivers' half width a refitted box gets as room: none
    for a view's first fit, ``RECEIVER_ROOM``, twice that on an axis where what the box
    had to hold grew since the box before was fitted (a view turning toward a longer
    stretch of ground keeps growing it)."""
    if before is None:
        return np.zeros(2)
    if before.need_half_xy is None:
        return np.full(2, RECEIVER_ROOM)
    grew = np.asarray(receivers[1]) > before.need_half_xy
    return np.where(grew, 2.0 * RECEIVER_ROOM, RECEIVER_ROOM)


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
                     depth_blocks=None, held=None, receiver_cache=None, quantize=False):
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
      up, with ``RECEIVER_ROOM`` to spare after a ``held`` one; unstabilized: exactly),
      when that is
      smaller than its slice's sphere.
    - ``held``: the last frame's ``CascadeFit`` per cascade (stabilized only): each is
      kept while it still holds its slice's receivers and is not much coarser than a fresh
      fit (``holding.hold_cascade``), so its shadow map need not be drawn again.
    - ``receiver_cache``: a ``receivers.ReceiverTermsCache`` the view keeps from frame to
      frame (None: one for this call).
    - ``quantize`` (stabilized only; ``held`` is then not read): each box is a step
      function of its receivers (``quantizing``): renders whose receivers differ a little
      get the same boxes, and each box depends on this call's arguments alone (a final
      render's).

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
    if depth_blocks is not None and receiver_cache is None:
        receiver_cache = ReceiverTermsCache()     # every cascade reads the same terms
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
        before = held[index] if stabilize and not quantize and held is not None and \
            index < len(held) else None
        square = receivers = None
        if depth_blocks is not None:
            receivers = receiver_square(world_from_view, projection, depth_blocks,
                                        slice_near, splits[index + 1], rotation, exact=True,
                                        cache=receiver_cache)
            square = receivers if receivers is None or not stabilize or quantize else \
                rounded_square(receivers, _room(receivers, before))
        fit = _fit_checked(_slice_corners(corners), rotation[:3, :3], resolution,
                           stabilize, margin, scene_near, sphere, square, before, receivers,
                           quantize)
        fit.receiver_rectangle = square
        fit.split_near, fit.split_far = float(splits[index]), float(splits[index + 1])
        cascades.append(fit)
    return CascadeSet(cascades=cascades, splits=splits, scheme=scheme, notes=tuple(notes))
