"""Cascaded-shadow-map math: every number the shadow passes need that can be computed on
the CPU without Blender. One module per concept:

- ``splits``: where the view depth is cut into cascades, blend bands, resolutions;
- ``spaces``: camera depth slices, the light's rotation, orthographic and perspective
  projections;
- ``stabilization``: the slice's exact bounding sphere, radius and texel rounding, the
  light-space texel grid;
- ``fitting``: one cascade's shadow box (``fit_cascade``) and a frame's
  (``compute_cascades``);
- ``receivers``: sample-distribution shadow maps (the visible depth range and each
  cascade's visible receivers);
- ``holding``: a viewport's cascade box kept from one frame to the next while it still
  serves;
- ``quantizing``: a final render's cascade boxes, step functions of their receivers;
- ``culling``: which casters may shadow a cascade or a point light's cube face;
- ``light_frusta``: spot and point light shadow frusta.

The names below are re-exported so ``cascades.compute_cascades`` etc. read the same from
any caller. The per-pixel half (which cascade a pixel reads, blend weights, the far
fade) lives in the GLSL alone (cascade selection in the shaders).

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

No module here imports ``bpy`` or ``gpu`` (numpy only), and none keeps state between
calls other than memos of pure functions (``core/memo.py``).
"""

from ..camera import CameraProjection, as_projection
from ..frame_layout import MAX_CASCADES, SPLIT_SCHEMES
from .culling import (aabb_in_cascade, aabbs_in_cascade, aabbs_in_point_light_face,
                      boxes_are_valid, boxes_in_light_frame)
from .fitting import (CascadeFit, CascadeSet, compute_cascades, default_occluder_margin,
                      fit_cascade)
from .light_frusta import (POINT_LIGHT_FACES, point_light_face_angle,
                           point_light_face_matrices, spot_light_matrices, spot_texel_size)
from .receivers import (ReceiverTermsCache, block_window, depth_blocks_from_reduction,
                        receiver_square, receiver_terms, rounded_square,
                        visible_depth_range)
from .spaces import (frustum_slice_corners, light_view_matrix, orthographic_clip_from_view,
                     perspective_clip_from_view, view_slice_corners)
from .splits import (MIN_CASCADE_RESOLUTION, blend_band_widths, cascade_resolutions,
                     manual_splits_from_fractions, split_distances)
from .stabilization import (bounding_sphere, round_up_radius, snap_to_texel_grid,
                            texel_grid_position)

__all__ = [
    "CameraProjection", "as_projection", "MAX_CASCADES", "SPLIT_SCHEMES",
    "aabb_in_cascade", "aabbs_in_cascade", "aabbs_in_point_light_face", "boxes_are_valid",
    "boxes_in_light_frame",
    "CascadeFit", "CascadeSet", "compute_cascades", "default_occluder_margin", "fit_cascade",
    "POINT_LIGHT_FACES", "point_light_face_angle", "point_light_face_matrices",
    "spot_light_matrices", "spot_texel_size",
    "ReceiverTermsCache", "block_window", "depth_blocks_from_reduction", "receiver_square",
    "receiver_terms", "rounded_square", "visible_depth_range",
    "frustum_slice_corners", "light_view_matrix", "orthographic_clip_from_view",
    "perspective_clip_from_view", "view_slice_corners",
    "MIN_CASCADE_RESOLUTION", "blend_band_widths", "cascade_resolutions",
    "manual_splits_from_fractions", "split_distances",
    "bounding_sphere", "round_up_radius", "snap_to_texel_grid", "texel_grid_position",
]
