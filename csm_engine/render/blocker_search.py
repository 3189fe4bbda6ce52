"""The soft filter's reach: the shadow atlas's nearest stored depth per block of texels.

Owns ``nearest_blocks``: the atlas reduced on the GPU to its nearest depth per
``BLOCK_TEXELS`` x ``BLOCK_TEXELS`` block (three 4x4 min steps, ``depth_range_frag.glsl``),
redone only when a tile was redrawn. The soft filter (``shadow_soft.glsl``) reads the 3x3
blocks around a point, which hold everything its widest search can reach, and sizes its
blocker search to the cone the light subtends at the nearest caster there. Sized to the
nearest caster anywhere in the tile instead, a low caster beside a tall one got a search
many times wider than its own cone; its few taps then missed the thin sliver of blockers
at the lit side of the penumbra, which came out too narrow.
"""

from .resources import NearestBlocks
from .visible_depth import reduce_min_max

# Texels on a side of a block: three 4x4 steps. The soft filter's widest search
# (SOFT_RADIUS_LIMIT_TEXELS, 48) must fit within one block on each side of a point's own.
BLOCK_TEXELS = 64
_STEPS = 3


def nearest_blocks(targets, atlas, tiles_drawn):
    """The nearest depth per block of ``atlas`` (``shadow_atlas.ShadowAtlas``) as an
    RGBA32F texture (nearest window depth in R; 1 where nothing was drawn): the one held
    when no tile was drawn since it was reduced (``tiles_drawn``: tiles drawn this frame),
    else reduced now."""
    frame_cache = targets.frame_cache
    held = frame_cache.nearest_blocks
    if tiles_drawn == 0 and held is not None and held.atlas is atlas.depth:
        return held.texture
    frame_cache.nearest_blocks = None
    depth = atlas.depth
    source, _fb = reduce_min_max(targets, "atlas_nearest", depth, (depth.width, depth.height),
                                 _STEPS)
    if targets.records:
        frame_cache.nearest_blocks = NearestBlocks(atlas.depth, source)
    return source
