/* Shadow-volume pass, vertex stage: world-space volume triangles (core/shadow_volumes.py)
 * through the camera, with their view depth for the fragment stage's own depth test. */
void main()
{
  volume_depth = dot(pos - frame.camera_position, frame.camera_forward);
  gl_Position = frame.clip_from_world * vec4(pos, 1.0);
  /* NOTE: gpu.state has no depth clamp, and volumes reach far past the camera's far plane.
   * The fragment stage compares view depths itself, so window depth is not needed: a clip
   * depth of 0 keeps every vertex between the near and far planes (the clipper still cuts
   * at w = 0, the plane through the eye, and at the screen's sides). What lies nearer than
   * the near plane is in front of every visible surface, so never counted anyway. */
  gl_Position.z = 0.0;
}
