void main()
{
  out_color = line_color;
}
