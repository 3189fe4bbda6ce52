/* Shadow-volume pass, fragment stage: depth-fail counting (Carmack's reverse) without a
 * stencil buffer. Added into a float target (additive blend): +1 for a volume face seen
 * from inside (back-facing), -1 for one seen from outside, only behind the G-buffer's
 * surface at this pixel. A sum above zero: the surface is inside a volume, in shadow. */
/* How much nearer than the G-buffer's surface (a share of its view depth) a volume face
 * may be and still count as behind it: float32 rounding of one surface drawn twice (about
 * 1e-7 of the depth). Wider lets a volume's side that passes just in front of a surface
 * count wrongly: at 1e-4 a distant caster's shadow edge crept a centimetre up a wall
 * 80 m away. */
#include "gbuffer_layout.glsl"

const float VOLUME_DEPTH_TOLERANCE = 1e-5;

void main()
{
  float surface = gbuffer_view_depth(texelFetch(gbuffer_depth, ivec2(gl_FragCoord.xy), 0));
  /* NOTE: a volume's caps lie on its caster's own triangles, where the G-buffer holds the
   * same depth up to rounding: such a face counts as behind (the tolerance), which keeps a
   * lit open surface (its own cap in front, the rest of its prism behind) at zero. */
  if (surface <= 0.0 || volume_depth < surface * (1.0 - VOLUME_DEPTH_TOLERANCE)) {
    discard;
  }
  /* One light per channel (render/shadow_volumes.py); the blend (ADDITIVE_PREMULT) adds
   * all four channels as they are. */
  out_count = (gl_FrontFacing ? -1.0 : 1.0) * channel;
}
