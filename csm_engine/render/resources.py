"""GPU resources of the passes: textures, framebuffers, and what the textures hold.

Owns ``RenderResources`` (textures by name plus the ``FrameCache`` saying what they hold;
long-lived: final renders share one across renders, since textures, unlike framebuffers,
may be shared between GPU contexts), ``Targets`` (one GPU context's view of them: its
framebuffers, the full-screen triangle, the frame uniform block, a white texture, and the
one door every draw and clear goes through) and ``RenderTargetError``.
"""

from dataclasses import dataclass, fields

import numpy as np

from . import shaders

_BYTES_PER_TEXEL = {'RGBA32F': 16, 'RGBA16F': 8, 'R32F': 4, 'DEPTH_COMPONENT32F': 4,
                    'RGBA8': 4, 'R8': 1, 'RG32F': 8}


class RenderTargetError(Exception):
    """A render target or shadow map could not be allocated; the message says which and
    how large."""


@dataclass
class HeldGBuffer:
    """The G-buffer the targets hold: the textures drawn into, and what was drawn
    (``gbuffer.GBufferContents``)."""
    targets: tuple
    contents: tuple


@dataclass
class HeldAmbientOcclusion:
    """The AO texture of the held G-buffer and the inputs it was made with."""
    texture: object
    inputs: tuple


@dataclass
class AtlasTiles:
    """What each tile of one atlas texture holds: (origin, resolution) -> the
    ``shadow_atlas.TileSignature`` it was drawn with."""
    atlas: object
    tiles: dict


@dataclass
class NearestBlocks:
    """The atlas texture ``blocker_search`` reduced, and the texture it reduced it to."""
    atlas: object
    texture: object


@dataclass
class PartialMarks:
    """The atlas's partial-caster mask texture, and whether it may hold marks (a texture
    new to us holds anything)."""
    texture: object
    may_hold_marks: bool


@dataclass
class FrameCache:
    """What the textures of a ``RenderResources`` hold, so that a pass whose inputs are
    those it last drew with is not drawn again. Every record names the texture it is about,
    so a reallocated texture is never taken for the one recorded. A pass forgets its record
    before drawing: if drawing raises, the next frame draws again."""
    gbuffer: HeldGBuffer = None
    ambient_occlusion: HeldAmbientOcclusion = None
    depth_blocks: object = None      # visible_depth's blocks of the held G-buffer
    atlas_tiles: AtlasTiles = None
    partial_marks: PartialMarks = None
    nearest_blocks: NearestBlocks = None

    def forget(self):
        """Draw every pass again at the next frame, as for a frame that changed all."""
        for f in fields(self):
            setattr(self, f.name, None)

    def forget_gbuffer(self):
        """The G-buffer is being redrawn: forget it and what was computed from it."""
        self.gbuffer = self.ambient_occlusion = self.depth_blocks = None


class RenderResources:
    """Textures (name -> ((name, size, format), GPUTexture)) and what they hold."""

    def __init__(self):
        self.textures = {}
        self.frame_cache = FrameCache()
        # The Exact filter's volume geometry (``shadow_volumes.ShadowVolumes``), kept with
        # the textures so that final renders, one Pipeline each, share it too.
        self.shadow_volumes = None

    def clear(self):
        """Drop every texture (and so what they held)."""
        self.textures.clear()
        self.frame_cache.forget()
        self.shadow_volumes = None


class Targets:
    """One GPU context's framebuffers over shared ``RenderResources``, and the small GPU
    objects every pass uses. Framebuffers belong to the context that made them, so a
    ``Targets`` is never shared between contexts."""

    def __init__(self, resources=None):
        self.resources = RenderResources() if resources is None else resources
        self._framebuffers = {}
        self._fullscreen = None
        self._white = None
        self._bsdf_lut = None
        self._ubo = None
        self.zeroed_emission = None     # the emission texture last cleared to zero
        self.zeroed_coat = None         # the coat texture last cleared to zero
        # Wait for the GPU after each pass, so its time is its own (slower).
        self.profile = False
        # Benchmark only: every draw and clear is skipped (see ``call``), so a frame's
        # Python can be timed alone; nothing drawn is recorded as held.
        self.benchmark_skip_gpu_calls = False

    @property
    def frame_cache(self):
        return self.resources.frame_cache

    def texture(self, name, size, fmt):
        """The texture ``name``, (re)allocated when its size or format changed."""
        import gpu
        textures = self.resources.textures
        key = (name, size, fmt)
        texture = textures.get(name)
        if texture is None or texture[0] != key:
            self._framebuffers = {k: v for k, v in self._framebuffers.items()
                                  if name not in k}
            textures.pop(name, None)
            try:
                created = gpu.types.GPUTexture(size, format=fmt)
            except Exception as error:
                megabytes = size[0] * size[1] * _BYTES_PER_TEXEL.get(fmt, 4) / 2**20
                raise RenderTargetError(
                    f"could not allocate the {size[0]}x{size[1]} {name} target "
                    f"({megabytes:,.0f} MB): {' '.join(str(error).split())}") from None
            textures[name] = (key, created)
        return textures[name][1]

    def framebuffer(self, name, depth=None, colors=()):
        import gpu
        key = (name, id(depth), tuple(id(c) for c in colors))
        fb = self._framebuffers.get(key)
        if fb is None:
            fb = gpu.types.GPUFrameBuffer(depth_slot=depth, color_slots=colors)
            self._framebuffers = {k: v for k, v in self._framebuffers.items() if k[0] != name}
            self._framebuffers[key] = fb
        return fb

    def gbuffer_depth(self, width, height):
        """The G-buffer's depth buffer; attached to a lighting target too (``lighting``)."""
        return self.texture("depth", (width, height), 'DEPTH_COMPONENT32F')

    def fullscreen_batch(self):
        import gpu
        if self._fullscreen is None:
            fmt = gpu.types.GPUVertFormat()
            fmt.attr_add(id="pos", comp_type='F32', len=2, fetch_mode='FLOAT')
            vbo = gpu.types.GPUVertBuf(fmt, 3)
            vbo.attr_fill("pos", np.array([[-1, -1], [3, -1], [-1, 3]], dtype=np.float32))
            self._fullscreen = gpu.types.GPUBatch(type='TRIS', buf=vbo)
        return self._fullscreen

    def frame_ubo(self, frame_data):
        """The frame uniform block, holding ``frame_data`` (``shadow_plan.pack_frame``)."""
        import gpu
        if self._ubo is None:
            self._ubo = gpu.types.GPUUniformBuf(frame_data.tobytes())
        else:
            self._ubo.update(frame_data.tobytes())
        return self._ubo

    def white(self):
        import gpu
        if self._white is None:
            self._white = gpu.types.GPUTexture(
                (1, 1), format='RGBA8',
                data=gpu.types.Buffer('FLOAT', 4, [1.0, 1.0, 1.0, 1.0]))
        return self._white

    def bsdf_lut(self):
        """The Principled BSDF's tables (``core/bsdf_tables.py``) as one float texture."""
        import gpu
        if self._bsdf_lut is None:
            from ..core import bsdf_tables
            rows = bsdf_tables.lut_texture_rows()
            self._bsdf_lut = gpu.types.GPUTexture(
                (rows.shape[1], rows.shape[0]), format='RGBA32F',
                data=gpu.types.Buffer('FLOAT', rows.size, rows.ravel().tolist()))
        return self._bsdf_lut

    def call(self, call, *args, **kwargs):
        """Every draw and clear of a frame goes through here, so that the benchmark can
        time the frame's Python alone (``benchmark_skip_gpu_calls``): on llvmpipe a draw
        call does the vertex work on the calling thread and its rasteriser threads compete
        with Python for the cores, so a normal frame cannot tell Python and GPU time
        apart."""
        if not self.benchmark_skip_gpu_calls:
            call(*args, **kwargs)

    @property
    def records(self):
        """Whether what this frame draws is recorded as held (not in the benchmark's
        Python-only frames, which draw nothing)."""
        return not self.benchmark_skip_gpu_calls

    def fullscreen_pass(self, program, target_fb, width, height, samplers, floats=(),
                        blocks=(), depth=None):
        """One full-screen triangle of ``program`` into ``target_fb``, without blending
        (the blend state found is put back). ``blocks``: (name, uniform buffer) pairs.
        ``depth``: for passes that split the screen by a depth target in ``target_fb``
        (llvmpipe skips the shading of pixel blocks failing an early depth test, never an
        ``if``): "MARK" writes the program's gl_FragDepth everywhere; "MASKED" shades
        only where the mark wrote below 1 (the triangle lies at depth 1); None, no depth
        test."""
        import gpu
        shader = shaders.LIBRARY.get(program)
        blend = gpu.state.blend_get() if hasattr(gpu.state, "blend_get") else 'NONE'
        with target_fb.bind():
            gpu.state.viewport_set(0, 0, width, height)
            if depth == "MARK":
                gpu.state.depth_test_set('ALWAYS')
                gpu.state.depth_mask_set(True)
            elif depth == "MASKED":
                gpu.state.depth_test_set('GREATER')
                gpu.state.depth_mask_set(False)
            else:
                gpu.state.depth_test_set('NONE')
            gpu.state.blend_set('NONE')
            shader.bind()
            for name, block in blocks:
                shader.uniform_block(name, block)
            for name, texture in samplers:
                shader.uniform_sampler(name, texture)
            for name, value in floats:
                shader.uniform_float(name, value)
            self.call(self.fullscreen_batch().draw, shader)
            gpu.state.depth_test_set('NONE')
            gpu.state.depth_mask_set(False)
            gpu.state.blend_set(blend)
            self.wait_when_profiling(target_fb, depth_only=depth == "MARK")

    def wait_when_profiling(self, fb, depth_only=False):
        """When profiling, wait until the GPU has drawn into ``fb`` (a 1-pixel read), so
        a pass's time is its own. ``depth_only``: ``fb`` has no colour target, so its depth
        is read (a colour read of it would wait for nothing)."""
        if not self.profile:
            return
        with fb.bind():
            if depth_only:
                fb.read_depth(0, 0, 1, 1)
            else:
                fb.read_color(0, 0, 1, 1, 4, 0, 'FLOAT')
