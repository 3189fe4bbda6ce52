/* The Principled BSDF as Cycles evaluates it for direct light (Blender 4.x/5.x, Multiscatter
 * GGX): a metallic GGX lobe with the F82-tint Fresnel, a dielectric GGX specular layer whose
 * Fresnel is the real one of the IOR (Specular IOR Level applied), its directional albedo
 * taken out of the Lambert diffuse beneath it, and multiple-scattering energy compensation
 * on both lobes. The view-dependent part (table lookups, layer weights) is computed once
 * per pixel (principled_setup); each light then costs one lobe evaluation
 * (principled_eval). Tables: core/bsdf_tables.py, in the bsdf_lut texture. Units as EEVEE's
 * (docs/lighting.md): the result is radiance for an irradiance of one. */

const float PI = 3.14159265358979;
/* Principled's convention: Specular IOR Level 0.5 at IOR 1.5 is a reflectance of 0.04 at
 * normal incidence, so the G-buffer's specular value s stands for F0 = 0.08 * s. */
const float F0_PER_SPECULAR_LEVEL = 0.08;

/* What a pixel's BSDF needs for every light, from its material and the view. */
struct Principled {
  vec3 diffuse_color;  /* Lambert albedo left under the specular layer (Cycles' DiffCol) */
  vec3 specular_color; /* what the metal and specular lobes reflect of a uniform World
                        * (Cycles' GlossCol) */
  vec3 metal_f0;       /* base colour: the metal's reflectance at normal incidence */
  vec3 metal_scale;    /* Metallic x multiple-scattering compensation of the metal lobe */
  float specular_scale; /* (1 - Metallic) x compensation of the dielectric lobe */
  float f0;            /* dielectric reflectance at normal incidence */
  float eta;           /* the IOR that has it (1: no specular layer) */
  float alpha2;        /* GGX alpha^2 = roughness^4 */
  float n_dot_v;
  float coat_scale;    /* Coat Weight x the coat lobe's compensation (0: no coat) */
  float coat_alpha2;
  float coat_eta;
  float coat_transmission; /* what the coat lets through to the layers below */
  float roughness;
};

/* A table of n x n nodes (x along a row, y across rows; core/bsdf_tables.py's layout) at
 * (x, y) in 0..1, nodes at i / (n - 1), interpolated linearly as Cycles'
 * lookup_table_read. lut_cell finds the cell: the texture position of its corner
 * between its four texels (for textureGather, which returns them x: left-top,
 * y: right-top, z: right-bottom, w: left-bottom) and the fractions t across it;
 * lut_mix interpolates one channel's four texels.
 * NOTE: a gather reads one channel of four texels for the cost of one fetch, and the
 * compiler drops the gathers of channels a program never uses (the metal's s_schlick5
 * without metal): two to three fetches a table instead of four. At the table's last
 * node the cell's far texels belong to the next table or lie past the texture's edge;
 * their weight is 0 there, as Cycles' clamped second node's is. */
vec2 lut_cell(int first_row, int first_column, int n, float x, float y, out vec2 t)
{
  vec2 position = clamp(vec2(x, y), 0.0, 1.0) * float(n - 1);
  ivec2 i = min(ivec2(position), ivec2(n - 1));
  t = position - vec2(i);
  return (vec2(float(first_column + i.x), float(first_row + i.y)) + 1.0) /
         vec2(textureSize(bsdf_lut, 0));
}

float lut_mix(vec4 texels, vec2 t)
{
  return mix(mix(texels.w, texels.z, t.x), mix(texels.x, texels.y, t.x), t.y);
}

#if !(defined(GPU_ARB_texture_gather) || __VERSION__ >= 400)
/* Without textureGather: the four texels fetched one by one, in its order. */
vec4 lut_texels(vec2 corner, const int channel)
{
  ivec2 i = ivec2(corner * vec2(textureSize(bsdf_lut, 0))) - 1;
  return vec4(texelFetch(bsdf_lut, i + ivec2(0, 1), 0)[channel],
              texelFetch(bsdf_lut, i + ivec2(1, 1), 0)[channel],
              texelFetch(bsdf_lut, i + ivec2(1, 0), 0)[channel],
              texelFetch(bsdf_lut, i, 0)[channel]);
}
#  define LUT_TEXELS(corner, channel) lut_texels(corner, channel)
#else
#  define LUT_TEXELS(corner, channel) textureGather(bsdf_lut, corner, channel)
#endif

/* E (GGX albedo), s_schlick5 and E_avg (x, y, z) for roughness r and view cosine mu. */
vec3 ggx_albedo_tables(float r, float mu)
{
  vec2 t;
  vec2 corner = lut_cell(BSDF_LUT_E_ROW, 0, BSDF_LUT_E_SIZE, r, mu, t);
  return vec3(lut_mix(LUT_TEXELS(corner, 0), t), lut_mix(LUT_TEXELS(corner, 1), t),
              lut_mix(LUT_TEXELS(corner, 2), t));
}

float f0_from_ior(float eta)
{
  float r = (eta - 1.0) / (eta + 1.0);
  return r * r;
}

float ior_from_f0(float f0)
{
  float root = sqrt(clamp(f0, 0.0, 0.99));
  return (1.0 + root) / (1.0 - root);
}

/* Unpolarized Fresnel reflectance of a dielectric of relative IOR eta (Cycles'
 * fresnel_dielectric_cos). */
float fresnel_dielectric(float cos_i, float eta)
{
  float c = abs(cos_i);
  float g = eta * eta - 1.0 + c * c;
  if (g <= 0.0) {
    return 1.0;
  }
  g = sqrt(g);
  float a = (g - c) / (g + c);
  float b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
  return 0.5 * a * a * (1.0 + b * b);
}

/* Smith's Lambda for GGX. */
float ggx_lambda(float alpha2, float cos_n)
{
  float tan2 = max(1.0 / (cos_n * cos_n) - 1.0, 0.0);
  return 0.5 * (sqrt(1.0 + alpha2 * tan2) - 1.0);
}

/* GGX's D G / (4 cos(view)): a lobe's eval times cos(light) for a Fresnel of 1. */
float ggx_lobe(float alpha2, float n_dot_h, float n_dot_v, float n_dot_l)
{
  float t = 1.0 + (alpha2 - 1.0) * n_dot_h * n_dot_h;
  float d = alpha2 / (PI * t * t);
  float g = 1.0 / (1.0 + ggx_lambda(alpha2, n_dot_v) + ggx_lambda(alpha2, n_dot_l));
  return d * g / (4.0 * n_dot_v);
}

/* Kulla-Conty's multiple-scattering Fresnel (Fms, with one Fss cancelled as Cycles does). */
vec3 multiscatter_fresnel(vec3 fss, float e_avg)
{
  return fss * e_avg / (1.0 - fss * (1.0 - e_avg));
}

/* The table's share of the way from F0 to 1 of a dielectric of IOR eta, for roughness r
 * and view cosine mu (Cycles' ggx_gen_schlick_ior_s). */
float dielectric_albedo_share(float r, float mu, float eta)
{
  float z = sqrt(abs((eta - 1.0) / (eta + 1.0)));
  float slice = clamp(z, 0.0, 1.0) * float(BSDF_LUT_S_SIZE - 1);
  int k = min(int(slice), BSDF_LUT_S_SIZE - 1);
  /* Slice k's texels hold slices k and k + 1. */
  vec2 t;
  vec2 corner = lut_cell(BSDF_LUT_S_IOR_ROW, k * BSDF_LUT_S_SIZE, BSDF_LUT_S_SIZE, r, mu, t);
  return mix(lut_mix(LUT_TEXELS(corner, 0), t), lut_mix(LUT_TEXELS(corner, 1), t),
             slice - float(k));
}

/* A dielectric lobe's multiple-scattering Fresnel for roughness r (Cycles:
 * microfacet_ggx_preserve_energy with Kulla-Conty's fit of the real Fresnel's average):
 * x = the eval's factor 1 + Fms (1 - E) / E, y = the albedo's factor E + Fms (1 - E);
 * e, e_avg: E and E_avg of the roughness and view (ggx_albedo_tables). */
vec2 dielectric_compensation(float e, float e_avg, float f0, float eta)
{
  float real_f0 = f0_from_ior(eta);
  float real_fss = (eta - 1.0) / (4.08567 + 1.00071 * eta);
  float fss = mix(f0, 1.0, clamp((real_fss - real_f0) / (1.0 - real_f0), 0.0, 1.0));
  float fms = multiscatter_fresnel(vec3(fss), e_avg).x;
  return vec2(1.0 + fms * (1.0 - e) / max(e, 1e-6), e + fms * (1.0 - e));
}

/* Principled v1 as Blender 3.x's Cycles sets it up (single-scattering GGX, its default
 * distribution): a Burley diffuse of base colour x (1 - Metallic), not darkened by the
 * specular lobe, and one GGX lobe whose Fresnel runs from
 * cspec0 = mix(0.08 x Specular, base colour, Metallic) to 1 as the real Fresnel of the IOR
 * of 0.08 x Specular does (interpolate_fresnel_color). */
Principled principled_v1_setup(Principled p, vec3 base, float m, float specular, float r,
                               float mu)
{
  p.f0 = min(F0_PER_SPECULAR_LEVEL * max(specular, 0.0), 0.99);
  p.eta = ior_from_f0(p.f0);
  p.metal_f0 = mix(vec3(p.f0), clamp(base, 0.0, 1.0), m);
  p.metal_scale = vec3(1.0);
  p.specular_scale = 0.0;
  p.coat_scale = 0.0;
  p.coat_alpha2 = 0.0;
  p.coat_eta = 1.0;
  p.coat_transmission = 1.0;
  p.diffuse_color = max(base, 0.0) * (1.0 - m);
  /* What the lobe reflects of a uniform World: its albedo with this Fresnel. */
  float e = ggx_albedo_tables(r, mu).x;
  float s = p.eta != 1.0 ? dielectric_albedo_share(r, mu, p.eta) : 0.0;
  p.specular_color = e * mix(p.metal_f0, vec3(1.0), s);
  return p;
}

/* Principled v1's response (Cycles 3.x: bsdf_principled_diffuse's full Burley diffuse with
 * retro-reflection, and GGX with the separable Smith term). */
void principled_v1_eval(Principled p, vec3 n, vec3 v, vec3 l, float n_dot_l,
                        out vec3 diffuse, out vec3 specular)
{
  float fl = pow(1.0 - n_dot_l, 5.0);
  float fv = pow(1.0 - clamp(p.n_dot_v, 0.0, 1.0), 5.0);
  float rr = p.roughness * (dot(l, v) + 1.0);
  float f = (1.0 - 0.5 * fv) * (1.0 - 0.5 * fl) + rr * (fl + fv + fl * fv * (rr - 1.0));
  diffuse = p.diffuse_color * (f * n_dot_l / PI);
  specular = vec3(0.0);
  if (p.n_dot_v <= 0.0 || p.alpha2 <= 1e-7) {
    return;
  }
  vec3 h = normalize(l + v);
  float n_dot_h = dot(n, h);
  float t = 1.0 + (p.alpha2 - 1.0) * n_dot_h * n_dot_h;
  float d = p.alpha2 / (PI * t * t);
  float g = 1.0 / ((1.0 + ggx_lambda(p.alpha2, p.n_dot_v)) *
                   (1.0 + ggx_lambda(p.alpha2, n_dot_l)));
  float real_f0 = f0_from_ior(p.eta);
  float share = p.eta != 1.0 ?
      (fresnel_dielectric(clamp(dot(h, v), 0.0, 1.0), p.eta) - real_f0) / (1.0 - real_f0) :
      0.0;
  specular = mix(p.metal_f0, vec3(1.0), share) * (d * g / (4.0 * p.n_dot_v));
}

/* The view-dependent part of the BSDF at a surface of normal n seen from direction v:
 * base colour, Metallic, specular (F0 / 0.08, Specular IOR Level applied), Roughness and
 * the Coat (weight, roughness, IOR); with PRINCIPLED_V1 (Blender < 4.0), v1's model. */
Principled principled_setup(vec3 base, float metallic, float specular, float roughness,
                            vec3 coat, vec3 n, vec3 v)
{
  Principled p;
  float r = clamp(roughness, 0.0, 1.0);
  float alpha = r * r;
  float mu = clamp(dot(n, v), 0.0, 1.0);
  float m = clamp(metallic, 0.0, 1.0);
  p.alpha2 = alpha * alpha;
  p.n_dot_v = dot(n, v);
  p.roughness = r;
#ifdef PRINCIPLED_V1
  return principled_v1_setup(p, base, m, specular, r, mu);
#endif

  /* Coat: a dielectric GGX layer on top; what it reflects is taken from every layer
   * below (and from the emission). */
  float above = 1.0;
  p.coat_scale = 0.0;
  p.coat_alpha2 = 0.0;
  p.coat_eta = max(coat.z, 1.0);
  p.specular_color = vec3(0.0);
  if (coat.x > 0.0 && p.coat_eta != 1.0) {
    float coat_r = clamp(coat.y, 0.0, 1.0);
    float coat_f0 = f0_from_ior(p.coat_eta);
    vec3 coat_tables = ggx_albedo_tables(coat_r, mu);
    vec2 compensation = dielectric_compensation(coat_tables.x, coat_tables.z, coat_f0,
                                                p.coat_eta);
    p.coat_scale = coat.x * compensation.x;
    p.coat_alpha2 = coat_r * coat_r * coat_r * coat_r;
    float albedo = compensation.y *
                   mix(coat_f0, 1.0, dielectric_albedo_share(coat_r, mu, p.coat_eta));
    p.specular_color = vec3(coat.x * albedo);
    above = clamp(1.0 - coat.x * albedo, 0.0, 1.0);
  }
  p.coat_transmission = above;

  vec3 tables = ggx_albedo_tables(r, mu);
  float e = tables.x;
  float e_avg = tables.z;
  float missing = (1.0 - e) / max(e, 1e-6);

  /* Metal: F82-tint with a white tint is Schlick's Fresnel from the base colour; its
   * hemispherical average is F0 + (1 - F0) / 21. */
  p.metal_f0 = clamp(base, 0.0, 1.0);
  vec3 metal_fss = mix(p.metal_f0, vec3(1.0), 1.0 / 21.0);
  vec3 metal_fms = multiscatter_fresnel(metal_fss, e_avg);
  p.metal_scale = above * m * (1.0 + metal_fms * missing);
  p.specular_color += above * m * (e + metal_fms * (1.0 - e)) *
                      mix(p.metal_f0, vec3(1.0), tables.y);

  /* Dielectric specular layer over the diffuse (weight 1 - Metallic, under the coat). */
  float weight = above * (1.0 - m);
  p.f0 = min(F0_PER_SPECULAR_LEVEL * max(specular, 0.0), 0.99);
  p.eta = p.f0 > 0.0 ? ior_from_f0(p.f0) : 1.0;
  float layer = 1.0;
  p.specular_scale = 0.0;
  if (p.eta != 1.0) {
    vec2 compensation = dielectric_compensation(e, e_avg, p.f0, p.eta);
    p.specular_scale = weight * compensation.x;
    /* The layer's albedo for this view: the table's share of the way from F0 to 1. */
    float albedo = compensation.y * mix(p.f0, 1.0, dielectric_albedo_share(r, mu, p.eta));
    p.specular_color += weight * albedo;
    layer = clamp(1.0 - albedo, 0.0, 1.0);
  }
  p.diffuse_color = max(base, 0.0) * weight * layer;
  return p;
}

/* Radiance towards v for an irradiance of one from direction l, split into the diffuse
 * and the specular (metal + dielectric) lobes. */
void principled_eval(Principled p, vec3 n, vec3 v, vec3 l, out vec3 diffuse,
                     out vec3 specular)
{
  float n_dot_l = dot(n, l);
  diffuse = p.diffuse_color * (max(n_dot_l, 0.0) / PI);
  specular = vec3(0.0);
  /* Cycles evaluates no lobe for a view below the surface, nor a near-mirror lobe
   * (alpha^2 <= 1e-7) for a point light: its highlight is a delta. */
  if (n_dot_l <= 0.0) {
    return;
  }
#ifdef PRINCIPLED_V1
  principled_v1_eval(p, n, v, l, n_dot_l, diffuse, specular);
  return;
#endif
  if (p.n_dot_v <= 0.0) {
    return;
  }
  vec3 h = normalize(l + v);
  float n_dot_h = dot(n, h);
  float h_dot_v = clamp(dot(h, v), 0.0, 1.0);
  float lobe = p.alpha2 > 1e-7 ? ggx_lobe(p.alpha2, n_dot_h, p.n_dot_v, n_dot_l) : 0.0;
  float x = 1.0 - h_dot_v;
  float x2 = x * x;
  vec3 metal_f = mix(p.metal_f0, vec3(1.0), x2 * x2 * x);
  float dielectric_f = 0.0;
  if (p.eta != 1.0) {
    float real_f0 = f0_from_ior(p.eta);
    float s = clamp((fresnel_dielectric(h_dot_v, p.eta) - real_f0) / (1.0 - real_f0), 0.0,
                    1.0);
    dielectric_f = mix(p.f0, 1.0, s);
  }
  specular = lobe * (p.metal_scale * metal_f + p.specular_scale * dielectric_f);
  if (p.coat_scale > 0.0 && p.coat_alpha2 > 1e-7) {
    specular += vec3(p.coat_scale * fresnel_dielectric(h_dot_v, p.coat_eta) *
                     ggx_lobe(p.coat_alpha2, n_dot_h, p.n_dot_v, n_dot_l));
  }
}
