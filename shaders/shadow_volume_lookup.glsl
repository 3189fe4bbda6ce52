/* The Exact filter's sun visibility: the shadow-volume pass's count at this pixel
 * (render/shadow_volumes.py); above zero the surface is inside a caster's volume. */

/* Sun visibility at pixel px (1 lit, 0 shadowed) by the counted shadow volumes. */
float volume_visibility(ivec2 px)
{
  return texelFetch(shadow_volume_count, px, 0).r > 0.5 ? 0.0 : 1.0;
}
