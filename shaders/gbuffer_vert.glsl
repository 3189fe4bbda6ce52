/* G-buffer pass, vertex stage: world normal (and tangent), UV and view depth per corner. */
#include "instance_matrix.glsl"

void main()
{
#ifdef INSTANCED
  mat4 world_from_object = instance_matrix();
#endif
  vec4 world = world_from_object * vec4(pos, 1.0);
  /* Inverse transpose keeps normals perpendicular under non-uniform scale (pillars are
   * scaled (1,3,1) in the course's shadow test). */
  world_normal = transpose(inverse(mat3(world_from_object))) * nor;
  /* A mirrored object (negative scale) turns its triangles' winding around, so
   * gl_FrontFacing says "back" for the faces the camera sees; the fragment stage undoes it. */
  mirror_sign = determinant(mat3(world_from_object)) < 0.0 ? -1.0 : 1.0;
#ifdef NORMAL_MAP
  /* A tangent lies in the surface like an edge does, so it moves with the matrix itself
   * (not its inverse transpose); w is the bitangent's sign (MikkTSpace). */
  world_tangent = vec4(mat3(world_from_object) * tan.xyz, tan.w);
#endif
  tex_coord = uv;
  world_position = world.xyz;
  /* Linear in the world position, so interpolation gives the exact per-pixel value; the
   * lighting pass rebuilds the world position from it (4 bytes a pixel instead of 16). */
  view_depth = dot(world.xyz - frame.camera_position, frame.camera_forward);
  gl_Position = frame.clip_from_world * world;
}
