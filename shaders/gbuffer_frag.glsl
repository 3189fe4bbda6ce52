/* G-buffer pass, fragment stage.
 * out_albedo   = base colour rgb, specular strength
 * out_normal   = world normal xyz, Blinn-Phong shininess
 * out_position = world position xyz, coverage (1 on geometry, 0 on background) */
void main()
{
  vec4 base = base_color;
  if (material_params.w > 0.5) {
    base *= texture(base_color_texture, tex_coord);
  }
  /* Alpha-masked (cutout) materials, e.g. Sponza's foliage. */
  if (material_params.z > 0.0 && base.a < material_params.z) {
    discard;
  }
  vec3 n = normalize(world_normal);
  /* Blender draws faces from both sides; light the side the camera sees. */
  if (!gl_FrontFacing) {
    n = -n;
  }
  out_albedo = vec4(base.rgb, material_params.y);
  out_normal = vec4(n, material_params.x);
  out_position = vec4(world_position, 1.0);
}
