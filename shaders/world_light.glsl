/* The World's light on a surface from its spherical harmonics (frame.world_sh, up to band
 * 2, core/world_light.py): the irradiance per normal for the diffuse lobe, and the radiance
 * around the reflected direction, blurred by roughness, for the specular lobes. A uniform
 * World gives its radiance L in both, whatever the direction: programs built without
 * WORLD_ENVIRONMENT (render/lighting.py: frames whose World is one colour) return it
 * without evaluating the harmonics, whose higher bands are zero then. */

#ifndef WORLD_ENVIRONMENT
/* The uniform World's radiance: band 0 of world_sh_sum, the sum's only term that is not
 * zero for it. */
vec3 world_uniform_radiance()
{
  return max(0.282095 * frame.world_sh[0].rgb, vec3(0.0));
}

vec3 world_diffuse_radiance(vec3 n)
{
  return world_uniform_radiance();
}

vec3 world_specular_radiance(vec3 r, float roughness)
{
  return world_uniform_radiance();
}
#else

/* sum of band-weighted coefficients times the harmonics at unit direction d */
vec3 world_sh_sum(vec3 d, vec3 band_weights)
{
  vec3 result = band_weights.x * 0.282095 * frame.world_sh[0].rgb;
  result += band_weights.y * 0.488603 *
            (frame.world_sh[1].rgb * d.y + frame.world_sh[2].rgb * d.z +
             frame.world_sh[3].rgb * d.x);
  result += band_weights.z *
            (1.092548 * (frame.world_sh[4].rgb * (d.x * d.y) +
                         frame.world_sh[5].rgb * (d.y * d.z) +
                         frame.world_sh[7].rgb * (d.x * d.z)) +
             0.315392 * frame.world_sh[6].rgb * (3.0 * d.z * d.z - 1.0) +
             0.546274 * frame.world_sh[8].rgb * (d.x * d.x - d.y * d.y));
  return max(result, vec3(0.0));
}

/* The World's irradiance on a surface of normal n, over pi: the radiance a white Lambert
 * surface sends back (clamped-cosine band weights pi, 2pi/3, pi/4, over pi). */
vec3 world_diffuse_radiance(vec3 n)
{
  return world_sh_sum(n, vec3(1.0, 2.0 / 3.0, 0.25));
}

/* The World's radiance seen in a glossy reflection along r: the harmonics blurred by a
 * Phong lobe of the exponent matching the roughness (band l weighted exp(-l^2 / 2n)). */
vec3 world_specular_radiance(vec3 r, float roughness)
{
  float alpha2 = max(pow(clamp(roughness, 0.0, 1.0), 4.0), 1e-4);
  float exponent = max(2.0 / alpha2 - 2.0, 1e-3);
  return world_sh_sum(r, vec3(1.0, exp(-0.5 / exponent), exp(-2.0 / exponent)));
}
#endif
