/* Bringing the half-resolution ambient occlusion (ao_frag.glsl) to a full-resolution pixel
 * of the lighting pass, without bleeding across silhouettes. */

/* The AO at full-resolution pixel px, from the four half-resolution values around it (each
 * computed at full-resolution pixel 2h, and holding that pixel's view depth): bilinear
 * weights, times how well each one's depth fits this surface (its depth here plus the
 * screen-space slope; 0 where the slope is unknown), so AO neither bleeds across
 * silhouettes nor blurs a crease away. */
float ambient_occlusion_at(ivec2 px, float depth, vec2 depth_slope)
{
  ivec2 last = textureSize(ambient_occlusion, 0) - 1;
  ivec2 base = px / 2;
  vec2 f = vec2(px - base * 2) * 0.5;
  float tolerance = 0.02 * depth + 2.0 * (abs(depth_slope.x) + abs(depth_slope.y));
  float sum = 0.0;
  float weight_sum = 0.0;
  for (int y = 0; y < 2; y++) {
    for (int x = 0; x < 2; x++) {
      ivec2 h = min(base + ivec2(x, y), last);
      vec2 ao_depth = texelFetch(ambient_occlusion, h, 0).rg;
      float expected = depth + dot(depth_slope, vec2(h * 2 - px));
      float bilinear = (x == 0 ? 1.0 - f.x : f.x) * (y == 0 ? 1.0 - f.y : f.y);
      float weight = bilinear * clamp(1.0 - abs(ao_depth.g - expected) / tolerance, 0.0, 1.0);
      sum += weight * ao_depth.r;
      weight_sum += weight;
    }
  }
  return weight_sum > 1e-6 ? sum / weight_sum : texelFetch(ambient_occlusion, min(base, last), 0).r;
}
