/* One step of a final render's anti-aliasing: the running mean of the jittered samples so
 * far (previous) moves towards this sample (current) by its share of the total weight, so
 * after N samples the target holds their weighted mean without a float sum target. */
void main()
{
  ivec2 p = ivec2(gl_FragCoord.xy);
  out_color = mix(texelFetch(previous, p, 0), texelFetch(current, p, 0), sample_share);
}
