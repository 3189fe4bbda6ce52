/* Instanced draws (INSTANCED): one draw gives every copy of a mesh, and each copy reads its
 * own matrix (world_from_object in the G-buffer, clip_from_object in a shadow tile) from the
 * texture instance_matrices: four RGBA32F texels (the matrix's columns) a copy,
 * INSTANCE_MATRICES_PER_ROW copies a row (render/instancing.py packs it), the draw's copies
 * from instance_offset on. */
#ifdef INSTANCED
#define INSTANCE_MATRICES_PER_ROW 1024

mat4 instance_matrix()
{
  int index = instance_offset + gl_InstanceID;
  ivec2 first = ivec2((index % INSTANCE_MATRICES_PER_ROW) * 4,
                      index / INSTANCE_MATRICES_PER_ROW);
  return mat4(texelFetch(instance_matrices, first, 0),
              texelFetch(instance_matrices, first + ivec2(1, 0), 0),
              texelFetch(instance_matrices, first + ivec2(2, 0), 0),
              texelFetch(instance_matrices, first + ivec2(3, 0), 0));
}
#endif
