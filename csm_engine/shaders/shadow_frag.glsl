/* Shadow pass, fragment stage. Depth is written by the rasterizer; only the ALPHA_MASK
 * variant does any work (cut-outs and hashed alpha must not cast solid shadows). The
 * colour target is the atlas's partial-caster mask: 1 where the texel's nearest caster is
 * alpha-hashed (its shadow is the share of texels the filter finds, which PCF Sharpen
 * must not threshold), 0 for opaque and cut-out casters. */
#ifdef ALPHA_MASK
#include "alpha_hash.glsl"
#endif

void main()
{
#ifdef ALPHA_MASK
  float alpha = material.base_color.a;
  if (material.has_base_texture != 0) {
    alpha *= texture(base_color_texture, tex_coord).a;
  }
  bool hashed = material.shadow_alpha_mode == ALPHA_HASHED;
  if (hashed ? alpha <= alpha_hash(gl_FragCoord.xy) : alpha < material.alpha_cutoff) {
    discard;
  }
  out_partial_caster = vec4(hashed ? 1.0 : 0.0);
#else
  out_partial_caster = vec4(0.0);
#endif
}
