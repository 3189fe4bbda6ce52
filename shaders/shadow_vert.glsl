/* Shadow pass, vertex stage: depth only, into one tile of the shadow atlas. */
void main()
{
  tex_coord = uv;
  gl_Position = clip_from_object * vec4(pos, 1.0);
}
