/* Post-process anti-aliasing (FXAA, after Timothy Lottes' FXAA 3.11 "quality" algorithm):
 * find the edge through each pixel from the luma of its neighbours, walk along it to both
 * ends, and blend the pixel with its neighbour across the edge by how far the pixel is
 * from the edge's middle: long, shallow stair steps become ramps.
 *
 * NOTE: textures made from Python sample with nearest filtering (the gpu module cannot set
 * filtering), so every "half-texel" fetch of the original is written as the mean of two
 * texelFetch()es, and the final blend mixes the two texels by hand.
 * Input is scene-linear colour; luma is taken after a square root (close to the display's
 * sRGB curve), so the thresholds mean what they mean on screen.
 *
 * Four programs come from this file. Without a define, one pass does it all (the
 * viewport). A final render runs three (render/antialiasing.py), with the same result:
 * FXAA_LUMA copies every pixel and writes its luma to a target of its own; FXAA_MARK
 * writes depth 0 where a pixel is on an edge (1 elsewhere); FXAA_BLEND then runs under a
 * depth test that passes only there, and reads the lumas with textureGather, four at a
 * time (cheaper than four texelFetch()es on llvmpipe).
 * NOTE: llvmpipe runs both sides of an `if` for every pixel of a block with one edge pixel,
 * so the one-pass program pays the corners and the edge walk's first step everywhere;
 * pixel blocks that fail an early depth test are not shaded at all. */

const float EDGE_THRESHOLD_MIN = 0.0312;
const float EDGE_THRESHOLD_MAX = 0.125;
const float SUBPIXEL_QUALITY = 0.75;
/* Step lengths (pixels) along the edge: fine near the pixel, coarser further out (edges
 * up to 18 pixels each way). NOTE: 6 steps, not FXAA's 12: on llvmpipe every step is paid
 * by every pixel of a block that has one edge pixel. */
const int EDGE_STEPS = 6;
const float STEP_SIZES[EDGE_STEPS] = float[EDGE_STEPS](1.0, 1.0, 2.0, 2.0, 4.0, 8.0);

ivec2 source_size;

#ifndef FXAA_MARK
vec4 color_at(ivec2 p)
{
  return texelFetch(source, clamp(p, ivec2(0), source_size - 1), 0);
}
#endif

float luma_of(vec4 c)
{
  return sqrt(clamp(dot(c.rgb, vec3(0.2126, 0.7152, 0.0722)), 0.0, 1.0));
}

#if defined(FXAA_MARK) || defined(FXAA_BLEND)
float luma_at(ivec2 p)
{
  return texelFetch(luma, clamp(p, ivec2(0), source_size - 1), 0).r;
}

/* The lumas of the 2x2 texels whose lower-left one is p: x (p.x, p.y + 1), y (p.x + 1,
 * p.y + 1), z (p.x + 1, p.y), w p itself; the sampler clamps to the edge as luma_at does. */
vec4 luma_quad(ivec2 p)
{
  return textureGather(luma, vec2(p + 1) / vec2(source_size), 0);
}

/* The sum of the lumas at q and at q + across (one step across the edge). */
float luma_pair(ivec2 q, ivec2 across, bool horizontal)
{
  vec4 quad = luma_quad(min(q, q + across));
  return horizontal ? quad.w + quad.x : quad.w + quad.z;
}
#else
float luma_at(ivec2 p)
{
  return luma_of(color_at(p));
}

float luma_pair(ivec2 q, ivec2 across, bool horizontal)
{
  return luma_at(q) + luma_at(q + across);
}
#endif

/* Whether the luma around a pixel varies too little for FXAA to touch it. */
bool is_flat(float center, float down, float up, float left, float right, out float range)
{
  float luma_min = min(center, min(min(down, up), min(left, right)));
  float luma_max = max(center, max(max(down, up), max(left, right)));
  range = luma_max - luma_min;
  return range < max(EDGE_THRESHOLD_MIN, luma_max * EDGE_THRESHOLD_MAX);
}

#if defined(FXAA_LUMA)
void main()
{
  vec4 center_color = texelFetch(source, ivec2(gl_FragCoord.xy), 0);
  out_color = center_color;
  out_luma = luma_of(center_color);
}

#elif defined(FXAA_MARK)
void main()
{
  source_size = textureSize(luma, 0);
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec4 lower_left = luma_quad(p - 1);
  vec4 upper_right = luma_quad(p);
  float range;
  bool flat_pixel = is_flat(lower_left.y, lower_left.z, upper_right.x, lower_left.x,
                            upper_right.z, range);
  gl_FragDepth = flat_pixel ? 1.0 : 0.0;
}

#else
void main()
{
  source_size = textureSize(source, 0);
  ivec2 p = ivec2(gl_FragCoord.xy);
  vec4 center_color = color_at(p);
#  ifdef FXAA_BLEND
  vec4 lower_left = luma_quad(p - 1);
  vec4 upper_right = luma_quad(p);
  float center = lower_left.y;
  float down = lower_left.z;
  float up = upper_right.x;
  float left = lower_left.x;
  float right = upper_right.z;
  float down_left = lower_left.w;
  float up_right = upper_right.y;
#  else
  float center = luma_of(center_color);
  float down = luma_at(p + ivec2(0, -1));
  float up = luma_at(p + ivec2(0, 1));
  float left = luma_at(p + ivec2(-1, 0));
  float right = luma_at(p + ivec2(1, 0));
#  endif
  float range;
  if (is_flat(center, down, up, left, right, range)) {
    out_color = center_color;
    return;
  }
#  ifndef FXAA_BLEND
  float down_left = luma_at(p + ivec2(-1, -1));
  float up_right = luma_at(p + ivec2(1, 1));
#  endif
  float up_left = luma_at(p + ivec2(-1, 1));
  float down_right = luma_at(p + ivec2(1, -1));

  float down_up = down + up;
  float left_right = left + right;
  float left_corners = down_left + up_left;
  float down_corners = down_left + down_right;
  float right_corners = down_right + up_right;
  float up_corners = up_right + up_left;
  float edge_horizontal = abs(-2.0 * left + left_corners) + abs(-2.0 * center + down_up) * 2.0 +
                          abs(-2.0 * right + right_corners);
  float edge_vertical = abs(-2.0 * up + up_corners) + abs(-2.0 * center + left_right) * 2.0 +
                        abs(-2.0 * down + down_corners);
  bool horizontal = edge_horizontal >= edge_vertical;

  /* The two neighbours across the edge; step towards the one with the steeper gradient. */
  float luma_1 = horizontal ? down : left;
  float luma_2 = horizontal ? up : right;
  float gradient_1 = luma_1 - center;
  float gradient_2 = luma_2 - center;
  bool steepest_is_1 = abs(gradient_1) >= abs(gradient_2);
  float gradient_scaled = 0.25 * max(abs(gradient_1), abs(gradient_2));
  ivec2 across = horizontal ? ivec2(0, steepest_is_1 ? -1 : 1) :
                              ivec2(steepest_is_1 ? -1 : 1, 0);
  float local_average = 0.5 * ((steepest_is_1 ? luma_1 : luma_2) + center);
  ivec2 along = horizontal ? ivec2(1, 0) : ivec2(0, 1);

  /* Walk both ways along the edge, reading the mean of the two rows it separates, until
   * that mean leaves the local average by a quarter of the gradient: the edge ends. */
  float distance_1 = 0.0, distance_2 = 0.0;
  float end_1 = 0.0, end_2 = 0.0;
  bool done_1 = false, done_2 = false;
  /* NOTE: a loop with a constant trip count is unrolled by the compiler, and llvmpipe then
   * runs every step for every pixel (the rest of an `if` is not skipped); a count the
   * compiler cannot see stays a loop, which ends once no pixel of the group still walks
   * (FXAA on the default scene at 1280x720: ~105 to ~57 ms of CPU). */
  int steps = EDGE_STEPS + min(source_size.x, 0);
  for (int i = 0; i < steps; i++) {
    if (!done_1) {
      distance_1 += STEP_SIZES[min(i, EDGE_STEPS - 1)];
      ivec2 q = p - along * int(distance_1);
      end_1 = 0.5 * luma_pair(q, across, horizontal) - local_average;
      done_1 = abs(end_1) >= gradient_scaled;
    }
    if (!done_2) {
      distance_2 += STEP_SIZES[min(i, EDGE_STEPS - 1)];
      ivec2 q = p + along * int(distance_2);
      end_2 = 0.5 * luma_pair(q, across, horizontal) - local_average;
      done_2 = abs(end_2) >= gradient_scaled;
    }
    if (done_1 && done_2) {
      break;
    }
  }
  /* The walk starts half a pixel from the centre in the original (bilinear) algorithm. */
  distance_1 -= 0.5;
  distance_2 -= 0.5;
  bool nearer_is_1 = distance_1 < distance_2;
  float nearest = min(distance_1, distance_2);
  float edge_length = distance_1 + distance_2;
  float pixel_offset = -nearest / edge_length + 0.5;
  /* Only blend when the luma at the nearer end varies the way the centre does: the pixel
   * is then on the side of the step that the ramp should lift or lower. */
  bool center_smaller = center < local_average;
  bool correct = ((nearer_is_1 ? end_1 : end_2) < 0.0) != center_smaller;
  float final_offset = correct ? pixel_offset : 0.0;

  /* Sub-pixel aliasing (a lone bright pixel): blend by the neighbourhood's contrast. */
  float average = (1.0 / 12.0) * (2.0 * (down_up + left_right) + left_corners + right_corners);
  float subpixel = clamp(abs(average - center) / range, 0.0, 1.0);
  subpixel = (-2.0 * subpixel + 3.0) * subpixel * subpixel;
  final_offset = max(final_offset, subpixel * subpixel * SUBPIXEL_QUALITY);

  out_color = mix(center_color, color_at(p + across), clamp(final_offset, 0.0, 1.0));
}
#endif
