"""Anti-aliasing maths for final renders: where each jittered sample looks and how much it
counts.

Owns ``sample_offsets`` (sub-pixel camera offsets over Blender's pixel filter, Film > Filter
Size, with Blackman-Harris weights, as Cycles and EEVEE filter pixels) and ``jittered``
(the same camera moved by a fraction of a pixel). A final render with N samples draws the
G-buffer and lighting N times through jittered cameras and averages them with these
weights; the shadow maps are planned once from the unjittered camera. numpy only.
"""

import numpy as np

from .camera import CameraView


def _radical_inverse(index, base):
    """Van der Corput: the digits of ``index`` in ``base`` mirrored after the point."""
    result, scale = 0.0, 1.0 / base
    while index > 0:
        index, digit = divmod(index, base)
        result += digit * scale
        scale /= base
    return result


def blackman_harris(distance, width):
    """Blackman-Harris window of full ``width`` (pixels) at ``distance`` from its centre:
    1 at the centre, 0 from width / 2 on (Cycles' default pixel filter shape)."""
    t = 0.5 + np.asarray(distance, dtype=np.float64) / max(width, 1e-9)
    t = np.clip(t, 0.0, 1.0)
    value = (0.35875 - 0.48829 * np.cos(2.0 * np.pi * t) + 0.14128 * np.cos(4.0 * np.pi * t)
             - 0.01168 * np.cos(6.0 * np.pi * t))
    return np.where(t >= 1.0, 0.0, value)


def sample_offsets(count, filter_size=1.5):
    """(count, 2) sub-pixel offsets in pixels and (count,) weights summing to 1.

    Sample 0 is the pixel centre (so a one-sample render is the plain image, and the
    auxiliary passes read from it are unjittered). The others are placed as EEVEE places
    its render samples (eevee_temporal_sampling.c): a Halton (2, 3) point (low discrepancy:
    each added sample fills the largest gap) mapped on each axis through the inverse CDF of
    a Blackman-Harris window spanning -1..1, times Blender's Film > Filter Size (pixels), so
    every sample weighs the same. A Filter Size below half a pixel is widened to half a
    pixel: narrower would leave most of the pixel unsampled.
    """
    count = int(count)
    if count < 1:
        raise ValueError(f"anti-aliasing sample count must be at least 1, got {count}")
    radius = max(float(filter_size), 0.5)
    x = np.linspace(-1.0, 1.0, 513)
    density = blackman_harris(x, 2.0)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]))])
    cdf /= cdf[-1]
    offsets = np.zeros((count, 2))
    for index in range(1, count):
        for axis, base in enumerate((2, 3)):
            offsets[index, axis] = radius * float(np.interp(_radical_inverse(index, base),
                                                            cdf, x))
    return offsets, np.full(count, 1.0 / count)


def jittered(camera, offset_px):
    """``camera`` with its image moved by ``offset_px`` = (dx, dy) pixels: the projection is
    translated in clip space, so every pixel samples the scene that far from its centre."""
    dx, dy = offset_px
    # NOTE: adding a constant times w to clip x/y moves every pixel by the same amount
    # for perspective (w = -z) and orthographic (w = 1) cameras alike.
    clip_from_view = np.array(camera.clip_from_view, dtype=np.float64)
    clip_from_view[0] += 2.0 * dx / camera.width * clip_from_view[3]
    clip_from_view[1] += 2.0 * dy / camera.height * clip_from_view[3]
    return CameraView(camera.world_from_view, clip_from_view, camera.width, camera.height,
                      camera.clip_start, camera.clip_end)
