/* Deferred lighting pass: ambient + sun (with cascaded shadows) + point + spot lights, and
 * every debug view. Writes scene-linear colour (Blender applies the view transform) and an
 * auxiliary target: sun visibility, cascade index, view depth, coverage. */
#include "common.glsl"

vec3 show_shadow_map(int t, vec2 uv)
{
  ShadowTileData tile = frame.shadow_tiles[t];
  ivec2 p = ivec2(clamp(uv, 0.0, 1.0) * (tile.resolution - 1.0)) + ivec2(tile.atlas_origin);
  float linear = shadow_linear_depth(texelFetch(shadow_atlas, p, 0).r, tile);
  /* From where the scene's bounds begin in this light's depth, so the grey ramp spans the
   * content rather than the (mostly empty) occluder margin. */
  return vec3((linear - tile.display_near) / max(tile.light_far - tile.display_near, 1e-6));
}

/* Where a square shadow-map view sits on screen: full screen (centred square) or inset. */
bool shadow_map_uv(vec2 pixel, out vec2 uv)
{
  vec2 size = frame.viewport_size;
  bool inset = frame.debug_inset != 0;
  float side = inset ? 0.35 * min(size.x, size.y) : min(size.x, size.y);
  vec2 origin = inset ? vec2(8.0) : 0.5 * (size - vec2(side));
  uv = (pixel - origin) / side;
  return all(greaterThanEqual(uv, vec2(0.0))) && all(lessThanEqual(uv, vec2(1.0)));
}

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

#ifdef POINT_LIGHTS
/* A point light's attenuation at p (0 beyond its reach), and the unit direction to it. */
float point_light_at(PointLightData light, vec3 p, out vec3 l)
{
  vec3 to_light = light.position - p;
  float d = length(to_light);
  l = to_light / max(d, 1e-6);
  return distance_falloff(light.falloff, d, light.radius);
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
#endif

/* The AO at full-resolution pixel px, from the four half-resolution values around it (each
 * computed at full-resolution pixel 2h, and holding that pixel's view depth): bilinear
 * weights, times how well each one's depth fits this surface (its depth here plus the
 * screen-space slope; 0 where the slope is unknown), so AO neither bleeds across
 * silhouettes nor blurs a crease away. */
float ambient_occlusion_at(ivec2 px, float depth, vec2 depth_slope)
{
  ivec2 last = textureSize(ambient_occlusion, 0) - 1;
  ivec2 base = px / 2;
  vec2 f = vec2(px - base * 2) * 0.5;
  float tolerance = 0.02 * depth + 2.0 * (abs(depth_slope.x) + abs(depth_slope.y));
  float sum = 0.0;
  float weight_sum = 0.0;
  for (int y = 0; y < 2; y++) {
    for (int x = 0; x < 2; x++) {
      ivec2 h = min(base + ivec2(x, y), last);
      vec2 ao_depth = texelFetch(ambient_occlusion, h, 0).rg;
      float expected = depth + dot(depth_slope, vec2(h * 2 - px));
      float bilinear = (x == 0 ? 1.0 - f.x : f.x) * (y == 0 ? 1.0 - f.y : f.y);
      float weight = bilinear * clamp(1.0 - abs(ao_depth.g - expected) / tolerance, 0.0, 1.0);
      sum += weight * ao_depth.r;
      weight_sum += weight;
    }
  }
  return weight_sum > 1e-6 ? sum / weight_sum : texelFetch(ambient_occlusion, min(base, last), 0).r;
}

/* The smooth-shading terminator (soft-shadows.md): a facet turned from the sun whose
 * shading normal faces it is looked up this many times the parabolic height of the
 * smooth surface over it above its own plane, as Cycles moves its shadow rays onto that
 * surface (Hanika 2021) for objects with a Shadow Terminator Geometry Offset. */
const float TERMINATOR_LIFT = 2.0;

void main()
{
  vec2 pixel = screen_uv * frame.viewport_size;
  ivec2 px = ivec2(pixel);
  vec4 albedo_spec = texelFetch(gbuffer_albedo, px, 0);
  vec4 normal_shine = texelFetch(gbuffer_normal, px, 0);
  float depth = texelFetch(gbuffer_depth, px, 0).r;
  vec4 emission_metallic = texelFetch(gbuffer_emission, px, 0);
  int debug_view = frame.debug_view;
  bool inset = frame.debug_inset != 0;
  int shadow_tile_count = frame.cascade_count + frame.spot_light_count;

#ifdef WITH_DEBUG_VIEWS
  if (debug_view == DEBUG_SHADOW_MAP || inset) {
    vec2 uv;
    int t = clamp(frame.debug_shadow_map, 0, max(shadow_tile_count - 1, 0));
    if (shadow_tile_count > 0 && shadow_map_uv(pixel, uv)) {
      out_color = vec4(show_shadow_map(t, uv), 1.0);
      out_aux = vec4(1.0, -1.0, 0.0, 1.0);
      return;
    }
    if (debug_view == DEBUG_SHADOW_MAP && !inset) {
      out_color = vec4(0.0, 0.0, 0.0, 1.0);
      out_aux = vec4(1.0, -1.0, 0.0, 1.0);
      return;
    }
  }
#endif

  if (depth <= 0.0) {
    /* Background: the World colour; alpha 0 with Film > Transparent. */
    out_color = vec4(frame.background_color, frame.background_alpha);
    out_aux = vec4(1.0, -1.0, 1e10, 0.0);
    return;
  }

  vec3 p = world_position_at(screen_uv, depth);
  vec3 n = normalize(normal_shine.xyz);
  /* The plane the shadow lookup's receiver-plane taps follow: the surface's own facet
   * (the G-buffer's facet target, exact per triangle), because the map holds the
   * geometry's depth, not the shading normal's idea of it (smooth shading and normal maps
   * tilt it). Ground truth, mismatch against Cycles: point_lights 0.18 % with the shading
   * normal only, 0.128 % with a facet from this pass's 2x2 pixel derivatives (wrong where
   * a quad straddles two triangles), 0.124 % with the exact one. */
  vec2 depth_derivatives = vec2(dFdx(depth), dFdy(depth));
  float depth_step = max(abs(depth_derivatives.x), abs(depth_derivatives.y));
  /* View depth change per pixel along this surface; unknown (0) across a depth jump. */
  vec2 depth_slope = depth_step < 0.05 * depth ? depth_derivatives : vec2(0.0);
  /* The triangle's own plane (the G-buffer's facet target), on the shading normal's side;
   * w: the object's Shadow Terminator Geometry Offset. */
  vec4 facet_target = texelFetch(gbuffer_facet, px, 0);
  vec3 facet = facet_target.xyz;
  vec3 shadow_normal = dot(facet, facet) > 0.5 ? normalize(facet) : n;
  float terminator_offset = facet_target.w;
  vec3 albedo = albedo_spec.rgb;
  float specular = albedo_spec.a;
  float shininess = normal_shine.w;
  float metallic = emission_metallic.a;
  vec3 to_camera = frame.is_perspective != 0 ? normalize(frame.camera_position - p) :
                                               -frame.camera_forward;
  float view_depth = depth;

  /* A uniform World of radiance L: irradiance pi * L times the Lambert BRDF albedo / pi. */
  vec3 color = frame.ambient_color * albedo;
  /* Ambient occlusion darkens only this term, as in EEVEE: direct light has its shadows. */
  float ambient_visibility = frame.ao_enabled != 0 ?
      mix(1.0, ambient_occlusion_at(px, depth, depth_slope), frame.ao_strength) : 1.0;
  color *= ambient_visibility;

  /* The sun's cascade, and the next one's weight inside a blend band. */
  bool sun_shadowed = frame.has_sun != 0 && frame.sun_casts_shadow != 0;
  vec3 sun_l = normalize(frame.sun_direction);
  float sun_n_dot_l = dot(n, sun_l);
  float next_weight;
  int sun_tile = sun_cascade(view_depth, next_weight);
  int second_tile = sun_tile + 1;
  /* Cascade Selection: Shadow Map. A finer map than the slice's own may hold the point
   * (a fitted map reaches past its split): read the finest that does, with room for the
   * filter's taps and the normal offset. */
  if (frame.cascade_selection == SELECT_MAP && frame.has_sun != 0 && sun_tile >= 0) {
    sun_tile = sun_cascade_by_map(p, sun_tile, shadow_filter_reach_texels(), second_tile,
                                  next_weight);
  }
  float cascade = sun_shadowed ? float(sun_tile) : -1.0;
  /* Facing away from the sun: in its own shadow, whatever the map says (and no taps to
   * pay for). */
  float sun_vis = (sun_shadowed && sun_n_dot_l <= 0.0) ? 0.0 : 1.0;
  int sun_lookups = (sun_shadowed && sun_tile >= 0 && sun_n_dot_l > 0.0) ?
                    (next_weight > 0.0 ? 2 : 1) : 0;

  /* NOTE: llvmpipe runs both sides of an `if` (and one pass of any loop) for every pixel,
   * but leaves a loop once no pixel of its group needs another pass: in this loop a pixel
   * pays for the next cascade's lookup only where some pixel near it is in a blend band. */
  float shadow_n_dot_sun = dot(shadow_normal, sun_l);
  /* The terminator band: the triangle faces away from the sun, its smooth shading toward
   * it. Without a Geometry Offset the facet shadows itself (a stepped terminator, as in
   * Cycles); with one the lookup rises to about where the smooth surface would be: at an
   * angle theta between shading normal and facet on a surface of curvature kappa (the
   * shading normal's change per unit of length across the pixel), theta^2 / (2 kappa). */
  vec3 p_sun = p;
  vec3 dndx = dFdx(n), dndy = dFdy(n);
  vec3 dpdx = dFdx(p), dpdy = dFdy(p);
  if (shadow_n_dot_sun <= 0.0 && sun_n_dot_l > 0.0 && terminator_offset > 0.0) {
    float kappa = max(length(dndx) / max(length(dpdx), 1e-6),
                      length(dndy) / max(length(dpdy), 1e-6));
    float theta = acos(clamp(dot(n, shadow_normal), -1.0, 1.0));
    p_sun = p + n * (TERMINATOR_LIFT * theta * theta / (2.0 * max(kappa, 1e-4)));
    shadow_normal = n;
    shadow_n_dot_sun = sun_n_dot_l;
  }
  for (int k = 0; k < sun_lookups; k++) {
    ShadowTileData tile = frame.shadow_tiles[k == 0 ? sun_tile : second_tile];
    /* Sun cascades are orthographic: said here as a constant, the compiler drops the
     * perspective code from the lookup (llvmpipe would run it for every pixel). */
    tile.is_perspective = 0;
    float vis = shadow_tile_visibility(tile, p_sun, shadow_normal, shadow_n_dot_sun,
                                       frame.sun_tan_half_angle);
    sun_vis = k == 0 ? vis : mix(sun_vis, vis, next_weight);
  }
  if (sun_lookups > 0) {
    cascade += sun_lookups == 2 ? next_weight * float(second_tile - sun_tile) : 0.0;
    sun_vis = sun_shadow_fade(sun_vis, view_depth);
  }
  if (frame.has_sun != 0) {
    color += frame.sun_color *
             surface_brdf(albedo, metallic, specular, shininess, n, sun_l, to_camera) * sun_vis;
  }

#ifdef POINT_LIGHTS
  /* Only the programs for scenes with point lights have these loops (see SPOT_LIGHTS). */
  int point_count = frame.point_light_count;
  int first_unshadowed = 0;
#  ifdef POINT_SHADOWS
  /* The point lights with cube-map shadows come first; only the programs for scenes with
   * such lights have this loop, so the others pay nothing for it. */
  first_unshadowed = frame.point_shadow_count;
  for (int i = 0; i < MAX_POINT_SHADOWS; i++) {
    if (i >= first_unshadowed) {
      break;
    }
    PointLightData light = frame.point_lights[i];
    vec3 l;
    float attenuation = point_light_at(light, p, l);
    if (attenuation > 0.0) {
      int tile = frame.point_shadow_tiles + 6 * i + cube_face(p - light.position);
      float vis = shadow_tile_visibility(frame.shadow_tiles[tile], p, shadow_normal,
                                         dot(shadow_normal, l), light.source_radius);
      color += light.color * attenuation * vis *
               surface_brdf(albedo, metallic, specular, shininess, n, l, to_camera);
    }
  }
#  endif
  for (int i = first_unshadowed; i < MAX_POINT_LIGHTS; i++) {
    if (i >= point_count) {
      break;
    }
    PointLightData light = frame.point_lights[i];
    vec3 l;
    float attenuation = point_light_at(light, p, l);
    if (attenuation > 0.0) {
      color += light.color * attenuation *
               surface_brdf(albedo, metallic, specular, shininess, n, l, to_camera);
    }
  }
#endif

#ifdef SPOT_LIGHTS
  /* Only the program for scenes with spot lights has this loop: llvmpipe would run one
   * pass of it, shadow lookup included, for every pixel of every scene. */
  int spot_count = frame.spot_light_count;
  for (int i = 0; i < MAX_SPOT_LIGHTS; i++) {
    if (i >= spot_count) {
      break;
    }
    SpotLightData spot = frame.spot_lights[i];
    vec3 to_light = spot.position - p;
    float d = length(to_light);
    vec3 l = to_light / max(d, 1e-6);
    float cone = smoothstep(spot.cos_outer, spot.cos_inner, dot(-l, normalize(spot.direction)));
    float attenuation = distance_falloff(spot.falloff, d, spot.radius) * cone;
    if (attenuation > 0.0) {
      float vis = 1.0;
      if (spot.shadow_tile >= 0) {
        vis = shadow_tile_visibility(frame.shadow_tiles[spot.shadow_tile], p, shadow_normal,
                                     dot(shadow_normal, l), spot.source_radius);
      }
      color += spot.color * attenuation * vis *
               surface_brdf(albedo, metallic, specular, shininess, n, l, to_camera);
    }
  }
#endif

  /* Emission (EEVEE's units: radiance added as is): shows in full shadow and without any
   * light, and no light or ambient term scales it. */
  color += emission_metallic.rgb;

#ifdef WITH_DEBUG_VIEWS
  if (debug_view == DEBUG_CASCADES) {
    /* Hue from the cascade, brightness from the lit image: readable on any albedo (a plain
     * multiply turns green grass under the blue cascade black). */
    float luma = dot(color, vec3(0.2126, 0.7152, 0.0722));
    color = cascade_color(cascade) * (0.15 + 0.85 * min(luma, 1.0));
  }
  else if (debug_view == DEBUG_SHADOW_FACTOR) {
    color = vec3(sun_vis);
  }
  else if (debug_view == DEBUG_TEXEL_DENSITY) {
    int c = sun_tile;
    if (c < 0) {
      color = vec3(0.5);
    }
    else {
      float pixel_world = max(length(dFdx(p)), length(dFdy(p)));
      float texels_per_pixel = pixel_world / max(frame.shadow_tiles[c].texel_world, 1e-9);
      /* log2 scale: 1/8 texel per pixel -> red, 1 -> green, 8 -> blue. */
      color = heat_color(log2(max(texels_per_pixel, 1e-6)) / 6.0 + 0.5) *
              (0.35 + 0.65 * clamp(dot(n, normalize(frame.sun_direction)), 0.0, 1.0));
    }
  }
  else if (debug_view == DEBUG_ALBEDO) {
    color = albedo;
  }
  else if (debug_view == DEBUG_NORMAL) {
    color = n * 0.5 + 0.5;
  }
  else if (debug_view == DEBUG_POSITION) {
    /* Bands 1/20 of the shadow distance wide: readable whatever the scene's scale. */
    color = fract(p * 20.0 / max(frame.shadow_distance, 1e-6));
  }
  else if (debug_view == DEBUG_DEPTH) {
    color = vec3(clamp(view_depth / max(frame.shadow_distance, 1e-6), 0.0, 1.0));
  }
  else if (debug_view == DEBUG_AMBIENT_OCCLUSION) {
    color = vec3(ambient_visibility);
  }
  else if (debug_view == DEBUG_SPECULAR) {
    color = vec3(specular, shininess / 256.0, metallic);
  }

#endif

  out_color = vec4(color, 1.0);
  out_aux = vec4(sun_vis, cascade, view_depth, 1.0);
}
