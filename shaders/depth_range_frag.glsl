/* One step of the visible depth range reduction (sample-distribution shadow maps): each
 * output pixel takes the nearest and farthest view depth of the 4x4 source pixels it covers,
 * as (nearest, farthest). The first step (GBUFFER_SOURCE) reads the G-buffer's view depth
 * (gbuffer_layout.glsl), where 0 is background (nothing to shadow); later steps read the
 * previous step's pairs. Steps repeat until one pixel holds the whole image's range. */
#ifdef GBUFFER_SOURCE
#include "gbuffer_layout.glsl"
#endif

const float NOTHING = 3.0e38;

void main()
{
  ivec2 size = textureSize(source, 0);
  ivec2 base = ivec2(gl_FragCoord.xy) * 4;
  float nearest = NOTHING;
  float farthest = 0.0;
  for (int y = 0; y < 4; y++) {
    for (int x = 0; x < 4; x++) {
      ivec2 p = base + ivec2(x, y);
      if (p.x >= size.x || p.y >= size.y) {
        continue;
      }
#ifdef GBUFFER_SOURCE
      float depth = gbuffer_view_depth(texelFetch(source, p, 0));
      if (depth > 0.0) {
        nearest = min(nearest, depth);
        farthest = max(farthest, depth);
      }
#else
      vec4 value = texelFetch(source, p, 0);
      nearest = min(nearest, value.r);
      farthest = max(farthest, value.g);
#endif
    }
  }
  out_color = vec4(nearest, farthest, 0.0, 1.0);
}
