"""What one final render produced, returned to whoever asked for it.

Owns ``RenderResult``: the images read back (when asked for), the shadow plan used, seconds
per step, what the passes drew and kept (``PassCounts``), the meshes it uploaded, warnings
in the user's words, the metadata the image carries (Cryptomatte's), and the error that stopped the render (None on success). The pipeline
fills the GPU steps; the engine adds the Blender steps (reading the scene, syncing meshes)
and hands it to the caller of ``render_final``.
"""

from dataclasses import dataclass, field, fields

# Steps a final render times, in the order they run (seconds). Blender's own work around
# the engine (depsgraph evaluation, writing the image) is whatever the wall clock adds.
TIMED_STEPS = ("scene_read", "mesh_upload", "python_setup", "shadow", "gbuffer", "depth_range",
               "ao", "shadow_volumes", "lighting",
               "fxaa", "antialiasing", "readback")


@dataclass
class PassCounts:
    """What the passes of one or more frames drew, and what they kept from the frame before
    because it would have come out the same (a shadow tile whose light matrix, casters and
    geometry are those it holds; a G-buffer, or its AO, of the same view and objects)."""
    shadow_tiles_drawn: int = 0
    shadow_tiles_kept: int = 0
    gbuffers_drawn: int = 0
    gbuffers_kept: int = 0
    ao_drawn: int = 0
    ao_kept: int = 0

    def __add__(self, other):
        return PassCounts(*(getattr(self, f.name) + getattr(other, f.name)
                            for f in fields(self)))


@dataclass
class RenderResult:
    images: dict = None            # name -> (H, W, 4) float32, bottom row first (like GL)
    plan: object = None            # core.shadow_plan.ShadowPlan
    timings: dict = field(default_factory=dict)   # step name -> seconds (see TIMED_STEPS)
    passes: PassCounts = field(default_factory=PassCounts)  # summed over the samples drawn
    mesh_uploads: int = 0          # meshes uploaded to the GPU by this render
    upload_bytes: int = 0          # their vertex and index data
    warnings: list = field(default_factory=list)
    error: str = None
    metadata: dict = field(default_factory=dict)  # key -> text for the image (Cryptomatte)
    # The Shadow error view's counts (render/shadow_volumes.py ShadowError), None in any
    # other view.
    shadow_error: object = None

    @property
    def ok(self):
        return self.error is None
