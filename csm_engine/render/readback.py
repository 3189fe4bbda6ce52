"""Read-back of a final render's images from the GPU into numpy arrays.

Owns which image is read from which target (``READS``) and ``read_images``: one read per
image into a buffer that the returned array views, without another copy; ``ReadbackMemory``,
the memory a caller that is done with the images before the next render lets them reuse;
and the world positions that tests ray-cast from, rebuilt from the view depth.
"""

import numpy as np

from ..core.camera import world_positions
from .passes import LIGHTING_PASS_TARGETS

# What each image is read from: (target, colour slot); the G-buffer's normal target is
# the pipeline's own, the other two the final target's ("combined" from wherever the
# anti-aliasing left it).
READS = {"combined": ("final", 0), "aux": ("final", 1), "normal": ("normals", 0)}
# The light and colour passes' targets, in the final target's colour slots 2.. when a
# render asks for them (render/passes.py).
READS.update({name: ("final", 2 + slot) for slot, name in enumerate(LIGHTING_PASS_TARGETS)})


class ReadbackMemory:
    """Float32 memory kept from one final render to the next, by name: read-back buffers
    and the contiguous copies Blender's render result is filled from.

    NOTE: a new 4-15 MB block per image and frame cost 5-15 ms a frame here (1280x720):
    glibc maps blocks that large fresh from the kernel, or hands them back once freed, so
    every 4 KiB page faults on its first write; memory written by the last frame costs
    nothing. Only for a caller that is done with the images before the next render."""

    def __init__(self):
        self._blocks = {}

    def buffer(self, name, count):
        """A ``gpu.types.Buffer`` of ``count`` floats (read_color writes only into one)."""
        import gpu
        block = self._blocks.get(name)
        if block is None or len(block) != count or not isinstance(block, gpu.types.Buffer):
            block = self._blocks[name] = gpu.types.Buffer('FLOAT', count)
        return block

    def array(self, name, shape):
        """A C-contiguous float32 numpy array of ``shape``."""
        block = self._blocks.get(name)
        if not isinstance(block, np.ndarray) or block.shape != tuple(shape):
            block = self._blocks[name] = np.empty(shape, dtype=np.float32)
        return block

    def contiguous(self, name, pixels):
        """``pixels`` itself when C-contiguous float32, else a copy in this memory."""
        if pixels.dtype == np.float32 and pixels.flags.c_contiguous:
            return pixels
        copy = self.array(name, pixels.shape)
        np.copyto(copy, pixels)
        return copy

    def clear(self):
        self._blocks = {}


def read_images(snap, reads, final_fb, combined_fb, normals_fb, with_positions=False,
                memory=None):
    """``reads``: image name ("combined", "aux", "normal", a ``LIGHTING_PASS_TARGETS``
    name) -> channels (1..4, from the first). Returns name -> (H, W, channels) float32,
    bottom row first; with ``with_positions`` also "position" (xyz world position, w
    coverage; needs "aux" with 4 channels). With ``memory`` (``ReadbackMemory``) the
    arrays view its buffers, valid until the next read into it."""
    import gpu
    width, height = snap.camera.width, snap.camera.height
    out = {}
    for name, channels in reads.items():
        source, slot = READS[name]
        fb = {"final": final_fb, "normals": normals_fb}[source]
        if name == "combined":
            fb, slot = combined_fb, 0
        count = width * height * channels
        buffer = gpu.types.Buffer('FLOAT', count) if memory is None \
            else memory.buffer(name, count)
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


def unpack_normals(targets, gbuffer):
    """The world normals of ``gbuffer`` (``gbuffer.GBuffer``, octahedral in its surface
    target, ``gbuffer_layout.glsl``) unpacked on the GPU into a float target (xyz, 0 on
    the background); returns its framebuffer, whose colour slot 0 ``read_images`` reads
    as "normal"."""
    # Unpacked where the packing is written (gbuffer_layout.glsl), not again in numpy.
    width, height = gbuffer.surface.width, gbuffer.surface.height
    texture = targets.texture("normals_unpacked", (width, height), 'RGBA32F')
    fb = targets.framebuffer("normals_unpacked", colors=(texture,))
    targets.fullscreen_pass("gbuffer_normals", fb, width, height,
                            (("gbuffer_surface_target", gbuffer.surface),
                             ("gbuffer_depth", gbuffer.view_depth)))
    return fb


def read_target(framebuffer, slot, width, height, channels):
    """Colour slot ``slot`` of ``framebuffer`` as a (H, W, channels) float32 array, bottom
    row first (the Cryptomatte IDs of each sample)."""
    import gpu
    buffer = gpu.types.Buffer('FLOAT', width * height * channels)
    with framebuffer.bind():
        framebuffer.read_color(0, 0, width, height, channels, slot, 'FLOAT', data=buffer)
    return np.frombuffer(buffer, dtype=np.float32).reshape(height, width, channels)
