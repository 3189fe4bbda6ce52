/* The PCF shadow filter (Shadow Filter: PCF): a grid of bilinearly weighted taps, or the
 * cross (5-tap) and nine-tap patterns, PCF Radius texels apart, then PCF Sharpen.
 * Used by shadow_lookup.glsl in the programs built with SHADOW_FILTER FILTER_PCF. The
 * patterns and Radius 0's one hard tap are read only by programs built with
 * WITH_PCF_PATTERNS (render/lighting.py picks them for frames that use them); the others
 * hold the grid alone. */
#include "shadow_atlas.glsl"

/* The cross pattern's taps, then the nine-tap pattern's four corners (times the radius). */
const vec2 TAP_PATTERN_OFFSETS[9] = vec2[](vec2(0.0, 0.0), vec2(1.0, 0.0), vec2(-1.0, 0.0),
                                       vec2(0.0, 1.0), vec2(0.0, -1.0), vec2(1.0, 1.0),
                                       vec2(-1.0, 1.0), vec2(1.0, -1.0), vec2(-1.0, -1.0));

/* Visibility (1 lit, 0 shadowed) at atlas-tile position `texel` (texels) of the tile at
 * atlas texel `origin`, for a receiver at window depth `compare` on a plane sloping by
 * `depth_per_texel` (see shadow_tap). */
float pcf_shadow(vec2 origin, float last_texel, vec2 texel, float compare, vec2 depth_per_texel)
{
  /* NOTE: llvmpipe runs both sides of every `if` (masked), so the grid and the patterns
   * are one loop whose trip count comes from the settings: no pattern costs the taps of
   * another. */
  int radius = int(frame.pcf_radius_texels);
  int pattern = frame.pcf_pattern;
  float lit = 0.0;
  /* Grid: (2r+1)^2 bilinearly weighted taps, gathered as the (2r+2)^2 texels they touch
   * with separable weights: the same footprint as hard taps, but edges ramp smoothly
   * instead of in texel-sized stair steps. */
  int last = (pattern == PCF_GRID && radius > 0) ? 2 * radius + 1 : -1;
  /* Cross (5 taps) and nine-tap (3x3) patterns r texels apart; radius 0 is one hard tap. */
  int taps = radius == 0 ? 1 : (pattern == PCF_CROSS5 ? 5 : (pattern == PCF_NINE_TAP ? 9 : 0));
  vec2 corner = texel - 0.5;
  vec2 base = floor(corner);
  vec2 f = corner - base;
#if defined(GPU_ARB_texture_gather) || __VERSION__ >= 400
  /* Four texels a fetch: textureGather returns the depths of the 2x2 texels around a
   * texel corner (x: left-top, y: right-top, z: right-bottom, w: left-bottom), so the
   * (2r+2)^2 texels take (r+1)^2 fetches (on llvmpipe a quarter of the fetch cost). A
   * block is kept inside the tile, as single taps are clamped to it. The cross and
   * nine-tap patterns' taps are fetched the same way, each weighting the one texel of
   * its block that it reads.
   * NOTE: one loop for the grid and the patterns, with its test at the end of its body:
   * llvmpipe runs a loop's body once more, every pixel masked off, before a test at its
   * start lets it leave, and runs a loop that no pixel enters once all the same, so two
   * nested grid loops and a pattern loop cost (r+2)^2 + 1 fetches instead of (r+1)^2. */
  vec2 atlas_step = 1.0 / vec2(textureSize(shadow_atlas, 0));
  int blocks = (last + 1) / 2;
  int fetches = last >= 0 ? blocks * blocks : taps;
  float r = float(radius);
  /* The grid's block (bx, by) of fetch k, row by row. NOTE: counted along, not k's
   * quotient and remainder: llvmpipe divides integers one pixel at a time. */
  int bx = 0;
  int by = 0;
  for (int k = 0; ; k++) {
    /* The block's texels' bilinear tap weights. */
    float wy0 = by == 0 ? 1.0 - f.y : 1.0;
    float wy1 = 2 * by + 1 == last ? f.y : 1.0;
    float wx0 = bx == 0 ? 1.0 - f.x : 1.0;
    float wx1 = 2 * bx + 1 == last ? f.x : 1.0;
    vec2 block = clamp(base + vec2(float(2 * bx - radius), float(2 * by - radius)),
                       vec2(0.0), vec2(last_texel - 1.0));
    vec4 weights = vec4(wx0 * wy1, wx1 * wy1, wx1 * wy0, wx0 * wy0);
#ifdef WITH_PCF_PATTERNS
    /* NOTE: only in WITH_PCF_PATTERNS programs: llvmpipe runs this for every pixel and
     * every fetch whether or not the frame uses a pattern (about a twentieth of the
     * lighting pass). */
    if (last < 0) {
      /* The pattern's tap k: its texel (clamped to the tile as shadow_tap does) in the
       * block that holds it. */
      vec2 tap = tile_texel(last_texel, texel + r * TAP_PATTERN_OFFSETS[min(k, 8)]);
      block = min(tap, vec2(max(last_texel - 1.0, 0.0)));
      vec2 d = tap - block;
      weights = vec4((1.0 - d.x) * d.y, d.x * d.y, d.x * (1.0 - d.y),
                     (1.0 - d.x) * (1.0 - d.y));
    }
#endif
    vec4 stored = textureGather(shadow_atlas, (origin + block + 1.0) * atlas_step);
    float plane = compare + dot(depth_per_texel, block + 0.5 - texel);
    vec4 planes = plane + vec4(depth_per_texel.y, depth_per_texel.x + depth_per_texel.y,
                               depth_per_texel.x, 0.0);
    lit += k < fetches ? dot(step(planes, stored), weights) : 0.0;
    if (k + 1 >= fetches) {
      break;
    }
    bx++;
    if (bx >= blocks) {
      bx = 0;
      by++;
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
  /* Cross (5 taps) and nine-tap (3x3) patterns r texels apart; radius 0 is one hard tap. */
  float r = float(radius);
  for (int k = 0; k < taps; k++) {
    lit += shadow_tap(origin, last_texel, texel + r * TAP_PATTERN_OFFSETS[k], texel, compare,
                      depth_per_texel);
  }
#endif
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
}
