/* Which of the sun's shadow maps a pixel reads: the cascade of its view-depth slice, the
 * next cascade's weight inside a blend band, the finest map that holds the point (Cascade
 * Selection: Shadow Map) with a cross-fade at that map's edge, and the fade of the shadow
 * towards the Shadow Distance. Distances are view depths (scene units along the camera's
 * forward axis) unless a name says texels. */

/* Index of the cascade whose slice holds this view depth, or -1 beyond the last. */
int cascade_index(float view_depth)
{
  int count = frame.cascade_count;
  for (int i = 0; i < MAX_CASCADES; i++) {
    if (i < count && view_depth <= frame.cascades[i].far_depth) {
      return i;
    }
  }
  return -1;
}

/* The sun's shadow lookups for a pixel at this view depth: its cascade (-1 beyond the
 * last) and, inside a blend band, the next cascade's weight (0 elsewhere). The lighting
 * pass looks up cascade i, then cascade i + 1 where the weight is above 0, and mixes:
 * sun_shadow_fade() gives the distance fade. */
int sun_cascade(float view_depth, out float next_weight)
{
  int i = cascade_index(view_depth);
  next_weight = 0.0;
  if (i >= 0 && i + 1 < frame.cascade_count) {
    float split = frame.cascades[i].far_depth;
    float band = frame.cascades[i].blend_band;
    /* The next cascade's box was fitted from split - band on, so it covers this point. */
    if (band > 0.0) {
      next_weight = clamp((view_depth - (split - band)) / band, 0.0, 1.0);
    }
  }
  return i;
}

/* Width (texels) of the cross-fade inside a finer cascade's map edge under map selection. */
const float MAP_BLEND_TEXELS = 48.0;

/* Map selection (SELECT_MAP): the first cascade whose shadow map holds p with `reach`
 * texels to spare for the filter, whatever slice of view depth p is in, and within
 * MAP_BLEND_TEXELS of that map's edge the next cascade that holds p mixed in (`second`,
 * weight `second_weight`). A cascade fitted to its receivers renders every caster over
 * its whole rectangle, which reaches past its slice's far split, so points there get its
 * finer texels too (docs/soft-shadows.md, "Cascade selection"). When no map holds p with
 * room: `cascade`, the depth slice's own, unmixed. */
int sun_cascade_by_map(vec3 p, int cascade, float reach, out int second,
                       out float second_weight)
{
  int first = -1;
  second = -1;
  second_weight = 0.0;
  for (int i = 0; i < MAX_CASCADES; i++) {
    if (i >= frame.cascade_count) {
      break;
    }
    ShadowTileData tile = frame.shadow_tiles[i];
    vec3 s = (tile.shadow_from_world * vec4(p, 1.0)).xyz; /* orthographic: w is 1 */
    /* Texels to the map's side edges (less the filter's reach), and to its far plane
     * (the box ends there too: a point beyond it is not in the map). */
    float inside = min(min(min(s.x, s.y), min(1.0 - s.x, 1.0 - s.y)) * tile.resolution - reach,
                       (1.0 - s.z) * (tile.light_far - tile.light_near) / tile.texel_world);
    bool holds = inside > 0.0;
    if (holds && first >= 0) {
      second = i;
      break;
    }
    if (holds) {
      first = i;
      float band = frame.cascades[i].blend_band > 0.0 ? MAP_BLEND_TEXELS : 0.0;
      second_weight = inside < band ? 1.0 - inside / band : 0.0;
      if (second_weight == 0.0) {
        break;
      }
    }
  }
  if (second < 0) {
    second_weight = 0.0;
  }
  return first >= 0 ? first : cascade;
}

/* Shadow visibility v faded out towards the Shadow Distance. */
float sun_shadow_fade(float vis, float view_depth)
{
  float fade_start = frame.fade_start_depth;
  float distance = frame.shadow_distance;
  if (distance > fade_start && view_depth > fade_start) {
    vis = mix(vis, 1.0, clamp((view_depth - fade_start) / (distance - fade_start), 0.0, 1.0));
  }
  return vis;
}
