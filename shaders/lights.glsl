/* Where a point or spot light's light reaches: distance falloff (EEVEE's inverse square cut
 * off at the light's influence radius, or the course's linear falloff), a spot light's
 * cone, the direction to the light, and which face of a point light's shadow cube a
 * direction falls in. Distances in scene units. */

/* How a point or spot light's colour (see PointLightData) reaches distance d. */
float distance_falloff(int falloff, float d, float radius)
{
  if (falloff == FALLOFF_LINEAR_RADIUS) {
    /* The course's falloff: linear to zero at the light's radius. */
    return 1.0 - min(d / max(radius, 1e-6), 1.0);
  }
  /* Inverse square, cut off smoothly at the influence radius as EEVEE does
   * (light_influence_attenuation, after Frostbite). NOTE: d^2 is kept above 1 cm^2, where
   * EEVEE's light would be a sphere of finite radiance, not a point. */
  float x = d * d / max(radius * radius, 1e-12);
  float window = clamp(1.0 - x * x, 0.0, 1.0);
  return window * window / max(d * d, 1e-4);
}

/* A point light's attenuation at p (0 beyond its reach), and the unit direction to it. */
float point_light_at(PointLightData light, vec3 p, out vec3 l)
{
  vec3 to_light = light.position - p;
  float d = length(to_light);
  l = to_light / max(d, 1e-6);
  return distance_falloff(light.falloff, d, light.radius);
}

/* A spot light's attenuation at p: its distance falloff times its cone (smooth from the
 * cone's edge to its Spot Blend), and the unit direction to it. */
float spot_light_at(SpotLightData spot, vec3 p, out vec3 l)
{
  vec3 to_light = spot.position - p;
  float d = length(to_light);
  l = to_light / max(d, 1e-6);
  float cone = smoothstep(spot.cos_outer, spot.cos_inner, dot(-l, normalize(spot.direction)));
  return distance_falloff(spot.falloff, d, spot.radius) * cone;
}

/* The cube face (+x, -x, +y, -y, +z, -z: cascades.POINT_LIGHT_FACES) a direction from a
 * point light lies in: its largest axis. */
int cube_face(vec3 away)
{
  vec3 size = abs(away);
  if (size.x >= size.y && size.x >= size.z) {
    return away.x >= 0.0 ? 0 : 1;
  }
  return size.y >= size.z ? (away.y >= 0.0 ? 2 : 3) : (away.z >= 0.0 ? 4 : 5);
}
