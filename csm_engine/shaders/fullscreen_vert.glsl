/* One triangle covering the screen; screen_uv runs 0..1 across the viewport. */
void main()
{
  screen_uv = pos * 0.5 + 0.5;
  gl_Position = vec4(pos, 0.0, 1.0);
}
