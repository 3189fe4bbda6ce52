/* The soft shadow filter (Shadow Filter: Soft): PCSS (after Fernando 2005) from the light's
 * size, with the blocker search limited to the cone the light subtends, a rotated Vogel
 * disk of bilinear taps as wide as the penumbra, and one steepened tap for penumbrae
 * narrower than a texel. Used by shadow_lookup.glsl in the programs built with
 * SHADOW_FILTER FILTER_SOFT. */
#include "shadow_atlas.glsl"

/* Taps of the blocker search and of the penumbra filter's disk. */
const int BLOCKER_SAMPLES = 12;
const int SOFT_FILTER_SAMPLES = 12;
/* Widest blocker search and penumbra radius, in texels of the tile: beyond this a soft
 * shadow is cut to this width (a cascade's texels are its own unit, so the same number
 * holds in every cascade). */
const float SOFT_RADIUS_LIMIT_TEXELS = 48.0;
const float GOLDEN_ANGLE = 2.39996323;

/* Texels on a side of a block of shadow_nearest_blocks (render/blocker_search.py): the
 * atlas's nearest stored depth per block. A block is wider than SOFT_RADIUS_LIMIT_TEXELS,
 * so the 3x3 blocks around a point hold everything its search can reach. */
const float NEAREST_BLOCK_TEXELS = 64.0;

/* The nearest depth (window depth, 1 for none) stored within reach of atlas-tile position
 * `texel` of `tile`. Blocks may straddle a neighbouring tile: its depths only make the
 * bound nearer, so the search wider, never too narrow. */
float nearest_depth_within_reach(ShadowTileData tile, vec2 texel)
{
  vec2 in_tile = clamp(texel, vec2(0.0), vec2(tile.resolution - 1.0));
  ivec2 block = ivec2((tile.atlas_origin + in_tile) / NEAREST_BLOCK_TEXELS);
  ivec2 last = textureSize(shadow_nearest_blocks, 0) - 1;
  float nearest = 1.0;
  for (int i = 0; i < 9; i++) {
    ivec2 b = clamp(block + ivec2(i % 3 - 1, i / 3 - 1), ivec2(0), last);
    nearest = min(nearest, texelFetch(shadow_nearest_blocks, b, 0).r);
  }
  return nearest;
}

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
 * as a blocker over half of a wide filter disk (docs/soft-shadows.md).
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

/* Visibility (1 lit, 0 shadowed) at atlas-tile position `texel` (texels) of `tile` for a
 * receiver `receiver_linear` from the light (window depth `compare`, on a plane sloping
 * by `depth_per_texel`), from a light of size `light_size` (the sun's tan(half angle), or
 * a spot or point light's radius in scene units); texel_world_xy: the tile's texel size
 * (scene units) along x and y at the receiver. */
float soft_shadow(ShadowTileData tile, float light_size, vec2 texel, float compare,
                  vec2 depth_per_texel, float receiver_linear, vec2 texel_world_xy)
{
  vec2 origin = tile.atlas_origin;
  float last_texel = tile.resolution - 1.0;
  /* 1. Blocker search: where could something stand between this point and the light?
   * Up to the nearest caster within the search's reach: a search sized to the tile's
   * nearest caster (display_near) spread a low caster's few taps over many times its
   * cone, and its penumbra's lit side went unseen. */
  float nearest = max(max(tile.display_near, tile.light_near),
                      shadow_linear_depth(nearest_depth_within_reach(tile, texel), tile));
  vec2 search = max(limit_soft_radius(penumbra_radius_texels(
                        tile, light_size, receiver_linear, nearest, texel_world_xy)),
                    vec2(1.0));
  float rotation = sample_rotation();
  /* Only blockers inside the cone the light subtends from this point count: one there hides
   * part of the light; one outside it, however near, hides none (a PCSS that averaged every
   * blocker in the search put penumbrae on fully lit ground beside them and widened them,
   * docs/ground-truth.md). A texel is inside when its nearest edge is
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
   * penumbrae 24-54 % wider than Cycles' (docs/soft-shadows.md). */
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
