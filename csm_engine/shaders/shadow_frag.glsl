/* Shadow pass, fragment stage. Depth is written by the rasterizer; only the ALPHA_MASK
 * variant does any work (cut-outs and hashed alpha must not cast solid shadows). */
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
  out_unused = vec4(0.0);
}
