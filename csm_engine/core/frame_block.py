"""The frame uniform block's values for one frame: what the G-buffer, ambient-occlusion
and lighting passes read (``frame_layout.FRAME_LAYOUT``).

Owns ``pack_frame`` (the std140 data of a snapshot and its shadow plan, or of the
snapshot alone), the parts of it other code reuses (``window_normal_from_world``,
``ambient_occlusion_fields``, ``sun_tan_half_angle``) and ``WINDOW_FROM_CLIP``. A pure
function of the snapshot and the plan; the inverses it needs are memos of pure functions
(``memo.py``). numpy only.
"""

import math

import numpy as np

from . import world_light
from .frame import spot_cone_cosines
from .frame_layout import (CASCADE_SELECTION_INDEX, DEBUG_VIEW_INDEX, FRAME_LAYOUT,
                           LIGHT_FALLOFF_INDEX, MAX_CASCADES, MAX_POINT_LIGHTS,
                           MAX_SPOT_LIGHTS, PCF_PATTERN_INDEX)
from .matrices import inverse_projection, inverse_rigid, inverse_transpose_3x3
from .memo import ArrayMemo, ValueMemo

# Maps OpenGL clip space (-1..1 on every axis) to window/texture space (0..1).
WINDOW_FROM_CLIP = np.array([[.5, 0, 0, .5], [0, .5, 0, .5], [0, 0, .5, .5], [0, 0, 0, 1.]])
WINDOW_FROM_CLIP.setflags(write=False)


def window_normal_from_world(tile):
    """4x4 whose upper 3x3 takes a world normal into an orthographic tile's window space
    (x, y over the tile 0..1, z window depth): the inverse transpose of the window-from-world
    3x3, as normals transform. A receiver plane with window normal (a, b, c) changes depth
    by -(a dx + b dy) / c across the tile, which the lighting pass adds to each PCF tap's
    compare depth (receiver-plane depth bias). Zero for perspective tiles (unused there)."""
    if tile.is_perspective:
        return np.zeros((4, 4))
    return _window_normal_from_clip_from_world(tile.clip_from_world).copy()


def _window_normal_uncached(clip_from_world):
    out = np.zeros((4, 4))
    linear = (WINDOW_FROM_CLIP @ clip_from_world)[:3, :3]
    out[:3, :3] = inverse_transpose_3x3(linear)
    out[3, 3] = 1.0
    return out


# A stabilized cascade keeps its matrix over many viewport redraws, and the inverse is a
# third of packing a frame: remembered by the matrix's value.
_window_normal_from_clip_from_world = ArrayMemo(_window_normal_uncached, 64)


def sun_tan_half_angle(sun):
    """tan of half the sun's angular diameter (Blender's Angle, 0..180 degrees): the soft
    shadows' penumbra width per unit of distance behind the blocker, on each side."""
    if sun is None:
        return 0.0
    angle = min(max(float(sun.angle), 0.0), math.radians(179.0))
    return math.tan(0.5 * angle)


def _world_sh(snap):
    """The frame's World radiance coefficients (9 vec4): the snapshot's, else its uniform
    ambient colour's."""
    coefficients = snap.world_sh if snap.world_sh is not None else \
        world_light.uniform_sh(snap.ambient)
    return np.pad(np.asarray(coefficients, dtype=np.float64), ((0, 0), (0, 1)))


def ambient_occlusion_fields(snap, clip_from_world=None):
    """The frame block's ``ao_*`` fields: the AO settings, and what ao_frag.glsl needs to
    turn a pixel and its view depth into a view-space point and a distance into pixels.
    ``clip_from_world``: the camera's, when the caller has it already."""
    s = snap.settings
    camera = snap.camera
    enabled = bool(s.ambient_occlusion)
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
                ao_distance=float(s.ao_distance),
                ao_strength=float(s.ao_strength) if enabled else 0.0,
                ao_pixels_per_unit=0.5 * camera.height * abs(p[1, 1]),
                ao_view_ray=view_ray)


def _camera_matrices(camera):
    """clip_from_world, view_from_world and world_from_clip of ``camera`` (read-only;
    see matrices.py for why not ``np.linalg.inv``)."""
    clip_from_view = getattr(camera, "clip_from_view", None)    # a CameraView's
    if clip_from_view is None:
        return _camera_matrices_uncached(camera.world_from_view, None, camera.clip_from_world)
    return _camera_matrices_of_view(np.asarray(camera.world_from_view, dtype=np.float64),
                                    np.asarray(clip_from_view, dtype=np.float64))


def _camera_matrices_uncached(world_from_view, clip_from_view, clip_from_world=None):
    world_from_view = np.asarray(world_from_view, dtype=np.float64)
    view_from_world = inverse_rigid(world_from_view)
    if clip_from_view is None:
        world_from_clip = np.linalg.inv(clip_from_world)
    else:
        clip_from_world = clip_from_view @ view_from_world
        world_from_clip = world_from_view @ inverse_projection(clip_from_view)
    matrices = (clip_from_world, view_from_world, world_from_clip)
    for matrix in matrices:
        matrix.setflags(write=False)
    return matrices


# A Fit to Visible Depth frame packs its camera twice, and a viewport redraw that only
# changes settings packs the same camera again: the last camera's matrices are kept.
_camera_matrices_of_view = ValueMemo(
    _camera_matrices_uncached, 1,
    key=lambda world_from_view, clip_from_view:
    world_from_view.tobytes() + clip_from_view.tobytes())


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
        world_sh=_world_sh(snap),
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
        sample_index=snap.sample_index,
        sun_tan_half_angle=sun_tan_half_angle(sun),
        point_light_count=len(points),
        spot_light_count=len(spots),
        debug_view=DEBUG_VIEW_INDEX[s.debug_view],
        debug_shadow_map=s.debug_shadow_map,
        debug_inset=int(bool(s.debug_inset)),
        **ambient_occlusion_fields(snap, clip_from_world),
        point_lights=point_rows,
    )


