/* The Exact filter's visibility: the shadow-volume pass's counts at this pixel
 * (render/shadow_volumes.py), one light per channel: the sun's first, then the first
 * three shadowed local lights' (point lights with shadows, then shadowed spots, in order).
 * Above zero the surface is inside a caster's volume. */

/* Visibility (1 lit, 0 shadowed) at pixel px by the counted volumes of channel c. */
float volume_visibility_in(ivec2 px, int c)
{
  return texelFetch(shadow_volume_count, px, 0)[c] > 0.5 ? 0.0 : 1.0;
}

/* The sun's visibility at pixel px by its counted shadow volumes. */
float volume_visibility(ivec2 px)
{
  return volume_visibility_in(px, 0);
}

/* The count channel of a shadowed local light: point light i (a shadowed one), or the
 * spot light that is the rank-th shadowed spot; -1 when it has none (it keeps its map). */
int point_volume_channel(int i)
{
  return i < 3 ? 1 + i : -1;
}

int spot_volume_channel(int rank)
{
  int c = 1 + frame.point_shadow_count + rank;
  return c <= 3 ? c : -1;
}
