/* Background pixels, where the G-buffer holds no surface: the World colour (alpha 0 with
 * Film > Transparent) and the auxiliary values lighting_frag.glsl gives them. Drawn with a
 * depth test that passes only there, so the lighting pass need not run on them. The
 * PASSES twin also clears the render passes there, as lighting_frag.glsl does. */
void main()
{
  out_color = vec4(frame.background_color, frame.background_alpha);
  out_aux = vec4(1.0, -1.0, 1e10, 0.0);
#ifdef PASSES
  out_diffuse_light = vec4(0.0, 0.0, 0.0, 1.0);
  out_specular_light = vec4(0.0);
  out_diffuse_color = vec4(0.0);
  out_specular_color = vec4(0.0);
#endif
}
