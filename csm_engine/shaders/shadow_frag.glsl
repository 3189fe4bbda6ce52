/* Shadow pass, fragment stage. Depth is written by the rasterizer; only the ALPHA_MASK
 * variant does any work (cut-outs and hashed alpha must not cast solid shadows). */
#ifdef ALPHA_MASK
/* Must match alpha_hash in gbuffer_frag.glsl: here one threshold per atlas texel, so a
 * 50% alpha surface fills half of every 8x8 texels and PCF turns that into half a shadow. */
float alpha_hash(vec2 pixel)
{
  ivec2 p = ivec2(floor(pixel)) & 7;
  int x = p.x;
  int xy = p.x ^ p.y;
  int rank = ((xy & 1) << 5) | ((x & 1) << 4) | ((xy & 2) << 2) | ((x & 2) << 1) |
             ((xy & 4) >> 1) | ((x & 4) >> 2);
  return (float(rank) + 0.5) / 64.0;
}
#endif

void main()
{
#ifdef ALPHA_MASK
  float alpha = material.base_color.a;
  if (material.has_base_texture != 0) {
    alpha *= texture(base_color_texture, tex_coord).a;
  }
  if (material.shadow_alpha_mode == ALPHA_HASHED ? alpha <= alpha_hash(gl_FragCoord.xy)
                                                 : alpha < material.alpha_cutoff) {
    discard;
  }
#endif
  out_unused = vec4(0.0);
}
