/* Flat-coloured overlays: the frozen cascade boxes (lines) and the cascade legend's
 * panel and swatches (triangles in pixel space). */
void main()
{
  line_color = color;
  gl_Position = clip_from_world * vec4(pos, 1.0);
}
