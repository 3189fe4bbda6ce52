/* Reading the shadow atlas: the conversion between a tile's stored window depth (0..1) and
 * distance from its light (scene units), one-texel depth taps, the partial-caster mask, and
 * the receiver plane (window depth change per texel across a receiver's own surface).
 * Every shadow filter (shadow_pcf.glsl, shadow_soft.glsl) reads the atlas through these.
 *
 * frame (FrameData, with ShadowTileData, ...) and the constants DEBUG_*, PCF_*, MAX_* come
 * from core/frame_layout.py, which generates the struct text and the #defines: the field
 * meanings and units are documented there. */

/* Distance from the light plane (orthographic) or light position (perspective) for a
 * window depth 0..1 stored in the atlas. Comparing linear distances lets one bias in scene
 * units serve both projections. */
float shadow_linear_depth(float window_depth, ShadowTileData tile)
{
  float near = tile.light_near, far = tile.light_far;
  if (tile.is_perspective != 0) {
    float ndc = window_depth * 2.0 - 1.0;
    return 2.0 * near * far / (far + near - ndc * (far - near));
  }
  return near + window_depth * (far - near);
}

/* The inverse of shadow_linear_depth: the window depth 0..1 of a distance from the light.
 * Both are increasing, so "occluder closer than the biased receiver" can be tested on the
 * stored window depths directly. Distances at or behind a perspective light's position
 * give -1 (nothing can be in front of them). */
float shadow_window_depth(float linear, ShadowTileData tile)
{
  float near = tile.light_near, far = tile.light_far;
  if (tile.is_perspective != 0) {
    if (linear <= 1e-6) {
      return -1.0;
    }
    return 0.5 * (far + near - 2.0 * near * far / linear) / (far - near) + 0.5;
  }
  return (linear - near) / (far - near);
}

/* The tile's texel under atlas-tile position `tap`, kept inside the tile. */
vec2 tile_texel(float last_texel, vec2 tap)
{
  return clamp(floor(tap), vec2(0.0), vec2(last_texel));
}

/* One tap at atlas-tile position `tap` (texels): 1 lit, 0 shadowed. NOTE: the receiver's
 * biased depth is converted to the atlas's window depth once per pixel (compare_window),
 * so a tap is one fetch and one compare, with no per-tap linearization (the lighting pass
 * is fill-bound on llvmpipe). The receiver plane: the depth the receiver's own surface has
 * under the tapped texel's centre differs from its depth at `receiver` by
 * depth_per_texel . (centre - receiver); comparing against that instead of one depth for
 * every tap keeps a flat lit surface lit under any filter width. */
float shadow_tap(vec2 origin, float last_texel, vec2 tap, vec2 receiver, float compare_window,
                 vec2 depth_per_texel)
{
  vec2 texel = tile_texel(last_texel, tap);
  float compare = compare_window + dot(depth_per_texel, texel + 0.5 - receiver);
  return texelFetch(shadow_atlas, ivec2(texel) + ivec2(origin), 0).r < compare ? 0.0 : 1.0;
}

/* The atlas's partial-caster mask (1: under an alpha-hashed caster) at a texel. Only
 * programs built with PARTIAL_CASTERS read it: without an alpha-hashed caster in the frame
 * the mask is clear (render/shadow_atlas.py). */
float partial_caster_at(vec2 origin, float last_texel, vec2 tap)
{
#ifdef PARTIAL_CASTERS
  return texelFetch(shadow_partial, ivec2(tile_texel(last_texel, tap)) + ivec2(origin), 0).r;
#else
  return 0.0;
#endif
}

/* Receiver-plane slope bound, in texels of depth per texel across (a plane the light
 * grazes at 89 degrees): steeper planes are left to the slope bias; without a bound a
 * plane edge-on to the light would give an infinite slope. */
const float RECEIVER_SLOPE_LIMIT = 60.0;

/* Window depth change per texel of a receiver plane with world normal n, in an orthographic
 * tile (0 for perspective tiles, whose window depth is not linear). */
vec2 receiver_depth_per_texel(ShadowTileData tile, vec3 n)
{
  if (tile.is_perspective != 0) {
    return vec2(0.0);
  }
  vec3 window_normal = mat3(tile.window_normal_from_world) * n;
  float depth_per_world = 1.0 / max(tile.light_far - tile.light_near, 1e-9);
  float bound = RECEIVER_SLOPE_LIMIT * tile.texel_world * depth_per_world;
  vec2 slope = -window_normal.xy / (window_normal.z * tile.resolution);
  if (abs(window_normal.z) < 1e-9 || any(isnan(slope))) {
    return vec2(0.0);
  }
  float length_slope = length(slope);
  return length_slope > bound ? slope * (bound / length_slope) : slope;
}
