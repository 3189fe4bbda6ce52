"""Read-back of a final render's images from the GPU into numpy arrays.

Owns which image is read from which target (``READS``) and ``read_images``: one read per
image into a new buffer that the returned array views, without another copy; and the world
positions that tests ray-cast from, rebuilt from the view depth.
"""

import numpy as np

from ..core.camera import world_positions
from .passes import LIGHTING_PASS_TARGETS

# What each image is read from: (target, colour slot); the G-buffer's normal target is
# the pipeline's own, the other two the final target's ("combined" from wherever the
# anti-aliasing left it).
READS = {"combined": ("final", 0), "aux": ("final", 1), "normal": ("gbuffer", 1)}
# The light and colour passes' targets, in the final target's colour slots 2.. when a
# render asks for them (render/passes.py).
READS.update({name: ("final", 2 + slot) for slot, name in enumerate(LIGHTING_PASS_TARGETS)})


def read_images(snap, reads, final_fb, combined_fb, gbuffer_fb, with_positions=False):
    """``reads``: image name ("combined", "aux", "normal", a ``LIGHTING_PASS_TARGETS``
    name) -> channels (1..4, from the first). Returns name -> (H, W, channels) float32,
    bottom row first; with ``with_positions`` also "position" (xyz world position, w
    coverage; needs "aux" with 4 channels)."""
    import gpu
    width, height = snap.camera.width, snap.camera.height
    out = {}
    for name, channels in reads.items():
        source, slot = READS[name]
        fb = {"final": final_fb, "gbuffer": gbuffer_fb}[source]
        if name == "combined":
            fb, slot = combined_fb, 0
        buffer = gpu.types.Buffer('FLOAT', width * height * channels)
        with fb.bind():
            fb.read_color(0, 0, width, height, channels, slot, 'FLOAT', data=buffer)
        out[name] = np.frombuffer(buffer, dtype=np.float32).reshape(
            height, width, channels)
    if with_positions:
        # xyz = world position, w = coverage (1 on geometry), as tests ray-cast from it.
        aux = out["aux"]
        covered = aux[..., 3] > 0.5
        position = np.zeros_like(aux)
        position[..., :3] = world_positions(
            snap.camera, np.where(covered, aux[..., 2], 1.0).astype(np.float64))
        position[..., :3] *= covered[..., None]
        position[..., 3] = covered
        out["position"] = position
    return out


def read_target(framebuffer, slot, width, height, channels):
    """Colour slot ``slot`` of ``framebuffer`` as a (H, W, channels) float32 array, bottom
    row first (the Cryptomatte IDs of each sample)."""
    import gpu
    buffer = gpu.types.Buffer('FLOAT', width * height * channels)
    with framebuffer.bind():
        framebuffer.read_color(0, 0, width, height, channels, slot, 'FLOAT', data=buffer)
    return np.frombuffer(buffer, dtype=np.float32).reshape(height, width, channels)
