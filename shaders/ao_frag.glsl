/* Screen-space ambient occlusion: four programs from this one file, all at half resolution.
 *
 * "ao_mask" (AO_MASK defined): depth 0 where there is something to search, 1 elsewhere;
 * the other three are drawn depth-tested against it.
 *
 * "ao": a GTAO-style horizon search (Jimenez et al. 2016, "Practical Real-Time Strategies
 * for Accurate Indirect Occlusion"). Each pixel walks the depth buffer both ways along one
 * screen direction (its slice), keeps the highest horizon on each side within
 * frame.ao_distance, and integrates the cosine-weighted visible arc between the two
 * horizons in closed form. Averaged over directions this is the fraction of the
 * cosine-weighted hemisphere not occluded within the distance, the quantity Cycles' AO
 * pass estimates by ray casting (1 = open sky, 0 = fully occluded). Direction and step
 * offset come from a 4x4 interleave (every 4x4 block holds all sixteen). It writes the
 * slice's visible arc, its arc with nothing above the tangent plane, the view depth of
 * the full-resolution pixel it stands for and that pixel's normal, packed.
 *
 * "ao_blur_rows", "ao_blur" (AO_BLUR defined, AO_BLUR_AXIS 0, 1): a separable depth-aware
 * blur, 7 taps along the rows, then 7 along the columns, weighted 1 2 3 4 3 2 1: the
 * visible arcs summed over the open arcs summed, which removes the pattern without
 * leaving blocks. A tap counts only when its surface point lies on the pixel's tangent
 * plane (within a few pixel footprints), so occlusion does not bleed across silhouettes
 * and a grazing plane still blurs along itself. Written as (AO, view depth); the lighting
 * pass brings it to full resolution (ambient_occlusion_at in ao_upsample.glsl).
 *
 * NOTE (llvmpipe): the cost is the search's depth reads, then the blur's taps; hence one
 * slice per pixel and 7 steps a side (two slices of 8 with a 4x4 blur cost 1.7 times as
 * much for the same error against Cycles, docs/ambient-occlusion.md), a blur of 7 + 7 taps
 * rather than 49, and everything at half resolution. Pixels with nothing to search are
 * kept out of the search and the blur by a depth test, not an `if`: llvmpipe skips the
 * pixel blocks that fail an early depth test, and runs both sides of an `if`.
 *
 * Inputs: the G-buffer's view depth (0 = background) and world normal. */

#include "gbuffer_layout.glsl"

#define AO_PI 3.14159265358979
#define AO_STEPS 7             /* per side of a slice */
#define AO_MAX_RADIUS 256.0    /* pixels: a nearby occluder farther on screen is missed */

/* View-space position (camera looks along -Z) of full-resolution pixel p at view depth d. */
vec3 ao_view_position(ivec2 p, float d)
{
  vec2 ndc = (vec2(p) + 0.5) / frame.viewport_size * 2.0 - 1.0;
  vec2 xy = ndc * frame.ao_view_ray.xy + frame.ao_view_ray.zw;
  return vec3(frame.is_perspective != 0 ? xy * d : xy, -d);
}

/* One full-resolution pixel covers this many scene units at view depth d. */
float ao_pixel_footprint(float d)
{
  return (frame.is_perspective != 0 ? d : 1.0) / frame.ao_pixels_per_unit;
}

/* A unit view-space normal in one float channel, for the blur (reading the G-buffer's
 * full-resolution normal again was a large part of each blur pass): octahedral
 * coordinates at 12 bits each, as an integer below 2^24, which a float holds exactly. */
float ao_pack_normal(vec3 n)
{
  vec2 oct = n.xy / (abs(n.x) + abs(n.y) + abs(n.z));
  oct = n.z >= 0.0 ? oct : (1.0 - abs(oct.yx)) * vec2(oct.x >= 0.0 ? 1.0 : -1.0,
                                                       oct.y >= 0.0 ? 1.0 : -1.0);
  vec2 u = round(clamp(oct * 0.5 + 0.5, 0.0, 1.0) * 4095.0);
  return u.x * 4096.0 + u.y;
}

vec3 ao_unpack_normal(float code)
{
  float x = floor(code / 4096.0);
  vec2 oct = vec2(x, code - x * 4096.0) / 4095.0 * 2.0 - 1.0;
  vec3 n = vec3(oct, 1.0 - abs(oct.x) - abs(oct.y));
  n.xy = n.z >= 0.0 ? n.xy : (1.0 - abs(n.yx)) * vec2(n.x >= 0.0 ? 1.0 : -1.0,
                                                      n.y >= 0.0 ? 1.0 : -1.0);
  return normalize(n);
}

/* The screen radius (full-resolution pixels) of the distance around a pixel at view depth
 * d, at most AO_MAX_RADIUS; below 1.5 (and on the background, d 0) there is nothing to
 * search: everything within the distance is inside the pixel. */
float ao_radius_px(float d)
{
  return d > 0.0 ? min(frame.ao_distance / ao_pixel_footprint(d), AO_MAX_RADIUS) : 0.0;
}

#ifdef AO_MASK

/* Depth 0 where there is something to search, 1 on the background and where everything
 * within the distance is inside the pixel. The search and both blur passes are drawn
 * depth-tested against it (GREATER, their triangle at depth 1): llvmpipe skips the pixel
 * blocks that fail an early depth test, where an `if` in the shader would save nothing. */
void main()
{
  ivec2 p = min(ivec2(gl_FragCoord.xy) * 2, ivec2(frame.viewport_size) - 1);
  gl_FragDepth = ao_radius_px(gbuffer_view_depth(texelFetch(gbuffer_depth, p, 0))) >= 1.5 ? 0.0 : 1.0;
}

#elif !defined(AO_BLUR)

/* The slice direction and step offset of half-resolution pixel p, from a 4x4 interleave:
 * index (a 4x4 ordered dither, so neighbours get far-apart directions) picks one of
 * AO_ROTATIONS directions evenly spread over half a turn, (index + 0.5) / AO_ROTATIONS *
 * pi, and a step offset (index * 7 mod 16 + 0.5) / 16, so directions next to each other
 * start their steps far apart. Every 4x4 block of pixels holds each pair once: the blur's
 * 4x4 box sees the same sixteen wherever it stands, and on a smooth surface the pattern
 * leaves nothing behind. */
#define AO_ROTATIONS 16
const vec2 AO_DIRECTIONS[AO_ROTATIONS] = vec2[AO_ROTATIONS](
    vec2(0.99518473, 0.09801714),
    vec2(0.95694034, 0.29028468),
    vec2(0.88192126, 0.47139674),
    vec2(0.77301045, 0.63439328),
    vec2(0.63439328, 0.77301045),
    vec2(0.47139674, 0.88192126),
    vec2(0.29028468, 0.95694034),
    vec2(0.09801714, 0.99518473),
    vec2(-0.09801714, 0.99518473),
    vec2(-0.29028468, 0.95694034),
    vec2(-0.47139674, 0.88192126),
    vec2(-0.63439328, 0.77301045),
    vec2(-0.77301045, 0.63439328),
    vec2(-0.88192126, 0.47139674),
    vec2(-0.95694034, 0.29028468),
    vec2(-0.99518473, 0.09801714));

int ao_pattern_index(ivec2 p)
{
  ivec2 q = p & 3;
  return ((q.x ^ q.y) & 1) * 8 + (q.y & 1) * 4 + (((q.x ^ q.y) >> 1) & 1) * 2 +
         ((q.y >> 1) & 1);
}

/* acos on [-1, 1] to ~7e-5 rad (Abramowitz & Stegun 4.4.45): a few multiplies and a
 * square root where the built-in is a long polynomial with range reduction. */
float ao_acos(float x)
{
  float a = abs(x);
  float r = sqrt(1.0 - a) * (1.5707288 + a * (-0.2121144 + a * (0.0742610 - 0.0187293 * a)));
  return x >= 0.0 ? r : AO_PI - r;
}

/* Four times the slice's cosine-weighted visible arc on one side, GTAO's closed form
 * cos n + 2 h sin n - cos(2h - n) for horizon angle h (its cosine c and sine s) and the
 * projected normal's angle n (cos_n, sin_n), without trigonometric calls. */
float ao_arc(float h, float c, float s, float cos_n, float sin_n)
{
  float cos_2h_n = (2.0 * c * c - 1.0) * cos_n + 2.0 * s * c * sin_n;
  return cos_n + 2.0 * h * sin_n - cos_2h_n;
}

void main()
{
  ivec2 size = ivec2(frame.viewport_size);
  ivec2 ao_pixel = ivec2(gl_FragCoord.xy);
  ivec2 p = min(ao_pixel * 2, size - 1);
  float depth = gbuffer_view_depth(texelFetch(gbuffer_depth, p, 0));
  float radius_px = ao_radius_px(depth);
  /* Drawn only where the mask found something to search; a pixel of a block drawn for
   * its neighbours takes no step and is "open". */
  bool searched = radius_px >= 1.5;
  radius_px = searched ? radius_px : -1.0;
  vec3 center = ao_view_position(p, depth);
  vec3 n = normalize(mat3(frame.view_from_world) * octahedral_unpack(texelFetch(gbuffer_surface_target, p, 0).z));
  vec3 v = frame.is_perspective != 0 ? normalize(-center) : vec3(0.0, 0.0, 1.0);
  /* View-space xy of full-resolution pixel q at depth d: (q * ray_scale + ray_offset) * d
   * (times 1 in an orthographic view), as ao_view_position. */
  vec2 ray_scale = 2.0 / frame.viewport_size * frame.ao_view_ray.xy;
  vec2 ray_offset = (1.0 / frame.viewport_size - 1.0) * frame.ao_view_ray.xy +
                    frame.ao_view_ray.zw;
  float perspective = frame.is_perspective != 0 ? 1.0 : 0.0;
  float fade = 1.0 / (0.05 * frame.ao_distance);
  /* A sample clamped back onto the pixel itself is the pixel, whatever rounding says. */
  float self_height = 1e-3 * ao_pixel_footprint(depth);
  int pattern = ao_pattern_index(ao_pixel);
  float jitter = (float((pattern * 7) & 15) + 0.5) / 16.0;

  /* The visible arc and the arc with nothing above the tangent plane (the slice's share
   * of the cosine-weighted hemisphere) go to the blur, which divides the sum of one by the
   * sum of the other over its neighbourhood: a pixel with nothing nearby is exactly 1. */
  vec2 dir = AO_DIRECTIONS[pattern];
  /* With square pixels, a screen direction is the same direction in view space, and the
   * plane through the eye, the pixel and that direction is the slice. */
  vec3 dir_v = vec3(dir, 0.0);
  vec3 ortho = dir_v - dot(dir_v, v) * v;
  vec3 axis = normalize(cross(ortho, v));
  vec3 n_proj = n - axis * dot(n, axis);
  /* A slice holding no part of the hemisphere's weight adds nothing to either sum. */
  float n_proj_len = length(n_proj);
  float cos_n = clamp(dot(n_proj, v) / max(n_proj_len, 1e-6), 0.0, 1.0);
  float sin_n = (dot(ortho, n_proj) < 0.0 ? -1.0 : 1.0) * sqrt(1.0 - cos_n * cos_n);
  float angle_n = sin_n < 0.0 ? -ao_acos(cos_n) : ao_acos(cos_n);
  /* The tangent plane's horizons, cos(angle_n +- pi/2): the lowest either side keeps. */
  float low_plus = -sin_n;
  float low_minus = sin_n;
  float cos_plus = low_plus;
  float cos_minus = low_minus;
  /* Steps at least a pixel apart: a pixel whose distance spans a few pixels takes fewer
   * (llvmpipe leaves the loop once a whole block of pixels has). */
  for (int k = 0; k < AO_STEPS && float(k) <= radius_px; k++) {
    /* Nearly even spacing, a little denser towards the end: the highest horizon within
     * the distance is often near its end (a wall's points at exactly the distance), so
     * the far steps matter as much as the near (s (1.3 - 0.3 s) with 7 steps: the error
     * against Cycles of 8 evenly spaced ones, docs/ambient-occlusion.md). */
    float s = (float(k) + jitter) / float(AO_STEPS);
    float t = max(s * (1.3 - 0.3 * s) * radius_px, 1.5 + float(k));
    vec2 offset = round(dir * t);
    for (int side = 0; side < 2; side++) {
      /* Off the screen: the border pixel, a real surface point (none beyond it). */
      ivec2 q = clamp(p + ivec2(side == 0 ? offset : -offset), ivec2(0), size - 1);
      float d = gbuffer_view_depth(texelFetch(gbuffer_depth, q, 0));
      vec3 delta = vec3((vec2(q) * ray_scale + ray_offset) * mix(1.0, d, perspective), -d) -
                   center;
      float dist2 = dot(delta, delta);
      float inv_dist = inversesqrt(max(dist2, 1e-20));
      float dist = dist2 * inv_dist;
      /* Cycles counts a hit within the distance only; the last 5 % fades, so the border
       * of the occluded band does not band with the step pattern. The background (d 0)
       * occludes nothing.
       * NOTE: a sample is the centre of the pixel nearest the step, a little off the
       * slice plane; on a flat surface that alone reads as a horizon just above the
       * tangent plane (a plane would occlude itself by ~2 %, most at grazing views).
       * Points within ~1 degree of the tangent plane therefore never occlude; their
       * cosine weight is ~0. */
      float weight = clamp((frame.ao_distance - dist) * fade, 0.0, 1.0);
      weight = (d > 0.0 && dot(delta, n) > 0.02 * dist + self_height) ? weight : 0.0;
      float c = dot(delta, v) * inv_dist;
      if (side == 0) {
        cos_plus = max(cos_plus, mix(low_plus, c, weight));
      } else {
        cos_minus = max(cos_minus, mix(low_minus, c, weight));
      }
    }
  }
  /* Both horizons are at or above the tangent plane (they start there), so the arcs
   * need no clamping to the hemisphere around the normal. */
  cos_plus = clamp(cos_plus, -1.0, 1.0);
  cos_minus = clamp(cos_minus, -1.0, 1.0);
  float arc_plus = ao_arc(ao_acos(cos_plus), cos_plus, sqrt(1.0 - cos_plus * cos_plus),
                          cos_n, sin_n);
  float arc_minus = ao_arc(-ao_acos(cos_minus), cos_minus,
                           -sqrt(1.0 - cos_minus * cos_minus), cos_n, sin_n);
  float visibility = n_proj_len * 0.25 * (arc_plus + arc_minus);
  /* The same with both horizons on the tangent plane (h = angle_n +- pi/2). */
  float open_sky = n_proj_len * (cos_n + angle_n * sin_n);
  out_ao_sums = vec4(searched ? vec2(visibility, open_sky) : vec2(1.0), depth,
                     ao_pack_normal(n));
}

#else /* AO_BLUR */

/* The blur's weights along each axis: a box of 4 convolved with itself. A box of 4 holds
 * every offset modulo 4 once, so it removes the 4x4 pattern where the AO is even; where
 * the AO changes across the pattern, a box leaves a sawtooth of period 4 (blocks, seen
 * at contacts), which the second box removes. (1 2 2 2 1, a box of 4 with one of 2, left
 * visible blotches on the voxel scenes.) */
#define AO_BLUR_TAPS 7
const float AO_TENT[AO_BLUR_TAPS] = float[AO_BLUR_TAPS](1.0, 2.0, 3.0, 4.0, 3.0, 2.0, 1.0);

/* One axis of the separable blur (AO_BLUR_AXIS 0: rows, then 1: columns), drawn only where
 * the search searched (depth-tested). Elsewhere the targets keep their cleared values:
 * (0, 0, 0) for the rows (nothing, no surface), (1, 0) for the result (open, no surface).
 * Rows: the tent-weighted sums of the visible and open arcs along the row and the pixel's
 * own depth. Columns: the same sums along the column of the rows' sums, their ratio the
 * AO, written with the view depth it stands for, so the lighting pass can bring it to full
 * resolution without bleeding across silhouettes (out_ao_depth: AO, view depth). */
void main()
{
  ivec2 size = ivec2(frame.viewport_size);
  ivec2 h0 = ivec2(gl_FragCoord.xy);
  ivec2 p = min(h0 * 2, size - 1);   /* the full-resolution pixel this one stands for */
  vec4 own = texelFetch(ao_half, h0, 0);
  float depth = own.b;
  vec3 n = ao_unpack_normal(own.a);
  /* A neighbour's distance from the tangent plane, dot(position - center, n), with the
   * position (q * ray_scale + ray_offset) * d, -d (xy not times d in an orthographic view):
   * linear in the neighbour's pixel q, so each tap costs a multiply-add or two. */
  vec2 ray_scale = 2.0 / frame.viewport_size * frame.ao_view_ray.xy;
  vec2 ray_offset = (1.0 / frame.viewport_size - 1.0) * frame.ao_view_ray.xy +
                    frame.ao_view_ray.zw;
  float perspective = frame.is_perspective != 0 ? 1.0 : 0.0;
  /* (q - p) * slope is how much farther along n a point at depth 1 of pixel q lies than
   * one of pixel p; height = d * (along_d + along) + along_1 * along is its distance
   * from the plane through the eye along n, less that of the pixel's own point
   * (perspective: along_d 1, along_1 0; orthographic: along_d 0, along_1 1). */
  vec2 slope = ray_scale * n.xy;
  float along_p = dot(vec2(p), slope) + dot(ray_offset, n.xy);
  float persp_along = perspective * along_p - n.z;
  float ortho_along = (1.0 - perspective) * along_p;
  float center_height = depth * persp_along + ortho_along;
  /* Off the tangent plane by more than this (scene units): another surface. */
  float inv_tolerance = 1.0 / (2.0 * ao_pixel_footprint(depth) + 0.02 * frame.ao_distance);
  ivec2 axis = ivec2(1 - AO_BLUR_AXIS, AO_BLUR_AXIS);
  /* Each tap was searched at full-resolution pixel 2h (the last column or row of an odd
   * size aside, a pixel off: well inside the tolerance), 2 axis further than the last. */
  float along_step = 2.0 * dot(vec2(axis), slope);
  /* A tap's distance from the tangent plane over the tolerance is d * scale + offset,
   * both linear in the tap's offset k: the weight costs a multiply-add per tap. */
  float k0 = float(-(AO_BLUR_TAPS / 2));
  float scale = (persp_along + perspective * k0 * along_step) * inv_tolerance;
  float scale_step = perspective * along_step * inv_tolerance;
  float offset = (ortho_along - center_height + (1.0 - perspective) * k0 * along_step) *
                 inv_tolerance;
  float offset_step = (1.0 - perspective) * along_step * inv_tolerance;
  ivec2 last = textureSize(ao_half, 0) - 1;
  /* Where the distance spans only a few pixels, so does the occlusion (a contact line at
   * a small distance): taps beyond about the distance's screen radius fade out, so the
   * blur does not wash it out. */
  float steps_per_radius = 2.0 / max(ao_radius_px(depth), 1e-3);
  float visible = 0.0;
  float open = 0.0;
  for (int i = 0; i < AO_BLUR_TAPS; i++) {
    vec4 sums = texelFetch(ao_half, clamp(h0 + (i - AO_BLUR_TAPS / 2) * axis, ivec2(0), last),
                           0);
    float d = sums.b;
    /* Background taps (depth 0, also the pixels with nothing searched) count for
     * nothing. */
    float near = clamp(1.5 - float(abs(i - AO_BLUR_TAPS / 2)) * steps_per_radius, 0.0, 1.0);
    float weight = d > 0.0 ? near * AO_TENT[i] * clamp(1.0 - abs(d * scale + offset),
                                                       0.0, 1.0) : 0.0;
    visible += weight * sums.r;
    open += weight * sums.g;
    scale += scale_step;
    offset += offset_step;
  }
#if AO_BLUR_AXIS == 0
  out_ao_sums = vec4(visible, open, depth, own.a);
#else
  /* No open arc at all (a slice with no part of the hemisphere's weight): open. */
  float ao = open > 1e-6 ? visible / open : 1.0;
  out_ao_depth = vec2(clamp(ao, 0.0, 1.0), depth);
#endif
}

#endif
