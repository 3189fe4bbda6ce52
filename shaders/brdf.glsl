/* The surface's response to one light (BRDF), in EEVEE's light units: Lambert diffuse and
 * energy-normalized Blinn-Phong specular with Principled BSDF's Specular and Metallic.
 * docs/lighting.md explains the units. */
#include "surface.glsl"

const float PI = 3.14159265358979;
/* Principled BSDF's convention: Specular level 0.5 is a reflectance of 0.04 at normal
 * incidence (glass, plastic), so F0 = 0.08 * level. */
const float F0_PER_SPECULAR_LEVEL = 0.08;

/* Outgoing radiance for an irradiance of one (W/m^2 on a surface facing the light), with
 * Principled's Metallic: a metal has no diffuse part and reflects its base colour,
 * F0 = mix(0.08 * specular, base colour, metallic); blinn_phong below is the dielectric. */
vec3 surface_brdf(vec3 albedo, float metallic, float specular, float shininess, vec3 n,
                  vec3 l, vec3 v)
{
  float n_dot_l = max(dot(n, l), 0.0);
  if (n_dot_l <= 0.0) {
    return vec3(0.0);
  }
  vec3 h = normalize(l + v);
  float exponent = max(shininess, 1.0);
  vec3 f0 = mix(vec3(F0_PER_SPECULAR_LEVEL * specular), albedo, metallic);
  float lobe = (exponent + 8.0) / (8.0 * PI) * pow(max(dot(n, h), 0.0), exponent);
  return (albedo * ((1.0 - metallic) / PI) + f0 * lobe) * n_dot_l;
}

/* Outgoing radiance for an irradiance of one (W/m^2 on a surface facing the light): the
 * BRDF times cos(angle to the light). Units as EEVEE's (docs/lighting.md): diffuse is
 * Lambert, albedo / pi; specular is energy-normalized Blinn-Phong,
 * F0 (n + 8) / (8 pi) (n.h)^n, whose lobe reflects about F0 of the light whatever the
 * exponent, so a white surface never sends back more than it receives. */
vec3 blinn_phong(vec3 albedo, float specular, float shininess, vec3 n, vec3 l, vec3 v)
{
  return surface_brdf(albedo, 0.0, specular, shininess, n, l, v);
}

/* The BRDF's two layers for the render passes (Diffuse and Glossy Light and Color),
 * whose products add up to surface_response. Blender defines the colour passes as what
 * each layer reflects of white light, and the light passes as the rest, so that
 * light x colour summed over the layers gives Combined. */
/* Diffuse Color: the Lambert layer's albedo (a metal has none). */
vec3 surface_diffuse_color(Surface s)
{
  return s.albedo * (1.0 - s.metallic);
}

/* Glossy Color: the specular layer's reflectance at normal incidence (F0). */
vec3 surface_specular_color(Surface s)
{
  return mix(vec3(F0_PER_SPECULAR_LEVEL * s.specular), s.albedo, s.metallic);
}

/* surface_response(s, l) in its diffuse and specular parts (diffuse + specular equals it
 * up to rounding): the same terms as surface_brdf, kept apart. */
void surface_response_split(Surface s, vec3 l, out vec3 diffuse, out vec3 specular)
{
  float n_dot_l = max(dot(s.normal, l), 0.0);
  if (n_dot_l <= 0.0) {
    diffuse = vec3(0.0);
    specular = vec3(0.0);
    return;
  }
  vec3 h = normalize(l + s.to_camera);
  float exponent = max(s.shininess, 1.0);
  float lobe = (exponent + 8.0) / (8.0 * PI) * pow(max(dot(s.normal, h), 0.0), exponent);
  diffuse = surface_diffuse_color(s) * (n_dot_l / PI);
  specular = surface_specular_color(s) * (lobe * n_dot_l);
}
