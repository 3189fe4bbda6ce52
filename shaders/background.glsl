/* What a pixel without a surface holds, in the lighting pass and in the background pass
 * that spares the lighting pass those pixels (render/lighting.py). */

/* The render passes there (PASSES programs only): all zero, AO open; Environment is
 * Combined there (render/passes.py). */
void write_no_surface_passes()
{
#ifdef PASSES
  out_diffuse_light = vec4(0.0, 0.0, 0.0, 1.0);
  out_specular_light = vec4(0.0);
  out_diffuse_color = vec4(0.0);
  out_specular_color = vec4(0.0);
#endif
}

/* The World colour (alpha 0 with Film > Transparent), the auxiliary values of no surface
 * (sun visibility 1, no cascade, a far view depth, no coverage) and the passes' zeros. */
void write_background()
{
  out_color = vec4(frame.background_color, frame.background_alpha);
  out_aux = vec4(1.0, -1.0, 1e10, 0.0);
  write_no_surface_passes();
}
