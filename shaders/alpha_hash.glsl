/* Hashed alpha's threshold, shared by the G-buffer and the shadow pass (both include this
 * file, so the two can never disagree).
 *
 * A stable per-pixel threshold in 0..1: the 8x8 ordered-dither (Bayer) rank of the pixel,
 * so alpha a keeps a of every 8x8 block of pixels (in 1/64 steps), evenly spread, and it
 * does not crawl while nothing moves. In the shadow pass the "pixel" is an atlas texel, so
 * a 50% alpha surface fills half of every 8x8 texels and PCF turns that into half a
 * shadow. */
float alpha_hash(vec2 pixel)
{
  ivec2 p = ivec2(floor(pixel)) & 7;
  int x = p.x;
  int xy = p.x ^ p.y;
  int rank = ((xy & 1) << 5) | ((x & 1) << 4) | ((xy & 2) << 2) | ((x & 2) << 1) |
             ((xy & 4) >> 1) | ((x & 4) >> 2);
  return (float(rank) + 0.5) / 64.0;
}
