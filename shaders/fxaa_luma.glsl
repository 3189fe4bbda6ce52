/* The luma FXAA finds edges by (fxaa_frag.glsl), which the lighting pass hands a final
 * render's FXAA (render/antialiasing.py) for each pixel it writes.
 * Luma is taken after a square root (close to the display's sRGB curve), so FXAA's
 * thresholds mean what they mean on screen. */

float fxaa_luma_of(vec4 c)
{
  return sqrt(clamp(dot(c.rgb, vec3(0.2126, 0.7152, 0.0722)), 0.0, 1.0));
}

#ifdef FXAA_INPUTS
/* Hands FXAA the luma of the colour this pixel's out_color holds. NOTE: written by the
 * lighting and background programs themselves, so a final render's FXAA needs no pass of
 * its own that reads every pixel only to take its luma; a frame without FXAA leaves the
 * slot unattached. */
void write_fxaa_inputs()
{
  out_fxaa_luma = fxaa_luma_of(out_color);
}
#else
void write_fxaa_inputs()
{
}
#endif
