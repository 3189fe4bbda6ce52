"""Receiver fitting (sample-distribution shadow maps): cascades fitted to what the camera
actually sees, not to the whole of its frustum.

Owns the G-buffer's screen blocks as the planner reads them
(``depth_blocks_from_reduction``), the visible depth range the splits divide
(``visible_depth_range``), the rectangle each cascade's visible receivers need in the
light's frame (``receiver_square``), and ``ReceiverTermsCache``, which keeps the per-block
work of one view from frame to frame. The hysteresis that holds a depth range while it
still fits is here too; what it holds from the frame before is passed in by the caller
(``view_state.ShadowViewState`` keeps it per view). numpy only.
"""

import math

import numpy as np

from ..memo import ValueMemo
from .spaces import _check_rotation
from .stabilization import _round_up_dyadic


def depth_blocks_from_reduction(pairs, block_pixels, width, height):
    """Screen blocks of the G-buffer reduction -> what ``cascades.receiver_square`` reads:
    (ndc_low, ndc_high, nearest, farthest) of the blocks that show anything.
    ``pairs``: (rows, cols, 2) nearest / farthest view depth per block (rows bottom-up;
    nearest > 1e37 where a block shows only background)."""
    pairs = np.asarray(pairs)
    nearest = pairs[..., 0].astype(np.float64).ravel()
    farthest = pairs[..., 1].astype(np.float64).ravel()
    ndc_low, ndc_high = _block_corners(pairs.shape[:2], block_pixels, width, height)
    shown = nearest < 1e37
    # NOTE: a view that the scene fills shows something in every block: the corners are
    # then the held arrays themselves. Otherwise indices and ``take``: boolean indexing
    # of the (rows, cols, 2) arrays cost ~0.15 ms a redraw.
    if shown.all():
        return ndc_low, ndc_high, nearest, farthest
    shown = np.flatnonzero(shown)
    return (ndc_low.take(shown, axis=0), ndc_high.take(shown, axis=0), nearest.take(shown),
            farthest.take(shown))


def _block_corners_uncached(shape, block_pixels, width, height):
    """Every block's NDC corners, (rows * cols, 2) row by row, for ``shape`` (rows, cols)
    blocks of ``block_pixels`` over a ``width`` x ``height`` view."""
    rows, cols = np.indices(shape)
    x0 = cols * block_pixels / width * 2.0 - 1.0
    x1 = np.minimum((cols + 1) * block_pixels, width) / width * 2.0 - 1.0
    y0 = rows * block_pixels / height * 2.0 - 1.0
    y1 = np.minimum((rows + 1) * block_pixels, height) / height * 2.0 - 1.0
    return (np.stack([x0, y0], axis=-1).reshape(-1, 2),
            np.stack([x1, y1], axis=-1).reshape(-1, 2))


# The same for every frame of one view size. The arrays a hit returns are the same
# (read-only) objects as the frame before's, which lets ``ReceiverTermsCache`` recognise
# them by identity without comparing their values.
_block_corners = ValueMemo(_block_corners_uncached, 8,
                           key=lambda shape, block_pixels, width, height:
                           (tuple(shape), block_pixels, width, height))


def block_window(projection, ndc_low, ndc_high):
    """Each block's x and y ends on the view window (at depth 1 for perspective):
    (x_lo, x_hi, y_lo, y_hi)."""
    left, right, bottom, top = projection.view_window()
    return (left + (ndc_low[:, 0] + 1.0) * 0.5 * (right - left),
            left + (ndc_high[:, 0] + 1.0) * 0.5 * (right - left),
            bottom + (ndc_low[:, 1] + 1.0) * 0.5 * (top - bottom),
            bottom + (ndc_high[:, 1] + 1.0) * 0.5 * (top - bottom))


def receiver_terms(world_from_view, projection, blocks, light_from_world_rot, window=None):
    """Per screen block and light-frame axis: the least and greatest of a x + b y (- c)
    over the block's x and y ends, where (a, b, c) is that axis's row of the linear map from
    view space, and the offset of the map. ``window``: ``block_window`` of the blocks'
    corners, when the caller has it.

    NOTE: a block's corner is (x d, y d, -d) in view space (perspective; orthographic:
    (x, y, -d)) for x, y and d each at one of its two ends, and its light-frame xy is
    linear in it. So each axis's extreme over a block's 8 corners follows from the
    extremes of each term (bilinear in d for perspective) without forming the corners:
    the same bounds as transforming every corner, at a fraction of the work."""
    world_from_view = np.asarray(world_from_view, dtype=np.float64)
    rotation_xy = _check_rotation(light_from_world_rot)[:2]
    x_lo, x_hi, y_lo, y_hi = block_window(projection, blocks[0], blocks[1]) \
        if window is None else window
    linear = rotation_xy @ world_from_view[:3, :3]            # (2, 3)
    offset = rotation_xy @ world_from_view[:3, 3]
    is_perspective = bool(projection.is_perspective)
    rows = []
    for a, b, c in linear:
        # x_lo <= x_hi, so a x is least at x_lo when a >= 0, else at x_hi (the same
        # products a minimum of both would pick, at half the work); likewise b y.
        ax_lo, ax_hi = (a * x_lo, a * x_hi) if a >= 0.0 else (a * x_hi, a * x_lo)
        by_lo, by_hi = (b * y_lo, b * y_hi) if b >= 0.0 else (b * y_hi, b * y_lo)
        g_lo = ax_lo + by_lo
        g_hi = ax_hi + by_hi
        if is_perspective:
            g_lo, g_hi = g_lo - c, g_hi - c
        rows += [g_lo, g_hi]
    # x least, x greatest, y least, y greatest (1-D each: numpy's 2-D reductions and
    # broadcasts cost several times more here); and c of each axis.
    return rows, linear[:, 2].copy(), offset, is_perspective


class ReceiverTermsCache:
    """``receiver_terms`` of one view, kept while they stay the same.

    The cascades of one frame ask for the same terms (same blocks, camera and light), and
    a redraw that keeps its G-buffer (nothing moved) hands the planner the very block
    arrays of the frame before. Both are recognised by the blocks' identity, so a cache
    belongs to one view (``view_state.ShadowViewState``) or to one ``compute_cascades``
    call, never to a module; the corner arrays are held only while they are read-only,
    so they cannot have changed in place."""

    def __init__(self):
        self._window = None     # (ndc_low, ndc_high, projection, block_window)
        self._terms = None      # (blocks, camera-and-light key, receiver_terms)

    def window(self, projection, ndc_low, ndc_high):
        held = self._window
        if held is not None and held[0] is ndc_low and held[1] is ndc_high and \
                held[2] == projection:
            return held[3]
        window = block_window(projection, ndc_low, ndc_high)
        if not (ndc_low.flags.writeable or ndc_high.flags.writeable):
            self._window = (ndc_low, ndc_high, projection, window)
        return window

    def terms(self, world_from_view, projection, blocks, light_from_world_rot):
        world_from_view = np.asarray(world_from_view, dtype=np.float64)
        key = (world_from_view.tobytes(),
               np.asarray(light_from_world_rot, dtype=np.float64).tobytes(), projection)
        held = self._terms
        if held is not None and held[0] is blocks and held[1] == key:
            return held[2]
        terms = receiver_terms(world_from_view, projection, blocks, light_from_world_rot,
                               self.window(projection, blocks[0], blocks[1]))
        self._terms = (blocks, key, terms)
        return terms


def receiver_square(world_from_view, projection, blocks, near_depth, far_depth,
                    light_from_world_rot, exact=False, cache=None):
    """The rectangle (centre_xy, half_widths_xy) in the rotated light frame that holds every
    visible receiver between view depths ``near_depth`` and ``far_depth``, or None when no
    receiver is there.

    ``blocks``: (ndc_low (N, 2), ndc_high (N, 2), nearest (N,), farthest (N,)): screen
    blocks and the view-depth range of what each shows (the G-buffer reduced on the GPU).
    Each block's part of the slice is a small frustum piece; its 8 corners bound it.
    NOTE: each half width is rounded up to 1/32 of its leading power of two
    (``rounded_square``), so the texel size changes rarely, by whole steps; a box fitted
    to it is kept while the receivers still fit (``holding``).
    ``exact``: the receivers' own extent, not rounded.
    ``cache``: a ``ReceiverTermsCache`` to take the per-block terms from (None: computed
    here)."""
    _ndc_low, _ndc_high, nearest, farthest = blocks
    # Indices, not a mask: ``take`` is several times faster than boolean indexing here.
    inside = np.flatnonzero((farthest >= near_depth) & (nearest <= far_depth))
    if not len(inside):
        return None
    d0 = np.maximum(nearest.take(inside), near_depth)
    d1 = np.minimum(farthest.take(inside), far_depth)
    terms, c, offset, is_perspective = (
        receiver_terms(world_from_view, projection, blocks, light_from_world_rot)
        if cache is None else
        cache.terms(world_from_view, projection, blocks, light_from_world_rot))
    positive = is_perspective and d0.min() > 0.0     # d1 >= d0 for a block inside
    # NOTE: the few numbers per axis below are Python floats (the same IEEE arithmetic as
    # numpy's, without its per-call cost on 2-element arrays).
    low, high = [], []
    for axis in range(2):
        g_lo, g_hi = terms[2 * axis].take(inside), terms[2 * axis + 1].take(inside)
        if positive:
            # d g is least at d0 or d1 times g's least, greatest at d0 or d1 times its
            # greatest, as d > 0.
            least = min((d0 * g_lo).min(), (d1 * g_lo).min())
            greatest = max((d0 * g_hi).max(), (d1 * g_hi).max())
        elif is_perspective:
            # Bilinear in (d, g): the extremes are at d0 or d1 times g's least or greatest.
            products = (d0 * g_lo, d1 * g_lo, d0 * g_hi, d1 * g_hi)
            least = min(float(p.min()) for p in products)
            greatest = max(float(p.max()) for p in products)
        else:
            depth = (-c[axis] * d0, -c[axis] * d1)
            least = (g_lo + np.minimum(*depth)).min()
            greatest = (g_hi + np.maximum(*depth)).max()
        low.append(float(least) + float(offset[axis]))
        high.append(float(greatest) + float(offset[axis]))
    square = (np.array([0.5 * (lo + hi) for lo, hi in zip(low, high)]),
              np.array([max(0.5 * (hi - lo), 1e-9) for lo, hi in zip(low, high)]))
    return square if exact else rounded_square(square)


def rounded_square(square, room=0.0):
    """A receivers' rectangle (centre_xy, half widths) with each half width widened by
    ``room`` (a share of it; one, or one per axis) and rounded up to 1/32 of its leading
    power of two, so the texel size of a box fitted to it changes only in coarse steps."""
    centre, half = square
    rooms = np.broadcast_to(np.asarray(room, dtype=np.float64), (2,)).tolist()
    return (np.asarray(centre, dtype=np.float64),
            np.array([_round_up_dyadic(max(float(h) * (1.0 + r), 1e-9), bits=6)
                      for h, r in zip(half, rooms)]))


def visible_depth_range(nearest, farthest, previous=None, steps_per_octave=8,
                        shrink_below=0.75):
    """The depth range sample-distribution shadow maps fit the cascades to, from the
    nearest and farthest view depth the G-buffer holds.

    NOTE: quantized outwards to a geometric grid (``steps_per_octave`` per doubling), and
    the ``previous`` range is kept while it still holds the new one and the new one's
    logarithmic span is not below ``shrink_below`` of it: small camera moves then leave the
    cascades exactly where they were (stabilized edges stay still, no re-rendered tiles),
    and a range that only grows or shrinks a little does not pop. When the visible range
    leaves the ``previous`` one, the end it left by is set one step further out: a camera
    that keeps moving the same way then keeps the new range for a while too. Returns
    (near, far) or None when nothing is visible."""
    if not (np.isfinite(nearest) and np.isfinite(farthest)) or not 0.0 < nearest <= farthest:
        return None
    step = math.log(2.0) / steps_per_octave
    low_step = math.floor(math.log(nearest) / step)
    high_step = math.ceil(math.log(farthest) / step + 1e-9)
    low, high = math.exp(low_step * step), math.exp(high_step * step)
    if previous is not None:
        old_low, old_high = previous
        if old_low <= low and old_high >= high and \
                math.log(high / low) >= shrink_below * math.log(old_high / old_low):
            return previous
        if low < old_low <= high:
            low = math.exp((low_step - 1) * step)
        if low <= old_high < high:
            high = math.exp((high_step + 1) * step)
    return (low, high)

