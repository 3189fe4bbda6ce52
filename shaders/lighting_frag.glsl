/* Deferred lighting pass: ambient + sun (with cascaded shadows) + point + spot lights +
 * emission, and every debug view. Writes scene-linear colour (Blender applies the view
 * transform) and an auxiliary target: sun visibility, cascade index, view depth, coverage.
 *
 * One program per Shadow Filter (SHADOW_FILTER), each with twins that have the point-light
 * loop (POINT_LIGHTS), the shadowed point lights (POINT_SHADOWS), the spot-light loop
 * (SPOT_LIGHTS) and the debug views (WITH_DEBUG_VIEWS) (render/shaders.py): llvmpipe pays
 * for code it skips, so a program holds only what its scene uses. Each also has a PASSES
 * twin, for final renders with render passes on: it writes the light and colour passes
 * (render/passes.py lists the targets) besides Combined. */
#include "surface.glsl"
#include "brdf.glsl"
#include "lights.glsl"
#include "world_light.glsl"
#include "ao_upsample.glsl"
#include "shadow_lookup.glsl"
#include "cascade_selection.glsl"
#include "terminator.glsl"
#include "debug_views.glsl"
#include "background.glsl"

#ifdef PASSES
/* What the diffuse and specular layers reflect of every light so far (W/m^2/sr), for the
 * Diffuse and Glossy Light passes. */
vec3 reflected_diffuse = vec3(0.0);
vec3 reflected_specular = vec3(0.0);
#endif

/* The light passes' share of a light whose irradiance on a surface facing it is
 * `irradiance`, from direction l: the same light Combined adds through surface_response,
 * split by layer. Nothing outside PASSES programs. */
void add_to_light_passes(Surface s, vec3 l, vec3 irradiance)
{
#ifdef PASSES
  vec3 diffuse;
  vec3 specular;
  surface_response_split(s, l, diffuse, specular);
  reflected_diffuse += irradiance * diffuse;
  reflected_specular += irradiance * specular;
#endif
}

/* The World's light on surface s, darkened by ambient occlusion (its share of the light
 * reaching s in `visibility`). */
vec3 ambient_light(Surface s, ivec2 px, out float visibility)
{
  /* Each lobe sends back the World's light times its albedo (the split sum of EEVEE, with
   * Cycles' tables): the diffuse colour under the specular layer times the irradiance of
   * the normal, and what the specular lobes reflect for this view times the World seen
   * around the reflected direction. A uniform World of radiance L gives L times each. */
  vec3 color = surface_diffuse_color(s) * world_diffuse_radiance(s.normal) +
               surface_specular_color(s) *
               world_specular_radiance(reflect(-s.to_camera, s.normal), s.roughness);
  /* Ambient occlusion darkens only this term, as in EEVEE (its horizon scan occludes the
   * diffuse and the specular World light alike): direct light has its shadows. */
  visibility = frame.ao_enabled != 0 ?
      mix(1.0, ambient_occlusion_at(px, s.view_depth, s.depth_slope), frame.ao_strength) : 1.0;
  return color * visibility;
}

/* ambient_light in its diffuse and specular parts, for the light passes (the two add up
 * to what ambient_light returns for the same `visibility`). Change both together. */
void ambient_light_split(Surface s, float visibility, out vec3 diffuse, out vec3 specular)
{
  diffuse = surface_diffuse_color(s) * world_diffuse_radiance(s.normal) * visibility;
  specular = surface_specular_color(s) *
             world_specular_radiance(reflect(-s.to_camera, s.normal), s.roughness) *
             visibility;
}

/* Adds the sun's light on surface s to `color`, through its cascaded shadow maps. Returns
 * what the lookups found: the sun's visibility (1 lit, 0 shadowed), the cascade read
 * (fractional inside a blend band, -1 for none) and the first shadow tile read (-1 beyond
 * the last cascade). May turn s.shadow_normal (see terminator_lookup_point). */
void add_sun(inout Surface s, inout vec3 color, out float visibility, out float cascade,
             out int sun_tile)
{
  /* The sun's cascade, and the next one's weight inside a blend band. */
  bool sun_shadowed = frame.has_sun != 0 && frame.sun_casts_shadow != 0;
  vec3 sun_l = normalize(frame.sun_direction);
  float sun_n_dot_l = dot(s.normal, sun_l);
  float next_weight;
  sun_tile = sun_cascade(s.view_depth, next_weight);
  int second_tile = sun_tile + 1;
  /* Cascade Selection: Shadow Map. A finer map than the slice's own may hold the point
   * (a fitted map reaches past its split): read the finest that does, with room for the
   * filter's taps and the normal offset. */
  if (frame.cascade_selection == SELECT_MAP && frame.has_sun != 0 && sun_tile >= 0) {
    sun_tile = sun_cascade_by_map(s.position, sun_tile, shadow_filter_reach_texels(),
                                  second_tile, next_weight);
  }
  cascade = sun_shadowed ? float(sun_tile) : -1.0;
  /* Facing away from the sun: in its own shadow, whatever the map says (and no taps to
   * pay for). */
  float sun_vis = (sun_shadowed && sun_n_dot_l <= 0.0) ? 0.0 : 1.0;
  int sun_lookups = (sun_shadowed && sun_tile >= 0 && sun_n_dot_l > 0.0) ?
                    (next_weight > 0.0 ? 2 : 1) : 0;
#if SHADOW_FILTER == FILTER_EXACT
  /* Exact: the counted shadow volumes, everywhere (no cascades, no shadow distance). */
  sun_lookups = 0;
  if (sun_shadowed && sun_n_dot_l > 0.0) {
    sun_vis = volume_visibility(ivec2(gl_FragCoord.xy));
  }
#endif

  /* NOTE: llvmpipe runs both sides of an `if` for every pixel, but leaves a loop once no
   * pixel of its group needs another pass: in this loop a pixel pays for the next
   * cascade's lookup only where some pixel near it is in a blend band. The loop's test
   * is at the end of its body: a loop whose test comes first runs its body once more,
   * with every pixel masked off, before it leaves (here a second lookup everywhere, a
   * sixth of the pass). */
  float shadow_n_dot_sun = dot(s.shadow_normal, sun_l);
  vec3 p_sun = terminator_lookup_point(s, sun_n_dot_l, shadow_n_dot_sun);
  for (int k = 0; ; k++) {
    ShadowTileData tile = frame.shadow_tiles[max(k == 0 ? sun_tile : second_tile, 0)];
    /* Sun cascades are orthographic: said here as a constant, the compiler drops the
     * perspective code from the lookup (llvmpipe would run it for every pixel). So is
     * their projection's last row, (0, 0, 0, 1) (core/frame_block.py: products of
     * matrices that end in it), and the lookup's w is 1. NOTE: llvmpipe reads the fields
     * of a tile picked per pixel one pixel at a time: each constant is a read less. */
    tile.is_perspective = 0;
    tile.shadow_from_world[0][3] = 0.0;
    tile.shadow_from_world[1][3] = 0.0;
    tile.shadow_from_world[2][3] = 0.0;
    tile.shadow_from_world[3][3] = 1.0;
    float vis = shadow_tile_visibility(tile, p_sun, s.shadow_normal, shadow_n_dot_sun,
                                       frame.sun_tan_half_angle);
    if (k < sun_lookups) {
      sun_vis = k == 0 ? vis : mix(sun_vis, vis, next_weight);
    }
    if (k + 1 >= sun_lookups) {
      break;
    }
  }
  if (sun_lookups > 0) {
    cascade += sun_lookups == 2 ? next_weight * float(second_tile - sun_tile) : 0.0;
    sun_vis = sun_shadow_fade(sun_vis, s.view_depth);
  }
  if (frame.has_sun != 0) {
    color += frame.sun_color * surface_response(s, sun_l) * sun_vis;
    add_to_light_passes(s, sun_l, frame.sun_color * sun_vis);
  }
  visibility = sun_vis;
}

/* Adds point lights first..end-1 (at most MAX_POINT_LIGHTS) to `color`. The shadowed
 * ones (`shadowed`: the first frame.point_shadow_count lights, at most MAX_POINT_SHADOWS)
 * look up their cube map's face; only the programs built with POINT_SHADOWS have that
 * lookup. `shadowed` is a constant at each call, so the compiler keeps one loop per call
 * and no lookup in the unshadowed one. The loop tests at the end of its body (see
 * add_sun): light i contributes only up to the last light, `last`, and a range without
 * lights costs one masked pass, as a loop that tests first does. */
void add_point_light_range(Surface s, int first, int end, const bool shadowed,
                           inout vec3 color)
{
  int last = min(end, shadowed ? MAX_POINT_SHADOWS : MAX_POINT_LIGHTS) - 1;
  for (int i = first; ; i++) {
    PointLightData light = frame.point_lights[min(i, MAX_POINT_LIGHTS - 1)];
    vec3 l;
    float attenuation = point_light_at(light, s.position, l);
    if (attenuation > 0.0 && i <= last) {
      float vis = 1.0;
#ifdef POINT_SHADOWS
      if (shadowed) {
        int tile = min(frame.point_shadow_tiles + 6 * i +
                       cube_face(s.position - light.position), MAX_SHADOW_TILES - 1);
        ShadowTileData face = frame.shadow_tiles[tile];
        /* Cube faces are perspective (core/shadow_plan.py): said as a constant, the
         * compiler drops the orthographic code and its tile reads (see add_sun). */
        face.is_perspective = 1;
        vis = shadow_tile_visibility(face, s.position, s.shadow_normal,
                                     dot(s.shadow_normal, l), light.source_radius);
#if SHADOW_FILTER == FILTER_EXACT
        /* The first shadowed lights have counted volumes (shadow_volume_lookup.glsl). */
        int c = point_volume_channel(i);
        if (c > 0) {
          vis = volume_visibility_in(ivec2(gl_FragCoord.xy), c);
        }
#endif
      }
#endif
      color += light.color * attenuation * vis * surface_response(s, l);
      add_to_light_passes(s, l, light.color * attenuation * vis);
    }
    if (i >= last) {
      break;
    }
  }
}

/* Adds every point light to `color`: the ones with cube-map shadows come first. */
void add_point_lights(Surface s, inout vec3 color)
{
  int first_unshadowed = 0;
#ifdef POINT_SHADOWS
  first_unshadowed = frame.point_shadow_count;
  add_point_light_range(s, 0, first_unshadowed, true, color);
#endif
  add_point_light_range(s, first_unshadowed, frame.point_light_count, false, color);
}

/* Adds every spot light to `color`, each through its own shadow map where it has one. */
void add_spot_lights(Surface s, inout vec3 color)
{
  /* The loop tests at the end of its body (see add_point_light_range). */
  int last = min(frame.spot_light_count, MAX_SPOT_LIGHTS) - 1;
  int shadowed_rank = 0;   /* shadowed spots before this one */
  for (int i = 0; ; i++) {
    SpotLightData spot = frame.spot_lights[min(i, MAX_SPOT_LIGHTS - 1)];
    vec3 l;
    float attenuation = spot_light_at(spot, s.position, l);
    if (attenuation > 0.0 && i <= last) {
      float vis = 1.0;
      if (spot.shadow_tile >= 0) {
        ShadowTileData tile = frame.shadow_tiles[max(spot.shadow_tile, 0)];
        /* A spot light's tile is perspective (core/shadow_plan.py): see
         * add_point_light_range. */
        tile.is_perspective = 1;
        vis = shadow_tile_visibility(tile, s.position, s.shadow_normal,
                                     dot(s.shadow_normal, l), spot.source_radius);
#if SHADOW_FILTER == FILTER_EXACT
        int c = spot_volume_channel(shadowed_rank);
        if (c > 0) {
          vis = volume_visibility_in(ivec2(gl_FragCoord.xy), c);
        }
#endif
      }
      color += spot.color * attenuation * vis * surface_response(s, l);
      add_to_light_passes(s, l, spot.color * attenuation * vis);
    }
    shadowed_rank += spot.shadow_tile >= 0 ? 1 : 0;
    if (i >= last) {
      break;
    }
  }
}

/* The passes of surface s, whose World light reached it by `ambient_visibility` (its AO),
 * the World's share split by ambient_light_split. Nothing outside PASSES programs. */
void write_surface_passes(Surface s, float ambient_visibility)
{
#ifdef PASSES
  vec3 diffuse_color = surface_diffuse_color(s);
  vec3 specular_color = surface_specular_color(s);
  vec3 world_diffuse;
  vec3 world_specular;
  ambient_light_split(s, ambient_visibility, world_diffuse, world_specular);
  /* Laid out as render/passes.py's LIGHTING_PASS_CHANNELS says: AO and Emission in the
   * alpha channels. */
  /* The light each layer reflects, not yet divided by its colour: samples average these
   * (and the colours) linearly, so the Light passes (render/passes.py divides once, at the
   * end) times the averaged colours add up to the averaged Combined. */
  out_diffuse_light = vec4(reflected_diffuse + world_diffuse, ambient_visibility);
  out_specular_light = vec4(reflected_specular + world_specular, s.emission.r);
  out_diffuse_color = vec4(diffuse_color, s.emission.g);
  out_specular_color = vec4(specular_color, s.emission.b);
#endif
}

void main()
{
  vec2 pixel = screen_uv * frame.viewport_size;
  ivec2 px = ivec2(pixel);
#ifdef WITH_DEBUG_VIEWS
  vec3 map_color;
  if (shadow_map_view(pixel, map_color)) {
    out_color = vec4(map_color, 1.0);
    out_aux = vec4(1.0, -1.0, 0.0, 1.0);
    write_no_surface_passes();
    return;
  }
#endif

  vec4 depth_texel = texelFetch(gbuffer_depth, px, 0);
  float depth = gbuffer_view_depth(depth_texel);
  if (depth <= 0.0) {
    write_background();
#ifdef WITH_DEBUG_VIEWS
    if (frame.debug_view == DEBUG_SHADOW_ERROR) {
      /* Black, so the view's surface pixels can be counted (render/shadow_volumes.py). */
      out_color = vec4(0.0, 0.0, 0.0, 1.0);
    }
#endif
    return;
  }

  Surface surface = gbuffer_surface(px, screen_uv, depth_texel, depth);
  float ambient_visibility;
  vec3 color = ambient_light(surface, px, ambient_visibility);
  float sun_visibility;
  float cascade;
  int sun_tile;
  add_sun(surface, color, sun_visibility, cascade, sun_tile);
#ifdef POINT_LIGHTS
  add_point_lights(surface, color);
#endif
#ifdef SPOT_LIGHTS
  add_spot_lights(surface, color);
#endif
  /* Emission (EEVEE's units: radiance added as is): shows in full shadow and without any
   * light, and no light or ambient term scales it. */
  color += surface.emission;

#ifdef WITH_DEBUG_VIEWS
  color = debug_view_color(surface, color, sun_visibility, cascade, sun_tile,
                           ambient_visibility);
#endif
  out_color = vec4(color, 1.0);
  out_aux = vec4(sun_visibility, cascade, surface.view_depth, 1.0);
  write_surface_passes(surface, ambient_visibility);
}
