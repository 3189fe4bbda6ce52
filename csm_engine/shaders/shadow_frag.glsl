/* Shadow pass, fragment stage. Depth is written by the rasterizer; only the ALPHA_MASK
 * variant does any work (cut-outs must not cast solid shadows). */
void main()
{
#ifdef ALPHA_MASK
  float alpha = material_params.y;
  if (material_params.w > 0.5) {
    alpha *= texture(base_color_texture, tex_coord).a;
  }
  if (alpha < material_params.z) {
    discard;
  }
#endif
  out_unused = vec4(0.0);
}
