"""A final render's cascade boxes: each a step function of the fresh fit, with no history.

Owns ``quantized_box``: the box that holds a cascade's receivers (the slice's corners, or
its visible receivers with Fit to Visible Depth), its half widths rounded up on a ladder
of ``2 ** (1 / HALF_WIDTH_STEPS_PER_OCTAVE)`` steps, its centre snapped to a grid of
1 / ``CENTRE_STEPS_PER_BOX`` of its width (whole texels, in the light's rotated frame,
which is fixed for a fixed sun) and its depths to a coarse grid along the light. Two
renders whose receivers differ a little then get the very same box, so the shadow pass
keeps its tile (``render/shadow_atlas.py``, tile signatures), and yet each render's box
depends on nothing but its own inputs: the frames of a camera animation render to the
same pixels in any process (``-a``, or a farm's workers). numpy only.
"""

import math

import numpy as np

from .stabilization import _round_up_dyadic

# NOTE: a half width rounded up on this ladder is at most 2 ** (1/24) - 1 = 2.9 % (on
# average 1.5 %) wider than the receivers need; finer steps change the box (and redraw
# its shadow map) more often while a turning camera's receivers grow or shrink, coarser
# ones blur every render's shadows (2 ** (1/16) steps with a 1/32 grid: 5 % coarser
# texels, a few more wrong pixels at shadow edges against Cycles).
HALF_WIDTH_STEPS_PER_OCTAVE = 24
# NOTE: the box is wider than its rounded half width by half a grid step on each side, so
# the snapped centre (at most half a step off) still holds the receivers: 1/48 of its
# width (2 %) more. The box then stays while its receivers drift by up to one step: a
# camera flying on redraws a cascade's map once per 1/48 of its width travelled.
CENTRE_STEPS_PER_BOX = 48
# The depth grid: this share of the depth the box must span (the slice's sphere and the
# occluder margin), rounded up to a power of two. Depth costs no texels, only precision.
DEPTH_STEPS_PER_SPAN = 16


def ladder_half_width(half):
    """``half`` rounded up to the next step of the ``HALF_WIDTH_STEPS_PER_OCTAVE`` ladder."""
    step = math.ceil(HALF_WIDTH_STEPS_PER_OCTAVE * math.log2(half))
    return 2.0 ** (step / HALF_WIDTH_STEPS_PER_OCTAVE)


def quantized_box(low_xy, high_xy, resolution, largest_half=math.inf):
    """(centre_xy, texel_xy) of the box that holds the rectangle ``low_xy`` .. ``high_xy``
    (rotated light frame) with ``resolution`` texels a side: per axis, the rectangle's
    half width on the ladder (at most ``largest_half``: the slice's sphere, which holds
    every receiver), a texel size that leaves room for half a grid step and a texel on
    each side, rounded up to 9 significant bits (exact, so whole multiples of it are
    too), and the rectangle's centre snapped to a grid of whole texels."""
    low = np.asarray(low_xy, dtype=np.float64)
    high = np.asarray(high_xy, dtype=np.float64)
    grid_texels = max(1, resolution // CENTRE_STEPS_PER_BOX)
    usable = max(resolution - grid_texels - 1, 1)
    centre, texel = np.empty(2), np.empty(2)
    for axis in range(2):
        half = max(0.5 * float(high[axis] - low[axis]), 1e-9)
        half = min(ladder_half_width(half), max(largest_half, half))
        # Box half width resolution * texel / 2 >= half + (grid_texels + 1) * texel / 2.
        texel[axis] = _round_up_dyadic(2.0 * half / usable, bits=9)
        step = grid_texels * texel[axis]
        centre[axis] = round(0.5 * float(low[axis] + high[axis]) / step) * step
    return centre, texel


def quantized_depths(near_depth, far_depth, span):
    """(near, far) depths along the light of a box that must reach from ``near_depth``
    (toward the light) to ``far_depth``: each widened outward to a grid of
    1 / ``DEPTH_STEPS_PER_SPAN`` of ``span`` (the slice's sphere and the occluder margin,
    which stay the same while the camera moves), rounded up to a power of two."""
    step = _round_up_dyadic(max(span, 1e-9) / DEPTH_STEPS_PER_SPAN, bits=1)
    return math.floor(near_depth / step) * step, math.ceil(far_depth / step) * step
