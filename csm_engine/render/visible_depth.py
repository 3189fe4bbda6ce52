"""The visible-depth reduction for Fit to Visible Depth (sample-distribution shadow maps).

Owns ``VisibleDepth``: the G-buffer's view depth reduced on the GPU to the nearest and
farthest depth per 16x16 block (two 4x4 min/max steps, ``depth_range_frag.glsl``) and read
back; the CPU fits the cascades to those blocks (``core.shadow_plan``). Blocks of a kept
G-buffer are kept with it (the frame cache's ``depth_blocks``). Also owns
``reduce_min_max``, the 4x4 min/max steps on the GPU, which ``blocker_search`` runs over
the shadow atlas too.
"""

import numpy as np

from ..core.shadow_plan import depth_blocks_from_reduction
from . import shaders


class VisibleDepth:
    """One view's reduction; holds the last read-back, which stands in for the reduction
    in the benchmark's Python-only frames (nothing is drawn there to reduce)."""

    # The G-buffer is reduced to blocks of this many pixels on a side (two 4x4 steps).
    DEPTH_BLOCK_PIXELS = 16

    def __init__(self):
        self._depth_pairs = None

    def blocks(self, targets, gbuffer, gbuffer_kept, width, height):
        """The visible depth blocks of ``gbuffer`` (``gbuffer.GBuffer``): those recorded
        with it when it was kept, else reduced now (and recorded); None without a GPU."""
        frame_cache = targets.frame_cache
        blocks = frame_cache.depth_blocks if gbuffer_kept else None
        if blocks is None:
            blocks = self._reduce(targets, gbuffer.view_depth, width, height)
            if blocks is not None:
                frame_cache.depth_blocks = blocks
        return blocks

    def _reduce(self, targets, view_depth, width, height):
        """Nearest and farthest view depth per 16x16 block, by two 4x4 min/max reductions
        on the GPU and one read-back of the small result
        (``shadow_plan.depth_blocks_from_reduction``)."""
        import gpu
        target, fb = reduce_min_max(targets, "depth_range", view_depth, (width, height), 2,
                                    source_is_view_depth=True)
        size = (target.width, target.height)
        if not targets.records:
            # Benchmark only (nothing was drawn to reduce): the last real frame's reduction
            # stands in, so the frame plans, and keeps shadow tiles, as a real one does.
            pairs = self._depth_pairs
            if pairs is None or pairs.shape[:2] != (size[1], size[0]):
                return None
        else:
            buffer = gpu.types.Buffer('FLOAT', size[0] * size[1] * 4)
            with fb.bind():
                fb.read_color(0, 0, size[0], size[1], 4, 0, 'FLOAT', data=buffer)
            pairs = np.frombuffer(buffer, dtype=np.float32).reshape(
                size[1], size[0], 4)[..., :2]
            self._depth_pairs = pairs
        return depth_blocks_from_reduction(pairs, self.DEPTH_BLOCK_PIXELS, width, height)


def reduce_min_max(targets, name, source, size, steps, source_is_view_depth=False):
    """``steps`` 4x4 min/max reductions of ``source`` (``size`` texels) on the GPU
    (``depth_range_frag.glsl``): per output texel the nearest (R) and farthest (G) value of
    the 4^steps x 4^steps block it covers. ``source_is_view_depth``: the G-buffer's view
    depth target (its first channel, ``gbuffer_layout.glsl``), whose 0 (background) is
    left out. Returns the last RGBA32F target and its
    framebuffer (textures named ``<name>_<step>``). The view depth's step is its own
    program (``depth_range_view``): llvmpipe would run both kinds of step's code for
    every pixel if a uniform chose between them."""
    import gpu
    library = shaders.LIBRARY
    view_depth = source_is_view_depth
    for step in range(steps):
        size = (max((size[0] + 3) // 4, 1), max((size[1] + 3) // 4, 1))
        target = targets.texture(f"{name}_{step}", size, 'RGBA32F')
        fb = targets.framebuffer(f"{name}_{step}", colors=(target,))
        with fb.bind():
            gpu.state.viewport_set(0, 0, size[0], size[1])
            gpu.state.depth_test_set('NONE')
            gpu.state.blend_set('NONE')
            shader = library.get("depth_range_view" if view_depth else "depth_range")
            shader.bind()
            shader.uniform_sampler("source", source)
            targets.call(targets.fullscreen_batch().draw, shader)
        source, view_depth = target, False
    return source, fb
