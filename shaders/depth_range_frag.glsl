/* One step of the visible depth range reduction (sample-distribution shadow maps): each
 * output pixel takes the nearest and farthest view depth of the 4x4 source pixels it covers,
 * as (nearest, farthest). The first step (VIEW_DEPTH) reads the G-buffer's view depth (the
 * first channel of its gbuffer_depth target, a plain float: gbuffer_layout.glsl), where 0 is
 * background (nothing to shadow); later steps read the previous step's pairs. Steps repeat
 * until one pixel holds the whole image's range. */
const float NOTHING = 3.0e38;

void main()
{
  ivec2 size = textureSize(source, 0);
  ivec2 base = ivec2(gl_FragCoord.xy) * 4;
#ifdef VIEW_DEPTH
  /* NOTE: four textureGathers (2x2 texels each) rather than 16 texel fetches: on llvmpipe a
   * gather costs about one fetch, and this step reads every pixel of the view. Each gather
   * is centred on a texel corner inside the block; at the view's right or top edge the
   * corner is moved back inside the view, so a block there reads its own texels twice
   * (the same nearest and farthest), except a last block one texel wide, which also reads
   * its neighbour's last texel: its range can only grow, so it still holds its receivers.
   * Background (0) is left out of the nearest, and is never the farthest of a block that
   * shows anything. */
  vec2 texel_size = 1.0 / vec2(size);
  ivec2 last_corner = max(size - 1, ivec2(1));
  vec4 nearest4 = vec4(NOTHING);
  vec4 farthest4 = vec4(0.0);
  for (int y = 1; y < 4; y += 2) {
    for (int x = 1; x < 4; x += 2) {
      ivec2 corner = min(base + ivec2(x, y), last_corner);
      vec4 depths = textureGather(source, vec2(corner) * texel_size, 0);
      nearest4 = min(nearest4, mix(vec4(NOTHING), depths, greaterThan(depths, vec4(0.0))));
      farthest4 = max(farthest4, depths);
    }
  }
  float nearest = min(min(nearest4.x, nearest4.y), min(nearest4.z, nearest4.w));
  float farthest = max(max(farthest4.x, farthest4.y), max(farthest4.z, farthest4.w));
#else
  float nearest = NOTHING;
  float farthest = 0.0;
  for (int y = 0; y < 4; y++) {
    for (int x = 0; x < 4; x++) {
      ivec2 p = base + ivec2(x, y);
      if (p.x >= size.x || p.y >= size.y) {
        continue;
      }
      vec4 value = texelFetch(source, p, 0);
      nearest = min(nearest, value.r);
      farthest = max(farthest, value.g);
    }
  }
#endif
  out_color = vec4(nearest, farthest, 0.0, 1.0);
}
