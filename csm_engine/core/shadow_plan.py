"""Shadow planning for one frame: which shadow maps to draw, where in the atlas, with
which matrices, and the lighting pass's uniform block.

Pure functions of a ``FrameSnapshot`` (plain data) and the scene bounds: ``plan_shadows``
(cascade splits and light matrices through ``cascades``, spot-light tiles),
``layout_atlas`` (shelf packing) and ``pack_frame`` (std140 data for ``FRAME_LAYOUT``).
The GPU side (``render/pipeline.py``) only executes the plan. numpy only.
"""

import math
from dataclasses import dataclass

import numpy as np

from . import cascades
from .frame import spot_cone_cosines
from .frame_layout import (CASCADE_SELECTION_INDEX, DEBUG_VIEW_INDEX, FRAME_LAYOUT,
                           LIGHT_FALLOFF_INDEX, MAX_CASCADES, MAX_POINT_LIGHTS,
                           MAX_POINT_SHADOWS, MAX_SHADOW_TILES, MAX_SPOT_LIGHTS,
                           PCF_PATTERN_INDEX)
from .matrices import inverse_projection, inverse_rigid, inverse_transpose_3x3

CASCADE_LINE_COLORS = ((1, .2, .2, 1), (.2, 1, .2, 1), (.3, .4, 1, 1), (1, 1, .2, 1))

# Maps OpenGL clip space (-1..1 on every axis) to window/texture space (0..1).
WINDOW_FROM_CLIP = np.array([[.5, 0, 0, .5], [0, .5, 0, .5], [0, 0, .5, .5], [0, 0, 0, 1.]])
MAX_ATLAS_WIDTH = 8192
SPOT_SHADOW_RESOLUTION = 1024
POINT_SHADOW_RESOLUTION = 512      # texels per cube face
# Texels each cube face reaches past 90 degrees, so PCF kernels up to radius 3 (and the
# bilinear taps' extra texel) near a face's edge read rendered texels; wider kernels and
# soft penumbrae there read the face's edge texels again (taps are clamped to the tile).
POINT_FACE_MARGIN_TEXELS = 4

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
    # Scene units per texel along the tile's x and y. Fit to Visible Depth makes a cascade's
    # box rectangular, so its texels are too; texel_world is the larger. None: square.
    texel_world_xy: tuple = None
    # A point light's cube face: (light position, face index into
    # cascades.POINT_LIGHT_FACES, reach), for caster culling. None for other tiles.
    point_face: tuple = None

    def texel_world_per_axis(self):
        """(x, y) scene units per texel (perspective: per unit of distance)."""
        if self.texel_world_xy is None:
            return (self.texel_world, self.texel_world)
        return self.texel_world_xy


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
    point_shadow_count: int = 0    # the first this many snap.points have six tiles each,
    point_shadow_tiles: int = 0    # from this tile index on (+x, -x, +y, -y, +z, -z)


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


# Scene name -> the depth range and per-cascade receiver squares the cascades were last
# fitted to (Fit to Visible Depth); kept so that the next frame can hold them
# (the hysteresis of cascades.visible_depth_range and cascades.receiver_square).
_DEPTH_RANGES = {}


def depth_blocks_from_reduction(pairs, block_pixels, width, height):
    """Screen blocks of the G-buffer reduction -> what ``cascades.receiver_square`` reads:
    (ndc_low, ndc_high, nearest, farthest) of the blocks that show anything.
    ``pairs``: (rows, cols, 2) nearest / farthest view depth per block (rows bottom-up;
    nearest > 1e37 where a block shows only background)."""
    pairs = np.asarray(pairs)
    nearest = pairs[..., 0].astype(np.float64).ravel()
    farthest = pairs[..., 1].astype(np.float64).ravel()
    ndc_low, ndc_high = _block_corners(pairs.shape[:2], block_pixels, width, height)
    shown = nearest < 1e37
    # NOTE: a view that the scene fills shows something in every block: the corners are
    # then the held arrays themselves. Otherwise indices and ``take``: boolean indexing
    # of the (rows, cols, 2) arrays cost ~0.15 ms a redraw.
    if shown.all():
        return ndc_low, ndc_high, nearest, farthest
    shown = np.flatnonzero(shown)
    return (ndc_low.take(shown, axis=0), ndc_high.take(shown, axis=0), nearest.take(shown),
            farthest.take(shown))


# (rows, cols, block pixels, width, height) -> every block's NDC corners, (rows * cols, 2)
# row by row: the same for every frame of one viewport size.
_BLOCK_CORNERS = {}


def _block_corners(shape, block_pixels, width, height):
    key = (shape, block_pixels, width, height)
    held = _BLOCK_CORNERS.get(key)
    if held is None:
        rows, cols = np.indices(shape)
        x0 = cols * block_pixels / width * 2.0 - 1.0
        x1 = np.minimum((cols + 1) * block_pixels, width) / width * 2.0 - 1.0
        y0 = rows * block_pixels / height * 2.0 - 1.0
        y1 = np.minimum((rows + 1) * block_pixels, height) / height * 2.0 - 1.0
        held = (np.stack([x0, y0], axis=-1).reshape(-1, 2),
                np.stack([x1, y1], axis=-1).reshape(-1, 2))
        for array in held:
            array.setflags(write=False)
        if len(_BLOCK_CORNERS) >= 8:
            _BLOCK_CORNERS.clear()
        _BLOCK_CORNERS[key] = held
    return held


# Which end of the bounds each of a box's 8 corners takes per axis (bit a of the index).
_CORNER_PICK = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], dtype=bool)


def plan_shadows(snap, bounds, depth_blocks=None):
    """Cascade splits and light matrices for this frame (pure math, see cascades.py).
    ``depth_blocks``: what the G-buffer shows per screen block
    (``depth_blocks_from_reduction``), measured when the Fit to Visible Depth setting is
    on (sample-distribution shadow maps): the splits then divide the visible depth range
    and each cascade covers only its receivers. None: the cascades divide clip start ..
    shadow distance and cover their whole frustum slice."""
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
            # NOTE: only viewport frames hold the last frame's fit (so the view does not
            # pop while it moves); a final render depends on nothing but its own scene.
            held = _DEPTH_RANGES.get(snap.scene_name, (None, None)) \
                if getattr(snap, "is_viewport", False) else (None, None)
            if depth_blocks is not None and len(depth_blocks[2]) and \
                    getattr(s, "fit_to_visible", False):
                fitted = cascades.visible_depth_range(
                    float(depth_blocks[2].min()), float(depth_blocks[3].max()),
                    previous=held[0])
                if fitted is not None:
                    # The fitted range has its own hybrid weight (Lambda (Fitted)): its
                    # near end is a surface, not the clip start (docs/soft-shadows.md).
                    arguments.update(depth_range=fitted, depth_blocks=depth_blocks,
                                     previous_squares=held[1],
                                     lam=float(s.fitted_split_lambda))
            try:
                result = cascades.compute_cascades(
                    camera.world_from_view, camera.projection, -snap.sun.to_light,
                    **arguments)
            except ValueError as error:
                # An impossible setting (e.g. manual splits that do not increase): say which
                # and draw with hybrid splits rather than fail the frame.
                warnings.append(f"{error}; using hybrid splits instead")
                arguments.update(scheme="HYBRID", manual=None)
                result = cascades.compute_cascades(
                    camera.world_from_view, camera.projection, -snap.sun.to_light,
                    **arguments)
            warnings.extend(result.notes)
            if "depth_range" in arguments:
                _DEPTH_RANGES[snap.scene_name] = (
                    arguments["depth_range"],
                    [getattr(fit, "receiver_rectangle", None) for fit in result.cascades])
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
                                    fit.near, fit.far, False, cascade=fit,
                                    texel_world_xy=tuple(float(t) for t in fit.texel_size_xy)))
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
    point_shadow_tiles = len(tiles)
    point_shadow_count = _plan_point_shadows(snap.points[:MAX_POINT_LIGHTS],
                                             int(s.resolution), tiles, warnings)
    if bounds is not None:
        # The shadow-map view stretches depth over the part the scene occupies; the occluder
        # margin alone would squeeze all content into the last few percent of grey.
        lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
        corners = np.ones((8, 4))
        corners[:, :3] = np.where(_CORNER_PICK, hi, lo)
        for tile in tiles:
            clip = corners @ tile.clip_from_world.T
            window = min(max(float((clip[:, 2] / clip[:, 3]).min()) * 0.5 + 0.5, 0.0), 1.0)
            if tile.is_perspective:
                ndc = window * 2.0 - 1.0
                tile.display_near = 2.0 * tile.near * tile.far / (
                    tile.far + tile.near - ndc * (tile.far - tile.near))
            else:
                tile.display_near = tile.near + window * (tile.far - tile.near)
    return ShadowPlan(tiles, count, np.asarray(splits, dtype=np.float64),
                      np.asarray(bands, dtype=np.float64), distance, spot_tiles, frozen_camera,
                      warnings, point_shadow_count, point_shadow_tiles)


def _plan_point_shadows(points, resolution, tiles, warnings):
    """Six cube-face tiles for each point light that casts shadows (they come first in
    ``points``, see snapshot.take), up to MAX_POINT_SHADOWS; appended to ``tiles``.
    Returns how many lights got them."""
    casting = 0
    while casting < len(points) and points[casting].casts_shadow:
        casting += 1
    if casting > MAX_POINT_SHADOWS:
        warnings.append(f"{casting} point lights cast shadows: CSM draws the shadows of "
                        f"{MAX_POINT_SHADOWS} (the others light without shadows)")
    resolution = min(POINT_SHADOW_RESOLUTION, resolution)
    angle = cascades.point_light_face_angle(resolution, POINT_FACE_MARGIN_TEXELS)
    texel = 2.0 * math.tan(0.5 * angle) / resolution
    count = min(casting, MAX_POINT_SHADOWS, (MAX_SHADOW_TILES - len(tiles)) // 6)
    for light in points[:count]:
        near = max(light.clip_start, 1e-3)
        far = max(light.radius, near * 2.0)
        position = np.asarray(light.position, dtype=np.float64)
        for face in range(len(cascades.POINT_LIGHT_FACES)):
            light_from_world, clip_from_light = cascades.point_light_face_matrices(
                position, face, angle, near, far)
            tiles.append(ShadowTile(clip_from_light @ light_from_world, resolution, texel,
                                    near, far, True, point_face=(position, face, far)))
    return count


def gbuffer_plan(snap, bounds):
    """The plan a Fit to Visible Depth frame draws its G-buffer with, before the visible
    depths are known. The G-buffer passes read only the camera (and the sample index) from
    the frame block, so no cascades are fitted for it: the real plan follows from the
    G-buffer's depths (``plan_shadows`` with ``depth_blocks``).

    NOTE: on the first frame of Freeze Cascades the plain plan is made here, as it always
    was: it is the one that stays frozen."""
    s = snap.settings
    if s.freeze_cascades and snap.scene_name not in _FROZEN:
        return plan_shadows(snap, bounds)
    camera = snap.camera
    distance = s.shadow_distance if s.shadow_distance > 0 else camera.clip_end
    distance = float(min(max(distance, camera.clip_start * 1.001), camera.clip_end))
    return ShadowPlan([], 0, np.array([camera.clip_start, distance]), np.zeros(MAX_CASCADES),
                      distance, {}, None, [])


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


def window_normal_from_world(tile):
    """4x4 whose upper 3x3 takes a world normal into an orthographic tile's window space
    (x, y over the tile 0..1, z window depth): the inverse transpose of the window-from-world
    3x3, as normals transform. A receiver plane with window normal (a, b, c) changes depth
    by -(a dx + b dy) / c across the tile, which the lighting pass adds to each PCF tap's
    compare depth (receiver-plane depth bias). Zero for perspective tiles (unused there)."""
    out = np.zeros((4, 4))
    if tile.is_perspective:
        return out
    clip_from_world = np.asarray(tile.clip_from_world, dtype=np.float64)
    key = clip_from_world.tobytes()
    held = _WINDOW_NORMALS.get(key)
    if held is not None:
        return held.copy()
    linear = (WINDOW_FROM_CLIP @ clip_from_world)[:3, :3]
    out[:3, :3] = inverse_transpose_3x3(linear)
    out[3, 3] = 1.0
    if len(_WINDOW_NORMALS) >= _WINDOW_NORMALS_MAX:
        _WINDOW_NORMALS.clear()
    _WINDOW_NORMALS[key] = out.copy()
    return out


# clip_from_world bytes -> window_normal_from_world: a stabilized cascade keeps its matrix
# over many viewport redraws, and the inverse is a third of packing a frame.
_WINDOW_NORMALS = {}
_WINDOW_NORMALS_MAX = 64


def sun_tan_half_angle(sun):
    """tan of half the sun's angular diameter (Blender's Angle, 0..180 degrees): the soft
    shadows' penumbra width per unit of distance behind the blocker, on each side."""
    if sun is None:
        return 0.0
    angle = min(max(float(getattr(sun, "angle", 0.0)), 0.0), math.radians(179.0))
    return math.tan(0.5 * angle)


def ambient_occlusion_fields(snap, clip_from_world=None):
    """The frame block's ``ao_*`` fields: the AO settings, and what ao_frag.glsl needs to
    turn a pixel and its view depth into a view-space point and a distance into pixels.
    ``clip_from_world``: the camera's, when the caller has it already."""
    s = snap.settings
    camera = snap.camera
    enabled = bool(getattr(s, "ambient_occlusion", False))
    if clip_from_world is None:
        clip_from_world = camera.clip_from_world
    clip_from_view = np.asarray(clip_from_world, dtype=np.float64) @ \
        np.asarray(camera.world_from_view, dtype=np.float64)
    p = clip_from_view
    if camera.is_perspective:
        # ndc = (P00 x + P02 z) / -z with z = -depth: x = depth * (ndc + P02) / P00.
        view_ray = (1.0 / p[0, 0], 1.0 / p[1, 1], p[0, 2] / p[0, 0], p[1, 2] / p[1, 1])
    else:
        # ndc = P00 x + P03: x = (ndc - P03) / P00.
        view_ray = (1.0 / p[0, 0], 1.0 / p[1, 1], -p[0, 3] / p[0, 0], -p[1, 3] / p[1, 1])
    return dict(ao_enabled=int(enabled),
                ao_distance=float(getattr(s, "ao_distance", 0.0)),
                ao_strength=float(getattr(s, "ao_strength", 0.0)) if enabled else 0.0,
                ao_pixels_per_unit=0.5 * camera.height * abs(p[1, 1]),
                ao_view_ray=view_ray)


# The last camera packed: (its matrices as bytes, (clip_from_world, view_from_world,
# world_from_clip)). A Fit to Visible Depth frame packs its camera twice.
_LAST_CAMERA = [None, None]


def _camera_matrices(camera):
    """clip_from_world, view_from_world and world_from_clip of ``camera`` (inverses, so
    the last camera's are kept; see matrices.py for why not ``np.linalg.inv``)."""
    world_from_view = np.asarray(camera.world_from_view, dtype=np.float64)
    clip_from_view = getattr(camera, "clip_from_view", None)    # a CameraView's
    key = None if clip_from_view is None else \
        world_from_view.tobytes() + np.asarray(clip_from_view, dtype=np.float64).tobytes()
    if key is None or _LAST_CAMERA[0] != key:
        view_from_world = inverse_rigid(world_from_view)
        if clip_from_view is None:
            clip_from_world = camera.clip_from_world
            world_from_clip = np.linalg.inv(clip_from_world)
        else:
            clip_from_world = np.asarray(clip_from_view, dtype=np.float64) @ view_from_world
            world_from_clip = world_from_view @ inverse_projection(clip_from_view)
        matrices = (clip_from_world, view_from_world, world_from_clip)
        for matrix in matrices:
            matrix.setflags(write=False)
        _LAST_CAMERA[:] = [key, matrices]
    return _LAST_CAMERA[1]


def pack_frame(snap, plan, like=None):
    """The frame uniform block for this frame (std140 float32 array, ``FRAME_LAYOUT``).
    ``like``: a block packed by this function for the same, unchanged ``snap`` with another
    plan or none (a Fit to Visible Depth frame packs twice): it is copied and only what
    depends on the plan is written again. ``plan`` None: the snapshot's fields alone, the
    plan's left 0 (a Fit to Visible Depth frame's G-buffer reads none of them)."""
    if plan is None:
        return FRAME_LAYOUT.pack(_snapshot_fields(snap))
    plan_values = _plan_fields(snap, plan)
    if like is None:
        return FRAME_LAYOUT.pack({**_snapshot_fields(snap), **plan_values})
    data = like.copy()
    for name in _PLAN_ARRAYS:       # rows the other plan used and this one may not
        field = FRAME_LAYOUT.field(name)
        data[field.offset // 4:(field.offset + field.count * field.stride) // 4] = 0.0
    FRAME_LAYOUT.write(data, plan_values)
    return data


# The frame block's arrays that depend on the plan (spot lights: their shadow tile).
_PLAN_ARRAYS = ("cascades", "shadow_tiles", "spot_lights")


def _plan_fields(snap, plan):
    """The frame block's fields that depend on the shadow plan."""
    s = snap.settings
    spots = snap.spots[:MAX_SPOT_LIGHTS]
    fade_start = plan.shadow_distance * (1.0 - s.fade_fraction) if s.fade_out \
        else plan.shadow_distance * 2.0
    count = plan.cascade_count
    bands = plan.bands[:MAX_CASCADES]
    # Cascades not in use end at 1e30, so a selection loop that passed them finds nothing.
    cascade_rows = [dict(near_depth=plan.splits[i] if i < count else 0.0,
                         far_depth=plan.splits[i + 1] if i < count else 1e30,
                         blend_band=bands[i] if i < len(bands) else 0.0)
                    for i in range(MAX_CASCADES)]
    tile_rows = [dict(shadow_from_world=WINDOW_FROM_CLIP @ tile.clip_from_world,
                      atlas_origin=tile.origin, resolution=tile.resolution,
                      texel_world=tile.texel_world,
                      texel_world_xy=tile.texel_world_per_axis(),
                      light_near=tile.near, light_far=tile.far,
                      is_perspective=int(tile.is_perspective), display_near=tile.display_near,
                      window_normal_from_world=window_normal_from_world(tile))
                 for tile in plan.tiles]
    spot_rows = []
    for i, spot in enumerate(spots):
        cos_outer, cos_inner = spot_cone_cosines(spot)
        spot_rows.append(dict(position=spot.position, radius=spot.radius, color=spot.color,
                              shadow_tile=plan.spot_tiles.get(i, -1), direction=spot.direction,
                              cos_outer=cos_outer, cos_inner=cos_inner,
                              falloff=LIGHT_FALLOFF_INDEX[spot.falloff],
                              source_radius=spot.source_radius))
    return dict(
        point_shadow_count=plan.point_shadow_count,
        point_shadow_tiles=plan.point_shadow_tiles,
        sun_casts_shadow=int(snap.sun is not None and count > 0),
        cascade_count=count,
        shadow_distance=plan.shadow_distance,
        fade_start_depth=fade_start,
        cascades=cascade_rows,
        shadow_tiles=tile_rows,
        spot_lights=spot_rows,
    )


def _snapshot_fields(snap):
    """The frame block's fields that depend only on the snapshot (camera, lights,
    settings)."""
    s = snap.settings
    camera = snap.camera
    points = snap.points[:MAX_POINT_LIGHTS]
    spots = snap.spots[:MAX_SPOT_LIGHTS]
    sun = snap.sun
    point_rows = [dict(position=light.position, radius=light.radius, color=light.color,
                       falloff=LIGHT_FALLOFF_INDEX[light.falloff],
                       source_radius=light.source_radius)
                  for light in points]
    clip_from_world, view_from_world, world_from_clip = _camera_matrices(camera)
    return dict(
        clip_from_world=clip_from_world,
        view_from_world=view_from_world,
        world_from_clip=world_from_clip,
        camera_position=camera.position,
        is_perspective=int(bool(camera.is_perspective)),
        camera_forward=camera.forward,
        viewport_size=(camera.width, camera.height),
        ambient_color=snap.ambient,
        background_alpha=0.0 if snap.film_transparent else 1.0,
        background_color=snap.background,
        sun_direction=sun.to_light if sun is not None else (0.0, 0.0, 0.0),
        has_sun=int(sun is not None),
        sun_color=sun.color if sun is not None else (0.0, 0.0, 0.0),
        pcf_radius_texels=s.pcf_radius,
        cascade_selection=CASCADE_SELECTION_INDEX[s.cascade_selection],
        pcf_pattern=PCF_PATTERN_INDEX[s.pcf_pattern],
        pcf_sharpen=s.pcf_sharpen,
        depth_bias_texels=s.depth_bias,
        slope_bias_texels=s.slope_bias,
        normal_offset_texels=s.normal_offset,
        sample_index=getattr(snap, "sample_index", 0),
        sun_tan_half_angle=sun_tan_half_angle(sun),
        point_light_count=len(points),
        spot_light_count=len(spots),
        debug_view=DEBUG_VIEW_INDEX[s.debug_view],
        debug_shadow_map=s.debug_shadow_map,
        debug_inset=int(bool(s.debug_inset)),
        **ambient_occlusion_fields(snap, clip_from_world),
        point_lights=point_rows,
    )


def front_to_back(snap, bounds_lo_hi):
    """Instance indices sorted by the view depth of their bounds' centres."""
    if bounds_lo_hi is None:
        return range(len(snap.instances))
    centres = 0.5 * (bounds_lo_hi[0] + bounds_lo_hi[1])
    return np.argsort(centres @ np.asarray(snap.camera.forward, dtype=np.float64))
