/* Shared lighting and shadow code: cascade selection, shadow-atlas lookup with bias and PCF,
 * Blinn-Phong in EEVEE's light units, light falloff, debug colour ramps. Included by
 * lighting_frag.glsl.
 *
 * frame (FrameData, with ShadowTileData, CascadeData, ...) and the constants DEBUG_*, PCF_*,
 * MAX_* come from core/frame_layout.py, which generates the struct text and the #defines:
 * the field meanings and units are documented there. */

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

/* One PCF tap: 1 lit, 0 shadowed. NOTE: the receiver's biased depth is converted to the
 * atlas's window depth once per pixel (compare_window), so a tap is one fetch and one
 * compare, with no per-tap linearization (the lighting pass is fill-bound on llvmpipe). */
float shadow_tap(vec2 origin, float last_texel, vec2 texel, float compare_window)
{
  ivec2 p = ivec2(clamp(floor(texel), vec2(0.0), vec2(last_texel))) + ivec2(origin);
  return texelFetch(shadow_atlas, p, 0).r < compare_window ? 0.0 : 1.0;
}

/* Visibility (1 lit, 0 shadowed) of world point p with normal n from shadow tile t. */
float shadow_tile_visibility(int t, vec3 p, vec3 n, float n_dot_l)
{
  ShadowTileData tile = frame.shadow_tiles[t];

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
  float bias = texel_world * (frame.depth_bias_texels + frame.slope_bias_texels * tan_l *
                              (1.0 + pcf_radius));

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

  int radius = int(pcf_radius);
  int pattern = frame.pcf_pattern;
  if (radius == 0) {
    return shadow_tap(origin, last_texel, texel, compare);
  }
  float lit = 0.0;
  float taps = 0.0;
  if (pattern == PCF_GRID) {
    /* (2r+1)^2 bilinearly weighted taps, gathered as the (2r+2)^2 texels they touch with
     * separable weights: the same footprint as hard taps, but edges ramp smoothly instead
     * of in texel-sized stair steps. */
    vec2 t = texel - 0.5;
    vec2 base = floor(t);
    vec2 f = t - base;
    int last = 2 * radius + 1;
    for (int y = 0; y <= last; y++) {
      float wy = (y == 0) ? 1.0 - f.y : ((y == last) ? f.y : 1.0);
      for (int x = 0; x <= last; x++) {
        float wx = (x == 0) ? 1.0 - f.x : ((x == last) ? f.x : 1.0);
        vec2 center = base + vec2(float(x - radius), float(y - radius)) + 0.5;
        lit += wx * wy * shadow_tap(origin, last_texel, center, compare);
      }
    }
    taps = float(last * last);
  }
  else {
    float r = float(radius);
    lit = shadow_tap(origin, last_texel, texel, compare);
    lit += shadow_tap(origin, last_texel, texel + vec2(r, 0.0), compare);
    lit += shadow_tap(origin, last_texel, texel + vec2(-r, 0.0), compare);
    lit += shadow_tap(origin, last_texel, texel + vec2(0.0, r), compare);
    lit += shadow_tap(origin, last_texel, texel + vec2(0.0, -r), compare);
    taps = 5.0;
    if (pattern == PCF_NINE_TAP) {
      lit += shadow_tap(origin, last_texel, texel + vec2(r, r), compare);
      lit += shadow_tap(origin, last_texel, texel + vec2(-r, r), compare);
      lit += shadow_tap(origin, last_texel, texel + vec2(r, -r), compare);
      lit += shadow_tap(origin, last_texel, texel + vec2(-r, -r), compare);
      taps = 9.0;
    }
  }
  return lit / taps;
}

/* Index of the cascade whose slice holds this view depth, or -1 beyond the last. */
int cascade_index(float view_depth)
{
  int count = frame.cascade_count;
  for (int i = 0; i < MAX_CASCADES; i++) {
    if (i < count && view_depth <= frame.cascades[i].far_depth) {
      return i;
    }
  }
  return -1;
}

/* Sun visibility with cascade blending and distance fade.
 * cascade_out: cascade index, with a fractional part inside a blend band (2.3 = 70% of
 * cascade 2 and 30% of cascade 3), or -1 where nothing is shadowed. */
float sun_visibility(vec3 p, vec3 n, float n_dot_l, float view_depth, out float cascade_out)
{
  int i = cascade_index(view_depth);
  cascade_out = float(i);
  if (i < 0) {
    return 1.0;
  }
  float vis = shadow_tile_visibility(i, p, n, n_dot_l);
  int count = frame.cascade_count;
  float split = frame.cascades[i].far_depth;
  float band = frame.cascades[i].blend_band;
  if (i + 1 < count && band > 0.0 && view_depth > split - band) {
    /* The next cascade's box was fitted from split - band on, so it covers this point. */
    float w = clamp((view_depth - (split - band)) / band, 0.0, 1.0);
    vis = mix(vis, shadow_tile_visibility(i + 1, p, n, n_dot_l), w);
    cascade_out += w;
  }
  float fade_start = frame.fade_start_depth;
  float distance = frame.shadow_distance;
  if (distance > fade_start && view_depth > fade_start) {
    vis = mix(vis, 1.0, clamp((view_depth - fade_start) / (distance - fade_start), 0.0, 1.0));
  }
  return vis;
}

const float PI = 3.14159265358979;
/* Principled BSDF's convention: Specular level 0.5 is a reflectance of 0.04 at normal
 * incidence (glass, plastic), so F0 = 0.08 * level. */
const float F0_PER_SPECULAR_LEVEL = 0.08;

/* Outgoing radiance for an irradiance of one (W/m^2 on a surface facing the light), with
 * Principled's Metallic: a metal has no diffuse part and reflects its base colour,
 * F0 = mix(0.08 * specular, base colour, metallic); blinn_phong below is the dielectric. */
vec3 surface_brdf(vec3 albedo, float metallic, float specular, float shininess, vec3 n,
                  vec3 l, vec3 v)
{
  float n_dot_l = max(dot(n, l), 0.0);
  if (n_dot_l <= 0.0) {
    return vec3(0.0);
  }
  vec3 h = normalize(l + v);
  float exponent = max(shininess, 1.0);
  vec3 f0 = mix(vec3(F0_PER_SPECULAR_LEVEL * specular), albedo, metallic);
  float lobe = (exponent + 8.0) / (8.0 * PI) * pow(max(dot(n, h), 0.0), exponent);
  return (albedo * ((1.0 - metallic) / PI) + f0 * lobe) * n_dot_l;
}

/* Outgoing radiance for an irradiance of one (W/m^2 on a surface facing the light): the
 * BRDF times cos(angle to the light). Units as EEVEE's (docs/lighting.md): diffuse is
 * Lambert, albedo / pi; specular is energy-normalized Blinn-Phong,
 * F0 (n + 8) / (8 pi) (n.h)^n, whose lobe reflects about F0 of the light whatever the
 * exponent, so a white surface never sends back more than it receives. */
vec3 blinn_phong(vec3 albedo, float specular, float shininess, vec3 n, vec3 l, vec3 v)
{
  return surface_brdf(albedo, 0.0, specular, shininess, n, l, v);
}

/* How a point or spot light's colour (see PointLightData) reaches distance d. */
float distance_falloff(int falloff, float d, float radius)
{
  if (falloff == FALLOFF_LINEAR_RADIUS) {
    /* The course's falloff: linear to zero at the light's radius. */
    return 1.0 - min(d / max(radius, 1e-6), 1.0);
  }
  /* Inverse square, cut off smoothly at the influence radius as EEVEE does
   * (light_influence_attenuation, after Frostbite). NOTE: d^2 is kept above 1 cm^2, where
   * EEVEE's light would be a sphere of finite radiance, not a point. */
  float x = d * d / max(radius * radius, 1e-12);
  float window = clamp(1.0 - x * x, 0.0, 1.0);
  return window * window / max(d * d, 1e-4);
}

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
