/* Screen-space ambient occlusion: two programs from this one file.
 *
 * "ao" (half resolution): a GTAO-style horizon search (Jimenez et al. 2016, "Practical
 * Real-Time Strategies for Accurate Indirect Occlusion"). For AO_SLICES screen directions
 * per pixel it walks the depth buffer both ways, keeps the highest horizon on each side
 * within frame.ao_distance, and integrates the cosine-weighted visible arc between the two
 * horizons analytically. Averaged over all directions this is the fraction of the
 * cosine-weighted hemisphere not occluded within the distance, the quantity Cycles' AO
 * pass estimates by ray casting (1 = open sky, 0 = fully occluded). Each half-resolution
 * pixel takes its rotation from a 4x4 pattern, so a 4x4 neighbourhood sees 16 rotations.
 *
 * "ao_blur" (AO_BLUR defined; half resolution too): a 4x4 depth-aware mean of the search's
 * result, which removes its 4x4 pattern. A neighbour counts only when its surface point
 * lies on the pixel's tangent plane (within a few pixel footprints), so occlusion does not
 * bleed across silhouettes and a grazing plane still blurs along itself. The lighting pass
 * brings it to full resolution (ambient_occlusion_at in ao_upsample.glsl).
 *
 * NOTE: the blur runs at half resolution because at full resolution its 16 neighbours
 * for each of 4x as many pixels made it the larger half of the AO's cost on llvmpipe.
 *
 * Inputs: the G-buffer's view depth (0 = background) and world normal. Both programs
 * write (AO, the view depth of the full-resolution pixel the value stands for), so the
 * blur and the lighting pass read one texel where they would read two. */

#define AO_PI 3.14159265358979
#define AO_HALF_PI 1.57079632679490
#define AO_SLICES 2
#define AO_STEPS 8             /* per side of a slice */
#define AO_MAX_RADIUS 256.0    /* pixels: a nearby occluder farther on screen is missed */

/* View-space position (camera looks along -Z) of full-resolution pixel p at view depth d. */
vec3 ao_view_position(ivec2 p, float d)
{
  vec2 ndc = (vec2(p) + 0.5) / frame.viewport_size * 2.0 - 1.0;
  vec2 xy = ndc * frame.ao_view_ray.xy + frame.ao_view_ray.zw;
  return vec3(frame.is_perspective != 0 ? xy * d : xy, -d);
}

/* One full-resolution pixel covers this many scene units at view depth d. */
float ao_pixel_footprint(float d)
{
  return (frame.is_perspective != 0 ? d : 1.0) / frame.ao_pixels_per_unit;
}

#ifndef AO_BLUR

/* 4x4 ordered-dither index 0..15: neighbouring pixels get far-apart rotations. */
float ao_bayer4(ivec2 p)
{
  ivec2 q = p & 3;
  int b = ((q.x ^ q.y) & 1) * 8 + (q.y & 1) * 4 + (((q.x ^ q.y) >> 1) & 1) * 2 +
          ((q.y >> 1) & 1);
  return float(b);
}

/* The cosine of the highest horizon seen walking from p along dir (full-res pixels),
 * starting from the tangent plane's horizon low_cos. */
float ao_horizon(ivec2 p, vec3 center, vec3 n, vec3 v, vec2 dir, float radius_px,
                 float jitter, float low_cos)
{
  ivec2 size = ivec2(frame.viewport_size);
  float horizon_cos = low_cos;
  for (int k = 0; k < AO_STEPS; k++) {
    /* Even spacing: the highest horizon within the distance is often near its end (a
     * wall's points at exactly the distance), so the far steps matter as much as the near. */
    float s = (float(k) + jitter) / float(AO_STEPS);
    float t = max(s * radius_px, 1.5 + float(k));
    if (t > radius_px + 1.5) {
      break;
    }
    ivec2 q = p + ivec2(round(dir * t));
    if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) {
      break;
    }
    float d = texelFetch(gbuffer_depth, q, 0).r;
    if (d <= 0.0) {
      continue;   /* background occludes nothing */
    }
    vec3 delta = ao_view_position(q, d) - center;
    float dist = length(delta);
    /* NOTE: a sample is the centre of the pixel nearest the step, a little off the slice
     * plane; on a flat surface that alone reads as a horizon just above the tangent plane
     * (a plane would occlude itself by ~2 %, most at grazing views). Points within ~1
     * degree of the tangent plane therefore never occlude; their cosine weight is ~0. */
    if (dot(delta, n) <= 0.02 * dist) {
      continue;
    }
    /* Cycles counts a hit within the distance only; the last 5 % fades, so the border of
     * the occluded band does not band with the step pattern. */
    float weight = clamp((frame.ao_distance - dist) / (0.05 * frame.ao_distance), 0.0, 1.0);
    horizon_cos = max(horizon_cos, mix(low_cos, dot(delta, v) / dist, weight));
  }
  return horizon_cos;
}

void main()
{
  ivec2 size = ivec2(frame.viewport_size);
  ivec2 ao_pixel = ivec2(gl_FragCoord.xy);
  ivec2 p = min(ao_pixel * 2, size - 1);
  float depth = texelFetch(gbuffer_depth, p, 0).r;
  if (depth <= 0.0) {
    out_ao_depth = vec2(1.0, 0.0);
    return;
  }
  float radius_px = frame.ao_distance / ao_pixel_footprint(depth);
  if (radius_px < 1.5) {
    out_ao_depth = vec2(1.0, depth);   /* everything within the distance is inside this pixel */
    return;
  }
  radius_px = min(radius_px, AO_MAX_RADIUS);
  vec3 center = ao_view_position(p, depth);
  vec3 n = normalize(mat3(frame.view_from_world) * texelFetch(gbuffer_normal, p, 0).xyz);
  vec3 v = frame.is_perspective != 0 ? normalize(-center) : vec3(0.0, 0.0, 1.0);

  float rotation = (ao_bayer4(ao_pixel) + 0.5) / 16.0;
  /* Interleaved gradient noise (Jimenez 2014) for the step offsets, independent of the
   * rotation pattern. */
  float jitter = fract(52.9829189 * fract(dot(vec2(ao_pixel), vec2(0.06711056, 0.00583715))));

  /* Each slice's visible arc is divided by its arc with nothing above the tangent plane
   * (its share of the cosine-weighted hemisphere), so a pixel with nothing nearby is
   * exactly 1 whatever its few slice directions; averaged over many slices the two agree. */
  float visibility = 0.0;
  float open_sky = 0.0;
  for (int slice = 0; slice < AO_SLICES; slice++) {
    float phi = (float(slice) + rotation) * AO_PI / float(AO_SLICES);
    vec2 dir = vec2(cos(phi), sin(phi));
    /* With square pixels, a screen direction is the same direction in view space, and the
     * plane through the eye, the pixel and that direction is the slice. */
    vec3 dir_v = vec3(dir, 0.0);
    vec3 ortho = dir_v - dot(dir_v, v) * v;
    vec3 axis = normalize(cross(ortho, v));
    vec3 n_proj = n - axis * dot(n, axis);
    float n_proj_len = length(n_proj);
    if (n_proj_len < 1e-6) {
      continue;   /* the slice holds no part of the hemisphere's weight */
    }
    float cos_n = clamp(dot(n_proj, v) / n_proj_len, 0.0, 1.0);
    float angle_n = (dot(ortho, n_proj) < 0.0 ? -1.0 : 1.0) * acos(cos_n);
    float cos_plus = ao_horizon(p, center, n, v, dir, radius_px, jitter,
                                cos(angle_n + AO_HALF_PI));
    float cos_minus = ao_horizon(p, center, n, v, -dir, radius_px, jitter,
                                 cos(angle_n - AO_HALF_PI));
    float h_plus = acos(clamp(cos_plus, -1.0, 1.0));
    float h_minus = -acos(clamp(cos_minus, -1.0, 1.0));
    h_plus = angle_n + min(h_plus - angle_n, AO_HALF_PI);
    h_minus = angle_n + max(h_minus - angle_n, -AO_HALF_PI);
    float sin_n = sin(angle_n);
    float arc_plus = cos_n + 2.0 * h_plus * sin_n - cos(2.0 * h_plus - angle_n);
    float arc_minus = cos_n + 2.0 * h_minus * sin_n - cos(2.0 * h_minus - angle_n);
    visibility += n_proj_len * 0.25 * (arc_plus + arc_minus);
    /* The same with both horizons on the tangent plane (h = angle_n +- pi/2). */
    open_sky += n_proj_len * (cos_n + angle_n * sin_n);
  }
  out_ao_depth = vec2(open_sky > 1e-6 ? clamp(visibility / open_sky, 0.0, 1.0) : 1.0, depth);
}

#else /* AO_BLUR */

/* Half resolution: the depth-aware mean of the 4x4 half-resolution neighbourhood, which
 * holds all 16 rotations of the search's pattern. Written with the view depth it stands
 * for, so the lighting pass can bring it to full resolution without bleeding across
 * silhouettes (out_ao_depth: AO, view depth; depth 0 = background). */
void main()
{
  ivec2 size = ivec2(frame.viewport_size);
  ivec2 h0 = ivec2(gl_FragCoord.xy);
  ivec2 p = min(h0 * 2, size - 1);   /* the full-resolution pixel this one stands for */
  /* The search wrote each value with the view depth of the pixel it stands for. */
  vec2 own = texelFetch(ao_half, h0, 0).rg;
  float depth = own.g;
  if (depth <= 0.0) {
    out_ao_depth = vec2(1.0, 0.0);
    return;
  }
  vec3 center = ao_view_position(p, depth);
  vec3 n = normalize(mat3(frame.view_from_world) * texelFetch(gbuffer_normal, p, 0).xyz);
  /* Off the tangent plane by more than this (scene units): another surface. */
  float tolerance = 2.0 * ao_pixel_footprint(depth) + 0.02 * frame.ao_distance;
  ivec2 half_size = textureSize(ao_half, 0);
  float sum = 0.0;
  float weight_sum = 0.0;
  for (int y = 0; y < 4; y++) {
    for (int x = 0; x < 4; x++) {
      ivec2 h = clamp(h0 + ivec2(x - 1, y - 1), ivec2(0), half_size - 1);
      vec2 ao_depth = texelFetch(ao_half, h, 0).rg;
      ivec2 q = min(h * 2, size - 1);   /* the full-resolution pixel h was computed at */
      float off_plane = abs(dot(ao_view_position(q, ao_depth.g) - center, n));
      /* Background neighbours (depth 0) count for nothing. */
      float weight = ao_depth.g > 0.0 ? clamp(1.0 - off_plane / tolerance, 0.0, 1.0) : 0.0;
      sum += weight * ao_depth.r;
      weight_sum += weight;
    }
  }
  /* No neighbour on this surface (a sliver): its own value. */
  out_ao_depth = vec2(weight_sum > 1e-4 ? sum / weight_sum : own.r, depth);
}

#endif
