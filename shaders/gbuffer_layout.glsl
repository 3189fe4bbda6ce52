/* The G-buffer's packed layout (render/gbuffer.py): written by gbuffer_frag.glsl, read by
 * every pass that reads the G-buffer (lighting through surface.glsl, AO, shadow volumes,
 * the depth range reduction, the normals' read-back).
 * gbuffer_surface_target (RGBA32F holding bits): x = half floats (base colour r, g), y =
 *   half floats (base colour b, specular), z = shading normal, w = the triangle's own
 *   normal (facet), both octahedral (two 15-bit coordinates)
 * gbuffer_depth (RG32F): x = view depth (0 = background), y = half floats (roughness, the
 *   object's Shadow Terminator Geometry Offset) as bits
 * Two targets instead of four: llvmpipe pays per colour target a fragment writes.
 * NOTE: float targets hold the bits, not integer ones: Blender 3.4 samples textures bound
 * from Python with linear filtering, which leaves an integer texture incomplete (reads as
 * zeros). No packing here makes a NaN's or an infinity's bits (a finite half float's
 * exponent is never all ones), and nothing does arithmetic on them before they are
 * unpacked.
 * NOTE: an octahedral normal in two 15-bit coordinates is off by at most ~1e-4, finer
 * than the three half floats it replaces (up to ~5e-4 per component). */

/* Two half floats as one float's bits. */
float pack_halves(vec2 v)
{
  return uintBitsToFloat(packHalf2x16(v));
}

/* The two half floats pack_halves packed. */
vec2 unpack_halves(float code)
{
  return unpackHalf2x16(floatBitsToUint(code));
}

/* Octahedral coordinates (-1..1) are stored in 0..OCTAHEDRAL_STEPS, two to a float's bits:
 * the top 16 bits stay below 0x7F80, so the float is never an infinity or a NaN. Even, so
 * that -1, 0 and 1 are exact (axis-aligned normals stay exact). */
#define OCTAHEDRAL_STEPS 32638.0

/* Unit vector n as a point of the octahedron unfolded onto the square -1..1. */
float octahedral_pack(vec3 n)
{
  vec2 p = n.xy / (abs(n.x) + abs(n.y) + abs(n.z));
  if (n.z < 0.0) {
    p = (1.0 - abs(p.yx)) * vec2(p.x >= 0.0 ? 1.0 : -1.0, p.y >= 0.0 ? 1.0 : -1.0);
  }
  uvec2 q = uvec2(round(clamp(p * 0.5 + 0.5, 0.0, 1.0) * OCTAHEDRAL_STEPS));
  return uintBitsToFloat(q.x | (q.y << 16u));
}

/* The unit vector octahedral_pack packed. */
vec3 octahedral_unpack(float code)
{
  uint bits = floatBitsToUint(code);
  vec2 p = vec2(uvec2(bits & 0xFFFFu, bits >> 16u)) * (2.0 / OCTAHEDRAL_STEPS) - 1.0;
  vec3 n = vec3(p, 1.0 - abs(p.x) - abs(p.y));
  float fold = max(-n.z, 0.0);
  n.xy += vec2(n.x >= 0.0 ? -fold : fold, n.y >= 0.0 ? -fold : fold);
  return normalize(n);
}

/* The view depth a gbuffer_depth texel holds (0 = background). */
float gbuffer_view_depth(vec4 texel)
{
  return texel.x;
}
