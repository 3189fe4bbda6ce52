/* Background pixels, where the G-buffer holds no surface (background.glsl). Drawn with a
 * depth test that passes only there, so the lighting pass need not run on them. */
#include "background.glsl"

void main()
{
  write_background();
}
