/* G-buffer pass, fragment stage: one material (MaterialData, core/material_layout.py) per
 * draw.
 * out_surface  = base colour rgb; specular: the dielectric layer's F0 / 0.08 (Specular IOR
 *                Level at IOR 1.5); world normal (normal-mapped where the material has a
 *                map); the triangle's own normal (on the shading normal's side), packed as
 *                gbuffer_layout.glsl says
 * out_depth    = view depth along the camera's forward axis (0 = background); roughness and
 *                the object's Shadow Terminator Geometry Offset, packed likewise
 * out_emission = emitted radiance rgb (W/m^2/sr, EEVEE's units), metallic
 * out_coat     = Principled Coat weight, roughness, IOR
 * out_ids      = (CRYPTOMATTE programs only, in out_coat's place: they draw the G-buffer
 *                a second time, render/gbuffer.py) the object's, material's and asset's
 *                Cryptomatte IDs (core/cryptomatte.py), 1 */

#include "alpha_hash.glsl"
#include "gbuffer_layout.glsl"

/* The course's Blinn-Phong exponent -> roughness, the inverse of the Beckmann-style
 * exponent 2 / r^4 - 2. */
float shininess_roughness(float shininess)
{
  return sqrt(sqrt(2.0 / (max(shininess, 0.0) + 2.0)));
}

/* Principled's specular layer: F0 of the IOR scaled by 2 x Specular IOR Level (Cycles'
 * ior_from_F0 clamps it at 0.99), as the G-buffer's F0 / 0.08. */
float specular_value(float ior, float level)
{
  float r = (ior - 1.0) / (ior + 1.0);
  return min(r * r * 2.0 * max(level, 0.0), 0.99) / 0.08;
}

void main()
{
  vec4 base = material.base_color;
#ifndef UNTEXTURED
  if (material.has_base_texture != 0) {
    base *= texture(base_color_texture, tex_coord);
  }
#endif
#ifdef ALPHA_MASK
  /* Only this variant may discard: see shaders.py on early depth tests. CLIP cuts out below
   * the cutoff (Sponza's foliage); HASHED keeps a pixel when alpha beats the hash. */
  /* Each jittered render sample turns the threshold by the golden ratio, so averaged
   * samples blend partial alpha smoothly instead of keeping one dither pattern. */
  float threshold = fract(alpha_hash(gl_FragCoord.xy) + 0.618034 * float(frame.sample_index));
  if (material.alpha_mode == ALPHA_HASHED ? base.a <= threshold
                                          : base.a < material.alpha_cutoff) {
    discard;
  }
#endif
  /* Blender draws faces from both sides; light the side the camera sees. */
  float facing = (gl_FrontFacing != (mirror_sign > 0.0)) ? -1.0 : 1.0;
  vec3 n = normalize(world_normal) * facing;
#ifdef NORMAL_MAP
  if (material.has_normal_texture != 0 && dot(world_tangent.xyz, world_tangent.xyz) > 0.0) {
    /* Blender's Normal Map node (tangent space): T, B = sign * cross(N, T), the map's
     * xyz along T, B, N, then mixed with N by Strength. The side flip of N flips T too;
     * the bitangent keeps its direction (and turns with a mirrored object's winding). */
    vec3 t = world_tangent.xyz * facing;
    vec3 b = world_tangent.w * mirror_sign * cross(n, world_tangent.xyz);
    vec3 mapped = texture(normal_texture, tex_coord).rgb * 2.0 - 1.0;
    vec3 bumped = normalize(mapped.x * t + mapped.y * b + mapped.z * n);
    n = normalize(mix(n, bumped, max(material.normal_strength, 0.0)));
  }
#endif
  float metallic = material.metallic;
  float roughness = material.roughness;
  float level = material.specular_level;
  float specular;
  bool has_surface = material.roughness_channel >= 0 || material.metallic_channel >= 0;
#ifdef UNTEXTURED
  /* UNTEXTURED: the variant for materials without images (roughness_channel and
   * metallic_channel are -1 then). */
  vec4 surface = vec4(0.0);
#else
  vec4 surface = has_surface ? texture(surface_texture, tex_coord) : vec4(0.0);
#endif
  if (has_surface && material.surface_convention == SURFACE_COURSE) {
    /* The course's files: shininess / 256 in green (0.01 where green is 0), specular
     * level in blue; no metal (docs/materials.md). */
    float green = surface[material.roughness_channel];
    roughness = shininess_roughness(green > 0.0 ? 256.0 * green : 0.01);
    specular = specular_value(1.5, surface[material.metallic_channel]);
    metallic = 0.0;
  }
  else {
    if (material.roughness_channel >= 0) {
      roughness = surface[material.roughness_channel];
    }
    if (material.metallic_channel >= 0) {
      metallic = surface[material.metallic_channel];
    }
    specular = specular_value(material.ior, level);
  }
  vec3 emission = material.emission;
#ifndef UNTEXTURED
  if (material.has_emission_texture != 0) {
    emission *= texture(emission_texture, tex_coord).rgb;
  }
#endif
  out_emission = vec4(emission, clamp(metallic, 0.0, 1.0));
#ifndef CRYPTOMATTE
  out_coat = vec4(material.coat_weight, material.coat_roughness, material.coat_ior, 0.0);
#endif
  /* The triangle's own plane: every pixel of a quad (helpers too) interpolates this
   * triangle, so the derivatives are exactly its edges. Turned to the side the shading
   * normal is on. */
  vec3 facet = cross(dFdx(world_position), dFdy(world_position));
  facet = dot(facet, facet) > 1e-30 ? normalize(facet) : n;
  facet = dot(facet, n) < 0.0 ? -facet : facet;
  out_surface = vec4(pack_halves(base.rg), pack_halves(vec2(base.b, specular)),
                     octahedral_pack(n), octahedral_pack(facet));
  out_depth = vec2(max(view_depth, 1e-6),
                   pack_halves(vec2(clamp(roughness, 0.0, 1.0), terminator_offset)));
#ifdef CRYPTOMATTE
  out_ids = vec4(cryptomatte_object, cryptomatte_material, cryptomatte_asset, 1.0);
#endif
}
