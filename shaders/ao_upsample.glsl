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
#if defined(GPU_ARB_texture_gather) || __VERSION__ >= 400
  /* The four values in two fetches: textureGather reads one channel of the 2x2 texels
   * around a texel corner (x: (0, 1), y: (1, 1), z: (1, 0), w: (0, 0) from base; past
   * the last row or column the texture's edge, as the clamped index below). */
  vec2 corner = vec2(base + 1) / vec2(last + 1);
  vec4 ao = textureGather(ambient_occlusion, corner, 0);
  vec4 ao_depth = textureGather(ambient_occlusion, corner, 1);
  vec4 values[2] = vec4[2](vec4(ao.w, ao_depth.w, ao.z, ao_depth.z),
                           vec4(ao.x, ao_depth.x, ao.y, ao_depth.y));
#endif
  float sum = 0.0;
  float weight_sum = 0.0;
  for (int y = 0; y < 2; y++) {
    for (int x = 0; x < 2; x++) {
      ivec2 h = min(base + ivec2(x, y), last);
#if defined(GPU_ARB_texture_gather) || __VERSION__ >= 400
      vec2 value = x == 0 ? values[y].xy : values[y].zw;
#else
      vec2 value = texelFetch(ambient_occlusion, h, 0).rg;
#endif
      float expected = depth + dot(depth_slope, vec2(h * 2 - px));
      float bilinear = (x == 0 ? 1.0 - f.x : f.x) * (y == 0 ? 1.0 - f.y : f.y);
      float weight = bilinear * clamp(1.0 - abs(value.g - expected) / tolerance, 0.0, 1.0);
      sum += weight * value.r;
      weight_sum += weight;
    }
  }
#if defined(GPU_ARB_texture_gather) || __VERSION__ >= 400
  float nearest = ao.w;
#else
  float nearest = texelFetch(ambient_occlusion, min(base, last), 0).r;
#endif
  return weight_sum > 1e-6 ? sum / weight_sum : nearest;
}
