/* The smooth-shading terminator (docs/soft-shadows.md): where the sun's shadow lookup is
 * taken for a facet turned from the sun whose smooth shading faces it. Cycles moves its
 * shadow rays onto the smooth surface over such a facet (Hanika 2021) for objects with a
 * Shadow Terminator Geometry Offset; this does the same with the lookup point. */
#include "surface.glsl"

/* The lookup rises this many times the parabolic height of the smooth surface over the
 * facet above the facet's own plane. */
const float TERMINATOR_LIFT = 2.0;

/* The point the sun's shadow lookup uses for surface s, whose shading normal makes
 * sun_n_dot_l with the direction to the sun and whose shadow normal makes
 * shadow_n_dot_sun. In the terminator band (the triangle faces away from the sun, its
 * smooth shading toward it) without a Geometry Offset the facet shadows itself (a stepped
 * terminator, as in Cycles); with one the lookup rises to about where the smooth surface
 * would be: at an angle theta between shading normal and facet on a surface of curvature
 * kappa (the shading normal's change per unit of length across the pixel),
 * theta^2 / (2 kappa). There the lookup follows the shading normal: s.shadow_normal and
 * shadow_n_dot_sun become the shading normal's, for the lights looked up after the sun
 * too. */
vec3 terminator_lookup_point(inout Surface s, float sun_n_dot_l, inout float shadow_n_dot_sun)
{
  vec3 p = s.position;
  vec3 n = s.normal;
  vec3 p_sun = p;
  vec3 dndx = dFdx(n), dndy = dFdy(n);
  vec3 dpdx = dFdx(p), dpdy = dFdy(p);
  if (shadow_n_dot_sun <= 0.0 && sun_n_dot_l > 0.0 && s.terminator_offset > 0.0) {
    float kappa = max(length(dndx) / max(length(dpdx), 1e-6),
                      length(dndy) / max(length(dpdy), 1e-6));
    float theta = acos(clamp(dot(n, s.shadow_normal), -1.0, 1.0));
    p_sun = p + n * (TERMINATOR_LIFT * theta * theta / (2.0 * max(kappa, 1e-4)));
    s.shadow_normal = n;
    shadow_n_dot_sun = sun_n_dot_l;
  }
  return p_sun;
}
