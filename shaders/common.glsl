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

/* One PCF tap at atlas-tile position `tap` (texels): 1 lit, 0 shadowed. NOTE: the
 * receiver's biased depth is converted to the atlas's window depth once per pixel
 * (compare_window), so a tap is one fetch and one compare, with no per-tap linearization
 * (the lighting pass is fill-bound on llvmpipe). The receiver plane: the depth the
 * receiver's own surface has under the tapped texel's centre differs from its depth at
 * `receiver` by depth_per_texel . (centre - receiver); comparing against that instead of
 * one depth for every tap keeps a flat lit surface lit under any filter width. */
/* The tile's texel under atlas-tile position `tap`, kept inside the tile. */
vec2 tile_texel(float last_texel, vec2 tap)
{
  return clamp(floor(tap), vec2(0.0), vec2(last_texel));
}

float shadow_tap(vec2 origin, float last_texel, vec2 tap, vec2 receiver, float compare_window,
                 vec2 depth_per_texel)
{
  vec2 texel = tile_texel(last_texel, tap);
  float compare = compare_window + dot(depth_per_texel, texel + 0.5 - receiver);
  return texelFetch(shadow_atlas, ivec2(texel) + ivec2(origin), 0).r < compare ? 0.0 : 1.0;
}

/* The atlas's partial-caster mask (1: under an alpha-hashed caster) at a texel. */
float partial_caster_at(vec2 origin, float last_texel, vec2 tap)
{
  return texelFetch(shadow_partial, ivec2(tile_texel(last_texel, tap)) + ivec2(origin), 0).r;
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

/* The cross pattern's taps, then the nine-tap pattern's four corners (times the radius). */
const vec2 TAP_PATTERN_OFFSETS[9] = vec2[](vec2(0.0, 0.0), vec2(1.0, 0.0), vec2(-1.0, 0.0),
                                       vec2(0.0, 1.0), vec2(0.0, -1.0), vec2(1.0, 1.0),
                                       vec2(-1.0, 1.0), vec2(1.0, -1.0), vec2(-1.0, -1.0));

/* NOTE: the filter is chosen when the program is built (SHADOW_FILTER, one program per
 * Shadow Filter setting), not by a uniform: llvmpipe runs the code of a branch not taken
 * as well, so the soft filter's loops in the same program made PCF 2.4x slower. */
#ifndef SHADOW_FILTER
#  define SHADOW_FILTER FILTER_PCF
#endif

#if SHADOW_FILTER == FILTER_SOFT
/* Soft shadows (PCSS, after Fernando 2005): how far the penumbra reaches depends on how far
 * the receiver is behind its blockers, and on the light's size. */
const int BLOCKER_SAMPLES = 12;
const int SOFT_FILTER_SAMPLES = 12;
/* Widest blocker search and penumbra radius, in texels of the tile: beyond this a soft
 * shadow is cut to this width (a cascade's texels are its own unit, so the same number
 * holds in every cascade). */
const float SOFT_RADIUS_LIMIT_TEXELS = 48.0;
const float GOLDEN_ANGLE = 2.39996323;

/* A per-pixel rotation in 0..2pi (interleaved gradient noise, Jimenez 2014): neighbouring
 * pixels sample the disk at other angles, so the few samples read as fine grain instead of
 * banding. */
float sample_rotation()
{
  /* Each jittered sample of a final render turns the pattern by the golden ratio. */
  return 6.28318531 * fract(52.9829189 * fract(dot(gl_FragCoord.xy,
                                                   vec2(0.06711056, 0.00583715))) +
                            0.618034 * float(frame.sample_index));
}

/* Sample i of n on a Vogel (golden-angle) disk of radius 1, rotated by `rotation`. */
vec2 vogel_disk(int i, int n, float rotation)
{
  float r = sqrt((float(i) + 0.5) / float(n));
  float a = float(i) * GOLDEN_ANGLE + rotation;
  return r * vec2(cos(a), sin(a));
}

/* Four texels around `tap`, bilinearly weighted: 1 lit, 0 shadowed. A texel shadows when
 * it is in front of the receiver's plane under it and also in front of `ceiling`: the soft
 * filter passes the receiver point's own depth plus one texel of the plane's slope, as
 * nothing behind a point hides the light from it, and the plane continued past a concave
 * corner (a sunlit wall down to its foot) runs behind the ground there, which then read
 * as a blocker over half of a wide filter disk (docs/soft-shadows.md, twelfth session).
 * The slack keeps a caster that touches the receiver found right at the contact; within
 * a texel of the point the plane itself is always below the ceiling. */
float shadow_tap_bilinear(vec2 origin, float last_texel, vec2 tap, vec2 receiver,
                          float compare, vec2 depth_per_texel, float ceiling)
{
  vec2 t = tap - 0.5;
  vec2 base = floor(t);
  vec2 f = t - base;
  vec4 lit;
  for (int k = 0; k < 4; k++) {
    vec2 cell = tile_texel(last_texel, base + vec2(float(k % 2), float(k / 2)) + 0.5);
    float plane = compare + dot(depth_per_texel, cell + 0.5 - receiver);
    float stored = texelFetch(shadow_atlas, ivec2(cell) + ivec2(origin), 0).r;
    lit[k] = stored < min(plane, ceiling) ? 0.0 : 1.0;
  }
  return mix(mix(lit.x, lit.y, f.x), mix(lit.z, lit.w, f.x), f.y);
}

/* Penumbra radius, in texels along the tile's x and y, for a receiver at `receiver_linear`
 * behind blockers at `blocker_linear` (distances from the light). Sun (orthographic): the
 * sun's disk of half-angle h spreads an edge over 2 tan(h) (receiver - blocker) in the
 * world. Spot (perspective): a sphere of radius R at the light spreads it over 2 R (receiver
 * - blocker) / blocker; a texel there is texel_world * receiver wide. Per axis because a
 * cascade fitted to its visible receivers has rectangular texels: one texel count for both
 * axes made penumbrae half as wide as Cycles' along the finer one. */
vec2 penumbra_radius_texels(ShadowTileData tile, float light_size, float receiver_linear,
                            float blocker_linear, vec2 texel_world_xy)
{
  float distance = max(receiver_linear - blocker_linear, 0.0);
  float world = tile.is_perspective != 0 ? light_size * distance / max(blocker_linear, 1e-4) :
                                           light_size * distance;
  return world / texel_world_xy;
}

/* `radius` scaled down so that neither axis is wider than SOFT_RADIUS_LIMIT_TEXELS. */
vec2 limit_soft_radius(vec2 radius)
{
  float widest = max(radius.x, radius.y);
  return widest > SOFT_RADIUS_LIMIT_TEXELS ? radius * (SOFT_RADIUS_LIMIT_TEXELS / widest) :
                                             radius;
}

float soft_shadow(ShadowTileData tile, float light_size, vec2 texel, float compare,
                  vec2 depth_per_texel, float receiver_linear, vec2 texel_world_xy)
{
  vec2 origin = tile.atlas_origin;
  float last_texel = tile.resolution - 1.0;
  /* 1. Blocker search: where could something stand between this point and the light?
   * Up to the nearest depth anything in this tile has (display_near). */
  float nearest = max(tile.display_near, tile.light_near);
  vec2 search = max(limit_soft_radius(penumbra_radius_texels(
                        tile, light_size, receiver_linear, nearest, texel_world_xy)),
                    vec2(1.0));
  float rotation = sample_rotation();
  /* Only blockers inside the cone the light subtends from this point count: one there hides
   * part of the light; one outside it, however near, hides none (a PCSS that averaged every
   * blocker in the search put penumbrae on fully lit ground beside them and widened them,
   * docs/ground-truth.md, "Eleventh session"). A texel is inside when its nearest edge is
   * within the cone's radius at its height above the point (sun: tan(half angle) x height;
   * a sphere light of radius R at distance D: R x height / (D - height) in the receiver's
   * texels). The 3x3 texels around the point come first: a small light's cone is narrower
   * than the search's spacing. No blocker in the cone: fully lit. */
  float blocker_window = 0.0;
  float blockers = 0.0;
  for (int i = 0; i < 9 + BLOCKER_SAMPLES; i++) {
    vec2 tap = i < 9 ? floor(texel) + vec2(float(i % 3) - 1.0, float(i / 3) - 1.0) + 0.5 :
                       texel + search * vogel_disk(i - 9, BLOCKER_SAMPLES, rotation);
    vec2 cell = tile_texel(last_texel, tap);
    float plane = compare + dot(depth_per_texel, cell + 0.5 - texel);
    float stored = texelFetch(shadow_atlas, ivec2(cell) + ivec2(origin), 0).r;
    vec2 away = max(abs(cell + 0.5 - texel) - 0.5, vec2(0.0)) * texel_world_xy;
    float height = receiver_linear - shadow_linear_depth(stored, tile);
    float cone_radius = tile.is_perspective != 0 ?
                            light_size * height / max(receiver_linear - height, 1e-4) :
                            light_size * height;
    /* Masked, not branched: llvmpipe runs both sides of an `if` anyway. */
    float in_cone = (stored < plane && length(away) <= cone_radius) ? 1.0 : 0.0;
    blocker_window += in_cone * stored;
    blockers += in_cone;
  }
  if (blockers == 0.0) {
    return 1.0;
  }
  /* 2. The penumbra from the blockers' mean distance; 3. a filter that wide. */
  float blocker_linear = shadow_linear_depth(blocker_window / blockers, tile);
  vec2 radius = limit_soft_radius(penumbra_radius_texels(tile, light_size, receiver_linear,
                                                        blocker_linear, texel_world_xy));
  /* A penumbra narrower than a texel is one bilinear tap (an edge spread over +-0.5
   * texel), its ramp steepened to the penumbra's own width (2 x radius texels, at most 3x
   * steeper, as PCF Sharpen's default: steeper shows the texels' stair steps); wider ones,
   * a disk of bilinear taps as wide as the penumbra (the sun's disk gives the same
   * profile: the part of a disk an edge covers). The plain bilinear ramp made 1-degree
   * penumbrae 24-54 % wider than Cycles' (docs/soft-shadows.md, twelfth session). */
  float widest = max(radius.x, radius.y);
  float ceiling = compare + abs(depth_per_texel.x) + abs(depth_per_texel.y);
  radius = max(radius - 0.25, vec2(0.0));
  if (max(radius.x, radius.y) < 0.5) {
    float one = shadow_tap_bilinear(origin, last_texel, texel, texel, compare, depth_per_texel,
                                    ceiling);
    float sharpen = clamp(0.5 / max(widest, 1e-3), 1.0, 3.0);
    return clamp((one - 0.5) * sharpen + 0.5, 0.0, 1.0);
  }
  float lit = 0.0;
  for (int i = 0; i < SOFT_FILTER_SAMPLES; i++) {
    vec2 tap = texel + radius * vogel_disk(i, SOFT_FILTER_SAMPLES, rotation);
    lit += shadow_tap_bilinear(origin, last_texel, tap, texel, compare, depth_per_texel,
                               ceiling);
  }
  return lit / float(SOFT_FILTER_SAMPLES);
}
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
 * light_size: the sun's tan(half angle), or a spot light's radius (scene units); used by
 * the soft filter only. */
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
  /* Perspective tiles have no receiver plane: their slope bias also covers the filter's
   * width, as before. */
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
#elif SHADOW_FILTER == FILTER_HARD
  return shadow_tap(origin, last_texel, texel, texel, compare, depth_per_texel);
#else
  /* NOTE: llvmpipe runs both sides of every `if` (masked), so the patterns are loops
   * whose trip counts come from the settings: the pattern not chosen costs one masked
   * tap (a loop body always runs once), not its whole set. */
  int radius = int(pcf_radius);
  int pattern = frame.pcf_pattern;
  float lit = 0.0;
  /* Grid: (2r+1)^2 bilinearly weighted taps, gathered as the (2r+2)^2 texels they touch
   * with separable weights: the same footprint as hard taps, but edges ramp smoothly
   * instead of in texel-sized stair steps. */
  int last = (pattern == PCF_GRID && radius > 0) ? 2 * radius + 1 : -1;
  vec2 corner = texel - 0.5;
  vec2 base = floor(corner);
  vec2 f = corner - base;
#if defined(GPU_ARB_texture_gather) || __VERSION__ >= 400
  /* Four texels a fetch: textureGather returns the depths of the 2x2 texels around a
   * texel corner (x: left-top, y: right-top, z: right-bottom, w: left-bottom), so the
   * (2r+2)^2 texels take (r+1)^2 fetches (on llvmpipe a quarter of the fetch cost). A
   * block is kept inside the tile, as single taps are clamped to it. */
  vec2 atlas_step = 1.0 / vec2(textureSize(shadow_atlas, 0));
  int blocks = (last + 1) / 2;
  for (int by = 0; by < blocks; by++) {
    float wy0 = by == 0 ? 1.0 - f.y : 1.0;
    float wy1 = 2 * by + 1 == last ? f.y : 1.0;
    for (int bx = 0; bx < blocks; bx++) {
      float wx0 = bx == 0 ? 1.0 - f.x : 1.0;
      float wx1 = 2 * bx + 1 == last ? f.x : 1.0;
      vec2 block = clamp(base + vec2(float(2 * bx - radius), float(2 * by - radius)),
                         vec2(0.0), vec2(last_texel - 1.0));
      vec4 stored = textureGather(shadow_atlas, (origin + block + 1.0) * atlas_step);
      float plane = compare + dot(depth_per_texel, block + 0.5 - texel);
      vec4 planes = plane + vec4(depth_per_texel.y, depth_per_texel.x + depth_per_texel.y,
                                 depth_per_texel.x, 0.0);
      lit += dot(step(planes, stored), vec4(wx0 * wy1, wx1 * wy1, wx1 * wy0, wx0 * wy0));
    }
  }
#else
  for (int y = 0; y <= last; y++) {
    float wy = (y == 0) ? 1.0 - f.y : ((y == last) ? f.y : 1.0);
    for (int x = 0; x <= last; x++) {
      float wx = (x == 0) ? 1.0 - f.x : ((x == last) ? f.x : 1.0);
      vec2 center = base + vec2(float(x - radius), float(y - radius)) + 0.5;
      lit += wx * wy * shadow_tap(origin, last_texel, center, texel, compare, depth_per_texel);
    }
  }
#endif
  /* Cross (5 taps) and nine-tap (3x3) patterns r texels apart; radius 0 is one hard tap. */
  int taps = radius == 0 ? 1 : (pattern == PCF_CROSS5 ? 5 : (pattern == PCF_NINE_TAP ? 9 : 0));
  float r = float(radius);
  for (int k = 0; k < taps; k++) {
    lit += shadow_tap(origin, last_texel, texel + r * TAP_PATTERN_OFFSETS[k], texel, compare,
                      depth_per_texel);
  }
  /* PCF Sharpen: steeper around 0.5, so the edge stays where the kernel smoothed it to
   * (no texel stair steps) while its ramp narrows, and a kernel reaching a little over a
   * shadow edge or onto a step beside lit ground leaves that ground fully lit (the plain
   * 3x3 ramp leaves faint stripes along voxel edges). After Unreal's Shadow Filter
   * Sharpen. Not under an alpha-hashed caster (the atlas's partial-caster mask at this
   * texel, see shadow_frag.glsl): its shadow is the share of its texels the kernel
   * finds, which sharpening would threshold away. */
  float filtered = lit / float(last >= 0 ? (last * last) : taps);
  float sharpen = partial_caster_at(origin, last_texel, texel) > 0.5 ? 1.0 : frame.pcf_sharpen;
  return clamp((filtered - 0.5) * sharpen + 0.5, 0.0, 1.0);
#endif
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

/* The sun's shadow lookups for a pixel at this view depth: its cascade (-1 beyond the
 * last) and, inside a blend band, the next cascade's weight (0 elsewhere). The lighting
 * pass looks up cascade i, then cascade i + 1 where the weight is above 0, and mixes:
 * sun_shadow_fade() gives the distance fade. */
int sun_cascade(float view_depth, out float next_weight)
{
  int i = cascade_index(view_depth);
  next_weight = 0.0;
  if (i >= 0 && i + 1 < frame.cascade_count) {
    float split = frame.cascades[i].far_depth;
    float band = frame.cascades[i].blend_band;
    /* The next cascade's box was fitted from split - band on, so it covers this point. */
    if (band > 0.0) {
      next_weight = clamp((view_depth - (split - band)) / band, 0.0, 1.0);
    }
  }
  return i;
}

/* Width (texels) of the cross-fade inside a finer cascade's map edge under map selection. */
const float MAP_BLEND_TEXELS = 48.0;

/* Map selection (SELECT_MAP): the first cascade whose shadow map holds p with `reach`
 * texels to spare for the filter, whatever slice of view depth p is in, and within
 * MAP_BLEND_TEXELS of that map's edge the next cascade that holds p mixed in (`second`,
 * weight `second_weight`). A cascade fitted to its receivers renders every caster over
 * its whole rectangle, which reaches past its slice's far split, so points there get its
 * finer texels too (docs/soft-shadows.md, "Cascade selection"). When no map holds p with
 * room: `cascade`, the depth slice's own, unmixed. */
int sun_cascade_by_map(vec3 p, int cascade, float reach, out int second,
                       out float second_weight)
{
  int first = -1;
  second = -1;
  second_weight = 0.0;
  for (int i = 0; i < MAX_CASCADES; i++) {
    if (i >= frame.cascade_count) {
      break;
    }
    ShadowTileData tile = frame.shadow_tiles[i];
    vec3 s = (tile.shadow_from_world * vec4(p, 1.0)).xyz; /* orthographic: w is 1 */
    /* Texels to the map's side edges (less the filter's reach), and to its far plane
     * (the box ends there too: a point beyond it is not in the map). */
    float inside = min(min(min(s.x, s.y), min(1.0 - s.x, 1.0 - s.y)) * tile.resolution - reach,
                       (1.0 - s.z) * (tile.light_far - tile.light_near) / tile.texel_world);
    bool holds = inside > 0.0;
    if (holds && first >= 0) {
      second = i;
      break;
    }
    if (holds) {
      first = i;
      float band = frame.cascades[i].blend_band > 0.0 ? MAP_BLEND_TEXELS : 0.0;
      second_weight = inside < band ? 1.0 - inside / band : 0.0;
      if (second_weight == 0.0) {
        break;
      }
    }
  }
  if (second < 0) {
    second_weight = 0.0;
  }
  return first >= 0 ? first : cascade;
}

/* Shadow visibility v faded out towards the Shadow Distance. */
float sun_shadow_fade(float vis, float view_depth)
{
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
