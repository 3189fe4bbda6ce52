/* G-buffer pass, vertex stage: world position, world normal and UV for each corner. */
void main()
{
  vec4 world = world_from_object * vec4(pos, 1.0);
  world_position = world.xyz;
  /* Inverse transpose keeps normals perpendicular under non-uniform scale (pillars are
   * scaled (1,3,1) in the course's shadow test). */
  world_normal = transpose(inverse(mat3(world_from_object))) * nor;
  tex_coord = uv;
  gl_Position = frame.clip_from_world * world;
}
