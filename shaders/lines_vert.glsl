/* Debug lines (frozen cascade boxes). */
void main()
{
  line_color = color;
  gl_Position = clip_from_world * vec4(pos, 1.0);
}
