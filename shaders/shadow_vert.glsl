/* Shadow pass, vertex stage: depth only, into one tile of the shadow atlas. */
#include "instance_matrix.glsl"

void main()
{
#ifdef INSTANCED
  mat4 clip_from_object = instance_matrix();
#endif
  tex_coord = uv;
  gl_Position = clip_from_object * vec4(pos, 1.0);
}
