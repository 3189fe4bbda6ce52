/* One shadow tile's visibility for a world point: the normal offset, constant and slope
 * biases (set in texels, converted with the tile's own texel size), the projection into the
 * tile, then this program's shadow filter (hard, PCF or soft; Exact takes the hard tap
 * for the lights without shadow volumes), and how far that filter
 * reads around a point. The sun's cascades, spot lights and point lights' cube faces all
 * look up their tiles here. */
#include "shadow_atlas.glsl"
#include "shadow_pcf.glsl"
#include "shadow_soft.glsl"
#include "shadow_volume_lookup.glsl"

/* NOTE: the filter is chosen when the program is built (SHADOW_FILTER, one program per
 * Shadow Filter setting), not by a uniform: llvmpipe runs the code of a branch not taken
 * as well, so the soft filter's loops in the same program made PCF 2.4x slower. */
#ifndef SHADOW_FILTER
#  define SHADOW_FILTER FILTER_PCF
#endif

/* How far from a point (texels of its tile) this program's filter may read, with a texel
 * to spare each side: what a map must hold around the point for its lookup to be whole. */
float shadow_filter_reach_texels()
{
#if SHADOW_FILTER == FILTER_SOFT
  return 2.0 + SOFT_RADIUS_LIMIT_TEXELS;
#else
  return 2.0 + frame.pcf_radius_texels + frame.normal_offset_texels;
#endif
}

/* Visibility (1 lit, 0 shadowed) of world point p with normal n from shadow tile `tile`.
 * light_size: the sun's tan(half angle), or a spot or point light's radius (scene units);
 * used by the soft filter only. */
float shadow_tile_visibility(ShadowTileData tile, vec3 p, vec3 n, float n_dot_l,
                             float light_size)
{
  float texel_world = tile.texel_world;
  if (tile.is_perspective != 0) {
    /* Perspective: a texel covers more of the world the further it is from the light. */
    vec4 s0 = tile.shadow_from_world * vec4(p, 1.0);
    texel_world *= shadow_linear_depth(clamp(s0.z / s0.w, 0.0, 1.0), tile);
  }
  float cos_l = clamp(n_dot_l, 0.05, 1.0);
  float tan_l = min(sqrt(1.0 - cos_l * cos_l) / cos_l, 10.0);
  /* NOTE: all three biases are given in texels and converted here with this tile's world
   * texel size, so one setting holds in every cascade whatever its resolution and extent. */
  float normal_offset = frame.normal_offset_texels * texel_world * (1.0 - n_dot_l * 0.5);
  float pcf_radius = frame.pcf_radius_texels;
  vec2 depth_per_texel = receiver_depth_per_texel(tile, n);
  /* Perspective tiles have no receiver plane, so their slope bias also covers the
   * filter's width. */
  float filter_reach = tile.is_perspective != 0 ? 1.0 + pcf_radius : 1.0;
  float bias = texel_world * (frame.depth_bias_texels + frame.slope_bias_texels * tan_l *
                              filter_reach);

  vec4 s = tile.shadow_from_world * vec4(p + n * normal_offset, 1.0);
  s.xyz /= s.w;
  if (s.x < 0.0 || s.x > 1.0 || s.y < 0.0 || s.y > 1.0 || s.z > 1.0) {
    return 1.0; /* Outside the tile: nothing was rendered there to cast a shadow. */
  }
  float receiver = shadow_linear_depth(max(s.z, 0.0), tile);
  float compare = shadow_window_depth(receiver - bias, tile);
  vec2 origin = tile.atlas_origin;
  float last_texel = tile.resolution - 1.0;
  vec2 texel = s.xy * tile.resolution;

#if SHADOW_FILTER == FILTER_SOFT
  vec2 texel_world_xy = tile.texel_world_xy * (texel_world / tile.texel_world);
  return soft_shadow(tile, light_size, texel, compare, depth_per_texel, receiver,
                     texel_world_xy);
#elif SHADOW_FILTER == FILTER_HARD || SHADOW_FILTER == FILTER_EXACT
  /* Exact: the sun's volumes replace its cascades (shadow_volume_lookup.glsl); spot and
   * point lights have no volumes and keep their maps' hard tap. */
  return shadow_tap(origin, last_texel, texel, texel, compare, depth_per_texel);
#else
  return pcf_shadow(origin, last_texel, texel, compare, depth_per_texel);
#endif
}
