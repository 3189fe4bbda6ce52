/* The debug views (Debug View setting) of the lighting programs built WITH_DEBUG_VIEWS:
 * the shadow map full screen or inset, cascade colours, shadow factor, texel density,
 * G-buffer channels, ambient occlusion, the shadow error against the exact shadow volumes,
 * and the colour ramps they use. */
#include "shadow_atlas.glsl"
#include "surface.glsl"
#include "shadow_volume_lookup.glsl"

/* Cascade 0..3 -> red, green, blue, yellow, mixed between neighbours for a fractional
 * cascade (a blend band); -1 (no cascade) -> white. */
vec3 cascade_color(float cascade)
{
  const vec3 colors[4] = vec3[4](vec3(1.0, 0.15, 0.15), vec3(0.15, 1.0, 0.15),
                                 vec3(0.2, 0.3, 1.0), vec3(1.0, 1.0, 0.15));
  if (cascade < 0.0) {
    return vec3(1.0);
  }
  int i = int(floor(cascade));
  float w = cascade - float(i);
  return mix(colors[min(i, 3)], colors[min(i + 1, 3)], w);
}

/* 0 -> red (too few texels), 0.5 -> green (one texel per pixel), 1 -> blue (wasted). */
vec3 heat_color(float t)
{
  t = clamp(t, 0.0, 1.0);
  if (t < 0.5) {
    return mix(vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0), t * 2.0);
  }
  return mix(vec3(0.0, 1.0, 0.0), vec3(0.0, 0.2, 1.0), t * 2.0 - 1.0);
}

/* Shadow tile t's stored depth at uv (0..1 across the tile) as a grey ramp. */
vec3 show_shadow_map(int t, vec2 uv)
{
  ShadowTileData tile = frame.shadow_tiles[t];
  ivec2 p = ivec2(clamp(uv, 0.0, 1.0) * (tile.resolution - 1.0)) + ivec2(tile.atlas_origin);
  float linear = shadow_linear_depth(texelFetch(shadow_atlas, p, 0).r, tile);
  /* From where the scene's bounds begin in this light's depth, so the grey ramp spans the
   * content rather than the (mostly empty) occluder margin. */
  return vec3((linear - tile.display_near) / max(tile.light_far - tile.display_near, 1e-6));
}

/* Where a square shadow-map view sits on screen: full screen (centred square) or inset. */
bool shadow_map_uv(vec2 pixel, out vec2 uv)
{
  vec2 size = frame.viewport_size;
  bool inset = frame.debug_inset != 0;
  float side = inset ? 0.35 * min(size.x, size.y) : min(size.x, size.y);
  vec2 origin = inset ? vec2(8.0) : 0.5 * (size - vec2(side));
  uv = (pixel - origin) / side;
  return all(greaterThanEqual(uv, vec2(0.0))) && all(lessThanEqual(uv, vec2(1.0)));
}

/* The Shadow Map view (full screen, or inset over any view) at this pixel (in pixels from
 * the viewport's corner): true where it covers the pixel, with its colour (black around
 * a full-screen map). */
bool shadow_map_view(vec2 pixel, out vec3 color)
{
  int debug_view = frame.debug_view;
  bool inset = frame.debug_inset != 0;
  int shadow_tile_count = frame.cascade_count + frame.spot_light_count;
  color = vec3(0.0);
  if (debug_view == DEBUG_SHADOW_MAP || inset) {
    vec2 uv;
    int t = clamp(frame.debug_shadow_map, 0, max(shadow_tile_count - 1, 0));
    if (shadow_tile_count > 0 && shadow_map_uv(pixel, uv)) {
      color = show_shadow_map(t, uv);
      return true;
    }
    if (debug_view == DEBUG_SHADOW_MAP && !inset) {
      return true;
    }
  }
  return false;
}

/* The Shadow error view at surface s: where the Filter's sun visibility differs from the
 * exact one (the counted shadow volumes) by more than half, pure red (a false shadow: the
 * map darkens what the sun reaches) or pure cyan (a missed shadow); elsewhere a grey from
 * the sun's exact shading, never below 0.2 so that every surface pixel is told from the
 * black background. render/shadow_volumes.py counts the two colours for the legend: keep them
 * pure. */
vec3 shadow_error_color(Surface s, vec3 color, float sun_visibility)
{
  vec3 sun_l = normalize(frame.sun_direction);
  bool shadowed = frame.has_sun != 0 && frame.sun_casts_shadow != 0;
  float exact = 1.0;
  if (shadowed) {
    exact = dot(s.normal, sun_l) <= 0.0 ? 0.0 : volume_visibility(ivec2(gl_FragCoord.xy));
  }
  float error = sun_visibility - exact;
  if (error < -0.5) {
    return vec3(1.0, 0.0, 0.0);
  }
  if (error > 0.5) {
    return vec3(0.0, 1.0, 1.0);
  }
  /* Agreement: the sun's own shading (shadow dark, lit by the angle to the sun), so the
   * shadows read whatever the light's strength. */
  return vec3(0.2 + 0.5 * exact * clamp(dot(s.normal, sun_l), 0.0, 1.0));
}

/* The colour of this program's Debug View at a lit surface s: `color` is the lit image
 * (returned as is for the views drawn elsewhere or not at all), sun_visibility, cascade
 * and sun_tile what the sun's lookups found, ambient_visibility the AO's share of the
 * World light. */
vec3 debug_view_color(Surface s, vec3 color, float sun_visibility, float cascade,
                      int sun_tile, float ambient_visibility)
{
  int debug_view = frame.debug_view;
  vec3 n = s.normal;
  vec3 p = s.position;
  if (debug_view == DEBUG_CASCADES) {
    /* Hue from the cascade, brightness from the lit image: readable on any albedo (a plain
     * multiply turns green grass under the blue cascade black). */
    float luma = dot(color, vec3(0.2126, 0.7152, 0.0722));
    color = cascade_color(cascade) * (0.15 + 0.85 * min(luma, 1.0));
  }
  else if (debug_view == DEBUG_SHADOW_FACTOR) {
    color = vec3(sun_visibility);
  }
  else if (debug_view == DEBUG_TEXEL_DENSITY) {
    int c = sun_tile;
    if (c < 0) {
      color = vec3(0.5);
    }
    else {
      float pixel_world = max(length(dFdx(p)), length(dFdy(p)));
      float texels_per_pixel = pixel_world / max(frame.shadow_tiles[c].texel_world, 1e-9);
      /* log2 scale: 1/8 texel per pixel -> red, 1 -> green, 8 -> blue. */
      color = heat_color(log2(max(texels_per_pixel, 1e-6)) / 6.0 + 0.5) *
              (0.35 + 0.65 * clamp(dot(n, normalize(frame.sun_direction)), 0.0, 1.0));
    }
  }
  else if (debug_view == DEBUG_ALBEDO) {
    color = s.albedo;
  }
  else if (debug_view == DEBUG_NORMAL) {
    color = n * 0.5 + 0.5;
  }
  else if (debug_view == DEBUG_POSITION) {
    /* Bands 1/20 of the shadow distance wide: readable whatever the scene's scale. */
    color = fract(p * 20.0 / max(frame.shadow_distance, 1e-6));
  }
  else if (debug_view == DEBUG_DEPTH) {
    color = vec3(clamp(s.view_depth / max(frame.shadow_distance, 1e-6), 0.0, 1.0));
  }
  else if (debug_view == DEBUG_AMBIENT_OCCLUSION) {
    color = vec3(ambient_visibility);
  }
  else if (debug_view == DEBUG_SHADOW_ERROR) {
    color = shadow_error_color(s, color, sun_visibility);
  }
  else if (debug_view == DEBUG_SPECULAR) {
    color = vec3(s.specular, s.roughness, s.metallic);
  }
  return color;
}
