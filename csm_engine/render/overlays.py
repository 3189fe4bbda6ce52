"""Overlays drawn over the lit image: the frozen cascades' light-space boxes.

Owns ``draw_frozen_cascades`` (coloured lines, one colour per cascade, while Freeze
Cascades holds them) and ``draw_overlays`` (the same into a given framebuffer, after
anti-aliasing, so 1-pixel lines stay crisp).
"""

import numpy as np

from ..core.shadow_plan import CASCADE_LINE_COLORS
from . import shaders
from .draw_lists import column_major

# The 12 edges of a box whose corners are numbered x + 2 y + 4 z (0/1 each).
_BOX_EDGES = ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7),
              (0, 4), (1, 5), (2, 6), (3, 7))


def draw_frozen_cascades(snap, plan):
    """Draw each frozen cascade's light-space box as coloured lines into the bound
    framebuffer, seen by ``snap``'s camera."""
    import gpu
    lines, colors = [], []
    for index, tile in enumerate(plan.tiles[:plan.cascade_count]):
        world_from_clip = np.linalg.inv(tile.clip_from_world)
        corners = np.array([[x, y, z, 1.0] for z in (-1, 1) for y in (-1, 1)
                            for x in (-1, 1)]) @ world_from_clip.T
        corners = corners[:, :3] / corners[:, 3:]
        for a, b in _BOX_EDGES:
            lines += [corners[a], corners[b]]
            colors += [CASCADE_LINE_COLORS[index]] * 2
    if not lines:
        return
    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type='F32', len=3, fetch_mode='FLOAT')
    fmt.attr_add(id="color", comp_type='F32', len=4, fetch_mode='FLOAT')
    vbo = gpu.types.GPUVertBuf(fmt, len(lines))
    vbo.attr_fill("pos", np.array(lines, dtype=np.float32))
    vbo.attr_fill("color", np.array(colors, dtype=np.float32))
    batch = gpu.types.GPUBatch(type='LINES', buf=vbo)
    shader = shaders.LIBRARY.get("lines")
    shader.bind()
    shader.uniform_float("clip_from_world", column_major(snap.camera.clip_from_world))
    batch.draw(shader)


def draw_overlays(snap, plan, target_fb, width, height):
    """The overlays of ``plan`` into ``target_fb`` (nothing unless cascades are frozen)."""
    import gpu
    if plan.frozen_camera is None:
        return
    with target_fb.bind():
        gpu.state.viewport_set(0, 0, width, height)
        draw_frozen_cascades(snap, plan)
