"""What one final render produced, returned to whoever asked for it.

Owns ``RenderResult``: the images read back (when asked for), the shadow plan used, seconds
per step, upload statistics, warnings in the user's words, and the error that stopped the
render (None on success). The pipeline fills the GPU steps; the engine adds the Blender
steps (reading the scene, syncing meshes) and hands it to the caller of ``render_final``.
"""

from dataclasses import dataclass, field

# Steps a final render times, in the order they run (seconds). Blender's own work around
# the engine (depsgraph evaluation, writing the image) is whatever the wall clock adds.
TIMED_STEPS = ("scene_read", "mesh_upload", "python_setup", "shadow", "gbuffer", "depth_range",
               "ao", "lighting",
               "fxaa", "antialiasing", "readback")


@dataclass
class RenderResult:
    images: dict = None            # name -> (H, W, 4) float32, bottom row first (like GL)
    plan: object = None            # core.shadow_plan.ShadowPlan
    timings: dict = field(default_factory=dict)   # step name -> seconds (see TIMED_STEPS)
    upload_bytes: int = 0          # mesh data uploaded to the GPU by this render
    warnings: list = field(default_factory=list)
    error: str = None

    @property
    def ok(self):
        return self.error is None
