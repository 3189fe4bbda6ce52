/* The G-buffer's world normals (gbuffer_layout.glsl) unpacked into a float target for the
 * read-back (render/readback.py): xyz, 0 on the background. */
#include "gbuffer_layout.glsl"

void main()
{
  ivec2 px = ivec2(gl_FragCoord.xy);
  vec3 n = octahedral_unpack(texelFetch(gbuffer_surface_target, px, 0).z);
  out_normal = gbuffer_view_depth(texelFetch(gbuffer_depth, px, 0)) > 0.0 ? vec4(n, 0.0) :
                                                                           vec4(0.0);
}
