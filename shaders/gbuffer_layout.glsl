/* The G-buffer's packed layout (render/gbuffer.py): written by gbuffer_frag.glsl, read by
 * every pass that reads the G-buffer (lighting through surface.glsl, AO, shadow volumes,
 * the depth range reduction).
 * gbuffer_surface_target (RGBA32UI): x = half floats (base colour r, g), y = half floats
 *   (base colour b, specular), z = shading normal, w = the triangle's own normal (facet),
 *   both octahedral in two 16-bit snorms
 * gbuffer_depth (RG32UI): x = view depth's float bits (0 = background), y = half floats
 *   (roughness, the object's Shadow Terminator Geometry Offset)
 * Two targets instead of four: llvmpipe pays per colour target a fragment writes.
 * NOTE: an octahedral 2 x snorm16 normal is off by at most ~6e-5 rad, finer than the three
 * half floats it replaces (up to ~5e-4 per component). */

/* Unit vector n as a point of the octahedron unfolded onto the square -1..1. */
uint octahedral_pack(vec3 n)
{
  vec2 p = n.xy / (abs(n.x) + abs(n.y) + abs(n.z));
  if (n.z < 0.0) {
    p = (1.0 - abs(p.yx)) * vec2(p.x >= 0.0 ? 1.0 : -1.0, p.y >= 0.0 ? 1.0 : -1.0);
  }
  return packSnorm2x16(p);
}

/* The unit vector octahedral_pack packed. */
vec3 octahedral_unpack(uint code)
{
  vec2 p = unpackSnorm2x16(code);
  vec3 n = vec3(p, 1.0 - abs(p.x) - abs(p.y));
  float fold = max(-n.z, 0.0);
  n.xy += vec2(n.x >= 0.0 ? -fold : fold, n.y >= 0.0 ? -fold : fold);
  return normalize(n);
}

/* The view depth a gbuffer_depth texel holds (0 = background). */
float gbuffer_view_depth(uvec4 texel)
{
  return uintBitsToFloat(texel.x);
}
