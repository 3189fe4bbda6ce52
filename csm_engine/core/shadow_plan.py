"""Shadow planning for one frame: which shadow maps to draw, where in the atlas, with
which matrices, and the lighting pass's uniform block.

Pure functions of a ``FrameSnapshot`` (plain data) and the scene bounds: ``plan_shadows``
(cascade splits and light matrices through ``cascades``, spot-light tiles),
``layout_atlas`` (shelf packing) and ``pack_frame`` (std140 data for ``FRAME_LAYOUT``).
The GPU side (``render/pipeline.py``) only executes the plan. numpy only.
"""

from dataclasses import dataclass

import numpy as np

from . import cascades
from .frame import spot_cone_cosines
from .frame_layout import (DEBUG_VIEW_INDEX, FRAME_LAYOUT, MAX_CASCADES, MAX_POINT_LIGHTS,
                           MAX_SHADOW_TILES, MAX_SPOT_LIGHTS, PCF_PATTERN_INDEX)

CASCADE_LINE_COLORS = ((1, .2, .2, 1), (.2, 1, .2, 1), (.3, .4, 1, 1), (1, 1, .2, 1))

# Maps OpenGL clip space (-1..1 on every axis) to window/texture space (0..1).
WINDOW_FROM_CLIP = np.array([[.5, 0, 0, .5], [0, .5, 0, .5], [0, 0, .5, .5], [0, 0, 0, 1.]])
MAX_ATLAS_WIDTH = 8192
SPOT_SHADOW_RESOLUTION = 1024

# Cascades kept while "Freeze Cascades" is on, per scene. Plain numpy data, no GPU objects.
_FROZEN = {}


@dataclass
class ShadowTile:
    clip_from_world: np.ndarray
    resolution: int
    texel_world: float         # orthographic: scene units per texel; perspective: per unit dist
    near: float
    far: float
    is_perspective: bool
    origin: tuple = (0, 0)     # atlas texels
    cascade: object = None     # cascades.CascadeFit for sun tiles
    display_near: float = 0.0  # where the scene starts in this light's depth (debug view)


@dataclass
class ShadowPlan:
    tiles: list
    cascade_count: int
    splits: np.ndarray         # count+1 view depths
    bands: np.ndarray          # blend band before each far split
    shadow_distance: float
    spot_tiles: dict           # spot index -> tile index
    frozen_camera: object = None
    warnings: list = None      # settings that could not be honoured, in the user's words


def instance_bounds(instances, meshes):
    """(N,3) world-space min and max of each instance's mesh bounds."""
    rows = [(i.world_from_object, meshes[i.key]) for i in instances if i.key in meshes]
    if not rows:
        return None
    matrices = np.stack([m for m, _ in rows])                          # (N,4,4)
    lo = np.stack([g.aabb_min for _, g in rows])
    hi = np.stack([g.aabb_max for _, g in rows])
    # 8 corners per box, via a bit pattern choosing lo or hi on each axis.
    pick = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=bool)
    corners = np.where(pick[None], hi[:, None, :], lo[:, None, :])      # (N,8,3)
    world = np.einsum("nij,nkj->nki", matrices[:, :3, :3], corners) + matrices[:, None, :3, 3]
    return world.min(axis=1), world.max(axis=1)


def plan_shadows(snap, bounds):
    """Cascade splits and light matrices for this frame (pure math, see cascades.py)."""
    s = snap.settings
    camera = snap.camera
    tiles = []
    spot_tiles = {}
    count = int(s.cascade_count)
    distance = s.shadow_distance if s.shadow_distance > 0 else camera.clip_end
    distance = float(min(max(distance, camera.clip_start * 1.001), camera.clip_end))
    splits = np.array([camera.clip_start, distance])
    bands = np.zeros(MAX_CASCADES)
    frozen_camera = None
    warnings = []
    if snap.sun is not None and snap.sun.casts_shadow:
        margin = None if s.occluder_margin_auto else float(s.occluder_margin)
        manual = cascades.manual_splits_from_fractions(distance, s.manual_splits, count)
        key = snap.scene_name
        if s.freeze_cascades and key in _FROZEN:
            result, frozen_camera = _FROZEN[key]
        else:
            arguments = dict(
                count=count, scheme=s.split_scheme, lam=float(s.split_lambda),
                manual=manual if s.split_scheme == 'MANUAL' else None,
                shadow_distance=distance, base_resolution=int(s.resolution),
                equal_resolution=bool(s.equal_resolution), stabilize=bool(s.stabilize),
                occluder_margin=margin, blend_band=float(s.blend_band),
                # Auto: the near plane reaches the scene's bounds, so no caster is clipped.
                # Manual: exactly the margin the user typed, nothing added.
                scene_bounds=bounds if s.occluder_margin_auto else None)
            try:
                result = cascades.compute_cascades(
                    camera.world_from_view, camera.clip_from_view, -snap.sun.to_light,
                    **arguments)
            except ValueError as error:
                # An impossible setting (e.g. manual splits that do not increase): say which
                # and draw with hybrid splits rather than fail the frame.
                warnings.append(f"{error}; using hybrid splits instead")
                arguments.update(scheme="HYBRID", manual=None)
                result = cascades.compute_cascades(
                    camera.world_from_view, camera.clip_from_view, -snap.sun.to_light,
                    **arguments)
            warnings.extend(result.notes)
            if s.freeze_cascades:
                _FROZEN[key] = (result, camera)
                frozen_camera = camera
            else:
                _FROZEN.pop(key, None)
        splits = result.splits
        bands = np.zeros(MAX_CASCADES)
        bands[:count] = cascades.blend_band_widths(splits, float(s.blend_band))
        for fit in result.cascades:
            tiles.append(ShadowTile(fit.clip_from_world, fit.resolution, fit.texel_size_world,
                                    fit.near, fit.far, False, cascade=fit))
    else:
        count = 0
    for index, spot in enumerate(snap.spots[:MAX_SPOT_LIGHTS]):
        if not spot.casts_shadow or len(tiles) >= MAX_SHADOW_TILES:
            continue
        resolution = min(SPOT_SHADOW_RESOLUTION, int(s.resolution))
        near = max(spot.clip_start, 1e-3)
        far = max(spot.radius, near * 2.0)
        light_from_world, clip_from_light = cascades.spot_light_matrices(
            spot.world_from_light, min(spot.spot_size, np.radians(179.0)), near, far)
        # A 180 degree cone has no perspective projection; 179 is the widest we draw.
        half = 0.5 * min(spot.spot_size, np.radians(179.0))
        spot_tiles[index] = len(tiles)
        tiles.append(ShadowTile(clip_from_light @ light_from_world, resolution,
                                2.0 * np.tan(half) / resolution, near, far, True))
    if bounds is not None:
        # The shadow-map view stretches depth over the part the scene occupies; the occluder
        # margin alone would squeeze all content into the last few percent of grey.
        corners = np.array([[bounds[i & 1][0], bounds[(i >> 1) & 1][1], bounds[(i >> 2) & 1][2],
                             1.0] for i in range(8)])
        for tile in tiles:
            clip = corners @ tile.clip_from_world.T
            window = np.clip(clip[:, 2] / clip[:, 3] * 0.5 + 0.5, 0.0, 1.0).min()
            if tile.is_perspective:
                ndc = window * 2.0 - 1.0
                tile.display_near = 2.0 * tile.near * tile.far / (
                    tile.far + tile.near - ndc * (tile.far - tile.near))
            else:
                tile.display_near = tile.near + window * (tile.far - tile.near)
    return ShadowPlan(tiles, count, np.asarray(splits, dtype=np.float64),
                      np.asarray(bands, dtype=np.float64), distance, spot_tiles, frozen_camera,
                      warnings)


def layout_atlas(tiles):
    """Shelf-pack square tiles into one atlas; returns (width, height) in texels."""
    x = y = row_height = width = 0
    for tile in tiles:
        if x + tile.resolution > MAX_ATLAS_WIDTH and x > 0:
            x, y = 0, y + row_height
            row_height = 0
        tile.origin = (x, y)
        x += tile.resolution
        row_height = max(row_height, tile.resolution)
        width = max(width, x)
    return max(width, 1), max(y + row_height, 1)


def pack_frame(snap, plan):
    """The lighting pass's uniform block for this frame (std140 float32 array)."""
    s = snap.settings
    camera = snap.camera
    data = FRAME_LAYOUT.new_data()
    put = FRAME_LAYOUT.set
    put(data, "clip_from_world", camera.clip_from_world)
    put(data, "view_from_world", np.linalg.inv(camera.world_from_view))
    put(data, "world_from_clip", np.linalg.inv(camera.clip_from_world))
    put(data, "camera_position", [*camera.position, 1.0 if camera.is_perspective else 0.0])
    put(data, "camera_forward", [*camera.forward, 0.0])
    put(data, "viewport", [camera.width, camera.height, 1.0 / camera.width, 1.0 / camera.height])
    put(data, "ambient", [*snap.ambient, 0.0 if snap.film_transparent else 1.0])
    put(data, "background", [*snap.background, 1.0])
    if snap.sun is not None:
        put(data, "sun_direction", [*snap.sun.to_light, 1.0])
        put(data, "sun_color", [*snap.sun.color, 1.0 if plan.cascade_count else 0.0])
    fade_start = plan.shadow_distance * (1.0 - s.fade_fraction) if s.fade_out \
        else plan.shadow_distance * 2.0
    put(data, "shadow_params", [plan.cascade_count, plan.shadow_distance, fade_start, 0.0])
    put(data, "filter_params", [s.pcf_radius, PCF_PATTERN_INDEX[s.pcf_pattern],
                                s.depth_bias, s.slope_bias])
    points = snap.points[:MAX_POINT_LIGHTS]
    spots = snap.spots[:MAX_SPOT_LIGHTS]
    put(data, "bias_params", [s.normal_offset, len(spots), len(points), 0.0])
    put(data, "debug_params", [DEBUG_VIEW_INDEX[s.debug_view], s.debug_shadow_map,
                               1.0 if s.debug_inset else 0.0, 0.0])
    far = np.full(MAX_CASCADES, 1e30)
    near = np.zeros(MAX_CASCADES)
    far[:plan.cascade_count] = plan.splits[1:plan.cascade_count + 1]
    near[:plan.cascade_count] = plan.splits[:plan.cascade_count]
    put(data, "cascade_splits", far)
    put(data, "cascade_near", near)
    put(data, "cascade_band", plan.bands[:MAX_CASCADES])
    for t, tile in enumerate(plan.tiles):
        put(data, "shadow_from_world", WINDOW_FROM_CLIP @ tile.clip_from_world, t)
        put(data, "shadow_tiles", [tile.origin[0], tile.origin[1], tile.resolution,
                                   tile.texel_world], t)
        put(data, "shadow_depth", [tile.near, tile.far, 1.0 if tile.is_perspective else 0.0,
                                   tile.display_near], t)
    for i, light in enumerate(points):
        put(data, "point_lights", [*light.position, light.radius], 2 * i)
        put(data, "point_lights", [*light.color, 0.0], 2 * i + 1)
    for i, spot in enumerate(spots):
        cos_outer, cos_inner = spot_cone_cosines(spot)
        put(data, "spot_lights", [*spot.position, spot.radius], 4 * i)
        put(data, "spot_lights", [*spot.color, plan.spot_tiles.get(i, -1)], 4 * i + 1)
        put(data, "spot_lights", [*spot.direction, cos_outer], 4 * i + 2)
        put(data, "spot_lights", [cos_inner, 0.0, 0.0, 0.0], 4 * i + 3)
    return data


def front_to_back(snap, bounds_lo_hi):
    """Instance indices sorted by the view depth of their bounds' centres."""
    if bounds_lo_hi is None:
        return range(len(snap.instances))
    centres = 0.5 * (bounds_lo_hi[0] + bounds_lo_hi[1])
    return np.argsort(centres @ np.asarray(snap.camera.forward, dtype=np.float64))


def world_positions(camera, view_depth):
    """(H, W, 3) world positions of pixel centres at the given view depths: the same
    reconstruction as ``world_position_at`` in lighting_frag.glsl, in float64."""
    height, width = view_depth.shape
    x = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    y = (np.arange(height) + 0.5) / height * 2.0 - 1.0
    ndc = np.stack(np.broadcast_arrays(x[None, :], y[:, None]), axis=-1)     # (H, W, 2)
    world_from_clip = np.linalg.inv(camera.clip_from_world)
    points = []
    for z in (-1.0, 1.0):
        clip = np.concatenate([ndc, np.full(ndc.shape[:2] + (1,), z),
                               np.ones(ndc.shape[:2] + (1,))], axis=-1)
        world = clip @ world_from_clip.T
        points.append(world[..., :3] / world[..., 3:])
    position = np.asarray(camera.position, dtype=np.float64)
    forward = np.asarray(camera.forward, dtype=np.float64)
    near_depth = (points[0] - position) @ forward
    far_depth = (points[1] - position) @ forward
    t = (view_depth - near_depth) / (far_depth - near_depth)
    return points[0] + (points[1] - points[0]) * t[..., None]

