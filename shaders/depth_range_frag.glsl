/* One step of the visible depth range reduction (sample-distribution shadow maps): each
 * output pixel takes the nearest and farthest view depth of the 4x4 source pixels it covers,
 * as (nearest, farthest). The first step reads the G-buffer's view depth, where 0 is
 * background (nothing to shadow); later steps read the previous step's pairs. Steps repeat
 * until one pixel holds the whole image's range. */
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
      vec4 value = texelFetch(source, p, 0);
      if (source_is_view_depth != 0) {
        if (value.r > 0.0) {
          nearest = min(nearest, value.r);
          farthest = max(farthest, value.r);
        }
      }
      else {
        nearest = min(nearest, value.r);
        farthest = max(farthest, value.g);
      }
    }
  }
  out_color = vec4(nearest, farthest, 0.0, 1.0);
}
