/* G-buffer pass, fragment stage.
 * out_albedo = base colour rgb, specular strength
 * out_normal = world normal xyz, Blinn-Phong shininess
 * out_depth  = view depth along the camera's forward axis (0 = background) */
void main()
{
  vec4 base = base_color;
  if (material_params.w > 0.5) {
    base *= texture(base_color_texture, tex_coord);
  }
#ifdef ALPHA_MASK
  /* Alpha-masked (cutout) materials, e.g. Sponza's foliage. Only this variant may discard:
   * see shaders.py on early depth tests. */
  if (base.a < material_params.z) {
    discard;
  }
#endif
  vec3 n = normalize(world_normal);
  /* Blender draws faces from both sides; light the side the camera sees. */
  if (gl_FrontFacing != (mirror_sign > 0.0)) {
    n = -n;
  }
  out_albedo = vec4(base.rgb, material_params.y);
  out_normal = vec4(n, material_params.x);
  out_depth = max(view_depth, 1e-6);
}
