/* One triangle covering the screen; screen_uv runs 0..1 across the viewport. It lies on
 * the far plane (window depth 1), so a depth test against the G-buffer's depth can tell
 * surfaces (nearer) from the background (still at the cleared 1); see Pipeline.draw. */
void main()
{
  screen_uv = pos * 0.5 + 0.5;
  gl_Position = vec4(pos, 1.0, 1.0);
}
