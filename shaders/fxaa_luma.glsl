/* The luma FXAA finds edges by (fxaa_frag.glsl), and what the lighting pass hands a final
 * render's FXAA (render/antialiasing.py): a copy of each pixel's colour and its luma.
 * Luma is taken after a square root (close to the display's sRGB curve), so FXAA's
 * thresholds mean what they mean on screen. */

float fxaa_luma_of(vec4 c)
{
  return sqrt(clamp(dot(c.rgb, vec3(0.2126, 0.7152, 0.0722)), 0.0, 1.0));
}

#ifdef FXAA_INPUTS
/* Hands FXAA the colour this pixel's out_color holds: a copy (the target FXAA's edge
 * blend then overwrites only on edges) and its luma. NOTE: written by the lighting and
 * background programs themselves, so a final render's FXAA needs no pass that reads every
 * pixel back only to copy it and take its luma; a frame without FXAA leaves these slots
 * unattached, and they cost nothing. */
void write_fxaa_inputs()
{
  out_fxaa_color = out_color;
  out_fxaa_luma = fxaa_luma_of(out_color);
}
#else
void write_fxaa_inputs()
{
}
#endif
