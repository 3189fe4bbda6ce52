/* The surface at one pixel as the lighting pass reads it back from the G-buffer (targets
 * written by gbuffer_frag.glsl): world position rebuilt from the view depth, shading and
 * shadow normals, material, and the view depth's slope across the screen; and its response
 * to a light (the Principled BSDF of brdf.glsl, set up once per pixel). The emission and
 * metallic target is read only by programs built with SURFACE_EMISSION, the coat target
 * only by those with SURFACE_COAT (render/lighting.py picks them for frames whose
 * materials write them). */
#include "brdf.glsl"
#include "gbuffer_layout.glsl"

/* One pixel's surface. Positions and distances in scene units, normals unit length. */
struct Surface {
  vec3 position;           /* world position */
  float view_depth;        /* along the camera's forward axis */
  vec2 depth_slope;        /* view depth change per pixel along this surface; 0 across a
                            * depth jump */
  vec3 normal;             /* shading normal (smooth shading, normal maps) */
  vec3 shadow_normal;      /* the plane shadow lookups follow (see gbuffer_surface) */
  float terminator_offset; /* the object's Shadow Terminator Geometry Offset */
  vec3 albedo;             /* base colour */
  float specular;          /* dielectric F0 / 0.08: Specular IOR Level at IOR 1.5 */
  float roughness;         /* Principled Roughness */
  float metallic;
  vec3 coat;               /* Principled Coat weight, roughness, IOR */
  vec3 emission;           /* emitted radiance, W/m^2/sr (under the coat) */
  vec3 to_camera;          /* unit direction to the eye */
  Principled bsdf;         /* the BSDF's view-dependent part (principled_setup) */
};

/* World position of the pixel at this view depth. On the line through the pixel from the
 * near to the far plane, view depth is linear in the line parameter for perspective and
 * orthographic cameras alike, so one mix() finds the point. */
vec3 world_position_at(vec2 uv, float view_depth)
{
  vec2 ndc = uv * 2.0 - 1.0;
  vec4 a = frame.world_from_clip * vec4(ndc, -1.0, 1.0);
  vec4 b = frame.world_from_clip * vec4(ndc, 1.0, 1.0);
  vec3 near_point = a.xyz / a.w;
  vec3 far_point = b.xyz / b.w;
  float near_depth = dot(near_point - frame.camera_position, frame.camera_forward);
  float far_depth = dot(far_point - frame.camera_position, frame.camera_forward);
  return mix(near_point, far_point, (view_depth - near_depth) / (far_depth - near_depth));
}

/* The surface at G-buffer pixel px (screen position uv 0..1), whose gbuffer_depth texel is
 * `depth_texel` (gbuffer_layout.glsl) and view depth `depth` (above 0: not background). */
Surface gbuffer_surface(ivec2 px, vec2 uv, vec4 depth_texel, float depth)
{
  vec4 surface_texel = texelFetch(gbuffer_surface_target, px, 0);
  vec4 albedo_spec = vec4(unpack_halves(surface_texel.x), unpack_halves(surface_texel.y));
  vec2 roughness_offset = unpack_halves(depth_texel.y);
#ifdef SURFACE_EMISSION
  vec4 emission_metallic = texelFetch(gbuffer_emission, px, 0);
#else
  /* No material of this frame emits or is metal: the target holds zeros
   * (render/gbuffer.py), and as constants they take the metal lobe out of the program. */
  vec4 emission_metallic = vec4(0.0);
#endif
  Surface s;
  s.view_depth = depth;
  s.position = world_position_at(uv, depth);
  s.normal = octahedral_unpack(surface_texel.z);
  /* The plane the shadow lookup's receiver-plane taps follow: the surface's own facet
   * (the G-buffer's facet, exact per triangle), because the map holds the
   * geometry's depth, not the shading normal's idea of it (smooth shading and normal maps
   * tilt it). Ground truth, mismatch against Cycles: point_lights 0.18 % with the shading
   * normal only, 0.128 % with a facet from this pass's 2x2 pixel derivatives (wrong where
   * a quad straddles two triangles), 0.124 % with the exact one. */
  vec2 depth_derivatives = vec2(dFdx(depth), dFdy(depth));
  float depth_step = max(abs(depth_derivatives.x), abs(depth_derivatives.y));
  s.depth_slope = depth_step < 0.05 * depth ? depth_derivatives : vec2(0.0);
  /* The triangle's own plane (the G-buffer's facet), on the shading normal's side. */
  s.shadow_normal = octahedral_unpack(surface_texel.w);
  s.terminator_offset = roughness_offset.y;
  s.albedo = albedo_spec.rgb;
  s.specular = albedo_spec.a;
  s.roughness = roughness_offset.x;
  s.metallic = emission_metallic.a;
  s.emission = emission_metallic.rgb;
#ifdef SURFACE_COAT
  s.coat = texelFetch(gbuffer_coat, px, 0).xyz;
#else
  /* No coated material: no coat layer to set up (its table lookups are half of
   * principled_setup's). */
  s.coat = vec3(0.0);
#endif
  s.to_camera = frame.is_perspective != 0 ? normalize(frame.camera_position - s.position) :
                                            -frame.camera_forward;
  s.bsdf = principled_setup(s.albedo, s.metallic, s.specular, s.roughness, s.coat, s.normal,
                            s.to_camera);
  /* Cycles' emission lies under the coat: what the coat reflects does not come through. */
  s.emission *= s.bsdf.coat_transmission;
  return s;
}

/* Radiance of surface s towards the camera for an irradiance of one from direction l,
 * split into its diffuse and specular lobes (diffuse + specular = surface_response). */
void surface_response_split(Surface s, vec3 l, out vec3 diffuse, out vec3 specular)
{
  principled_eval(s.bsdf, s.normal, s.to_camera, l, diffuse, specular);
}

/* Radiance of surface s towards the camera for an irradiance of one from direction l. */
vec3 surface_response(Surface s, vec3 l)
{
  vec3 diffuse;
  vec3 specular;
  surface_response_split(s, l, diffuse, specular);
  return diffuse + specular;
}

/* Blender's Diffuse Color: the albedo of the diffuse lobe (base colour under the specular
 * layer, without the metal's share). */
vec3 surface_diffuse_color(Surface s)
{
  return s.bsdf.diffuse_color;
}

/* Blender's Glossy Color: what the metal and specular lobes reflect of a uniform World. */
vec3 surface_specular_color(Surface s)
{
  return s.bsdf.specular_color;
}
