/* Shadow pass, fragment stage. Depth is written by the rasterizer; only the ALPHA_MASK
 * variant does any work (cut-outs and hashed alpha must not cast solid shadows).
 * PARTIAL_CASTER: the pass that marks the atlas's partial-caster mask, drawn after a tile's
 * depth with the depth test on and depth writes off: an alpha-hashed caster marks every
 * texel where it is the nearest surface or lies in front of what its discarded fragments
 * let through (its whole footprint, not only its stipple), so one mask read at the
 * pixel's texel tells the filter that the shadow there is a share of texels that PCF
 * Sharpen must not threshold. */
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
  if (material.shadow_alpha_mode == ALPHA_HASHED ? alpha <= alpha_hash(gl_FragCoord.xy)
                                                 : alpha < material.alpha_cutoff) {
    discard;
  }
#endif
#ifdef PARTIAL_CASTER
  out_partial_caster = vec4(1.0);
#else
  out_partial_caster = vec4(0.0);
#endif
}
