/* Shadow pass, fragment stage: only alpha-masked materials do any work (cut-outs must not
 * cast solid shadows). Depth is written by the rasterizer. */
void main()
{
  if (material_params.z > 0.0) {
    float alpha = material_params.y;
    if (material_params.w > 0.5) {
      alpha *= texture(base_color_texture, tex_coord).a;
    }
    if (alpha < material_params.z) {
      discard;
    }
  }
  out_unused = vec4(0.0);
}
