"""Shadow planning for one frame: which shadow maps to draw, where in the atlas, with
which matrices.

Owns ``plan_shadows`` (cascade splits and light matrices through ``cascades``, spot and
point light tiles), ``gbuffer_plan`` (the plan a Fit to Visible Depth frame draws its
G-buffer with), ``layout_atlas`` (shelf packing), the per-instance helpers the passes
sort and cull with (``instance_bounds``, ``front_to_back``), and the ``ShadowTile`` /
``ShadowPlan`` records the GPU side executes. Functions of a ``FrameSnapshot`` (plain
data), the scene bounds and, for what a view carries from frame to frame (frozen
cascades, hysteresis), the view's ``view_state.ShadowViewState``. The frame uniform block
is packed by ``frame_block.pack_frame`` (re-exported here). numpy only.
"""

import math
from dataclasses import dataclass

import numpy as np

from . import cascades
# Re-exported: the render passes take the planner's inputs and outputs from here.
from .cascades import depth_blocks_from_reduction
from .frame_block import (WINDOW_FROM_CLIP, ambient_occlusion_fields, pack_frame,
                          sun_tan_half_angle, window_normal_from_world)
from .frame_layout import (MAX_CASCADES, MAX_POINT_LIGHTS, MAX_POINT_SHADOWS,
                           MAX_SHADOW_TILES, MAX_SPOT_LIGHTS)
from .view_state import FrozenCascades, ShadowViewState

CASCADE_LINE_COLORS = ((1, .2, .2, 1), (.2, 1, .2, 1), (.3, .4, 1, 1), (1, 1, .2, 1))

MAX_ATLAS_WIDTH = 8192
SPOT_SHADOW_RESOLUTION = 1024
POINT_SHADOW_RESOLUTION = 512      # texels per cube face
# Texels each cube face reaches past 90 degrees, so PCF kernels up to radius 3 (and the
# bilinear taps' extra texel) near a face's edge read rendered texels; wider kernels and
# soft penumbrae there read the face's edge texels again (taps are clamped to the tile).
POINT_FACE_MARGIN_TEXELS = 4

__all__ = ["CASCADE_LINE_COLORS", "MAX_ATLAS_WIDTH", "SPOT_SHADOW_RESOLUTION",
           "POINT_SHADOW_RESOLUTION", "POINT_FACE_MARGIN_TEXELS", "ShadowTile", "ShadowPlan",
           "instance_bounds", "plan_shadows", "gbuffer_plan", "layout_atlas", "front_to_back",
           # re-exported
           "depth_blocks_from_reduction", "WINDOW_FROM_CLIP", "ambient_occlusion_fields",
           "pack_frame", "sun_tan_half_angle", "window_normal_from_world"]


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


# Which end of the bounds each of a box's 8 corners takes per axis (bit a of the index).
_CORNER_PICK = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], dtype=bool)
_CORNER_PICK.setflags(write=False)


def plan_shadows(snap, bounds, depth_blocks=None, view_state=None):
    """Cascade splits and light matrices for this frame (the math is in ``cascades``).
    ``depth_blocks``: what the G-buffer shows per screen block
    (``depth_blocks_from_reduction``), measured when the Fit to Visible Depth setting is
    on (sample-distribution shadow maps): the splits then divide the visible depth range
    and each cascade covers only its receivers. None: the cascades divide clip start ..
    shadow distance and cover their whole frustum slice.
    ``view_state``: the view's ``ShadowViewState``, read and updated (frozen cascades,
    and for a viewport the last fit's depth range and cascade boxes). None: a fresh one,
    so nothing is frozen or held. A final render's cascades depend on its own frame
    alone (frozen cascades aside): each box is a step function of what it must hold
    (``cascades.quantizing``), so the render after a small camera move (the next frame
    of a camera animation, or F12 again) mostly gets the same boxes."""
    state = ShadowViewState() if view_state is None else view_state
    state.follow_scene(snap.scene_name)
    viewport = bool(snap.is_viewport)
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
        if s.freeze_cascades and state.frozen is not None:
            result, frozen_camera = state.frozen.cascades, state.frozen.camera
        else:
            arguments = dict(
                count=count, scheme=s.split_scheme, lam=float(s.split_lambda),
                manual=manual if s.split_scheme == 'MANUAL' else None,
                shadow_distance=distance, base_resolution=int(s.resolution),
                equal_resolution=bool(s.equal_resolution), stabilize=bool(s.stabilize),
                occluder_margin=margin, blend_band=float(s.blend_band),
                # Auto: the near plane reaches the scene's bounds, so no caster is clipped.
                # Manual: exactly the margin the user typed, nothing added.
                scene_bounds=bounds if s.occluder_margin_auto else None,
                receiver_cache=state.receiver_cache)
            # NOTE: a viewport keeps its last fit while it still serves: the depth range
            # while it holds the visible one, each cascade's box while it holds its
            # receivers and is not much coarser than a fresh fit. A final render keeps
            # nothing (any process must render a frame of an animation to the same
            # pixels): its depth range is on a fixed ladder and its boxes are quantized.
            # Either way a camera that moves a little draws (almost) no shadow map again.
            if depth_blocks is not None and len(depth_blocks[2]) and s.fit_to_visible:
                fitted = cascades.visible_depth_range(
                    float(depth_blocks[2].min()), float(depth_blocks[3].max()),
                    previous=state.fitted_depth_range if viewport else None)
                if fitted is not None:
                    # The fitted range has its own hybrid weight (Lambda (Fitted)): its
                    # near end is a surface, not the clip start (docs/soft-shadows.md).
                    arguments.update(depth_range=fitted, depth_blocks=depth_blocks,
                                     lam=float(s.fitted_split_lambda))
            arguments.update(held=state.held_cascades if viewport else None,
                             quantize=not viewport)
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
            if viewport:
                state.fitted_depth_range = arguments.get("depth_range")
                state.held_cascades = list(result.cascades)
            if s.freeze_cascades:
                state.frozen = FrozenCascades(result, camera)
                frozen_camera = camera
            else:
                state.frozen = None
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


def gbuffer_plan(snap, bounds, view_state=None):
    """The plan a Fit to Visible Depth frame draws its G-buffer with, before the visible
    depths are known. The G-buffer passes read only the camera (and the sample index) from
    the frame block, so no cascades are fitted for it: the real plan follows from the
    G-buffer's depths (``plan_shadows`` with ``depth_blocks``).

    NOTE: on the first frame of Freeze Cascades (nothing frozen in ``view_state`` yet) the
    plain plan is made here: it is the one that stays frozen."""
    s = snap.settings
    state = ShadowViewState() if view_state is None else view_state
    state.follow_scene(snap.scene_name)
    if s.freeze_cascades and state.frozen is None:
        return plan_shadows(snap, bounds, view_state=state)
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


def front_to_back(snap, bounds_lo_hi):
    """Instance indices sorted by the view depth of their bounds' centres."""
    if bounds_lo_hi is None:
        return range(len(snap.instances))
    centres = 0.5 * (bounds_lo_hi[0] + bounds_lo_hi[1])
    return np.argsort(centres @ np.asarray(snap.camera.forward, dtype=np.float64))
