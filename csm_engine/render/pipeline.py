"""The deferred pipeline: shadow atlas, G-buffer, lighting and debug views, for any target.

Owns every GPU pass and the textures they render into. Input is a ``FrameSnapshot``
(plain data) plus a ``MeshCache``; output is pixels in a target framebuffer: the viewport's
own (``view_draw``) or an offscreen one that ``render()`` reads back. Both go through
``Pipeline.draw``, so the viewport and a final render of the same camera agree.

Passes per frame:
1. shadow: one depth-only tile per cascade (and per shadowed spot or point light face) in
   one atlas, and beside it a one-byte partial-caster mask that the alpha-hashed casters
   mark (PCF Sharpen leaves their partial shadows alone);
2. G-buffer: albedo+specular, normal+shininess, view depth (0 = background), the
   triangle's own normal+the object's Shadow Terminator Geometry Offset, emission+
   metallic, depth (materials: one uniform block each, core/material_layout.py); world
   positions are rebuilt from view depth in the lighting pass (``world_positions`` here);
   then, when on, ambient occlusion: a half-resolution horizon search and a depth-aware
   blur back to full resolution (``ao_frag.glsl``);
3. lighting: a full-screen pass reading the G-buffer, the atlas and the AO
   (``lighting_frag.glsl``);
4. overlays: frozen cascade boxes.

Framebuffers belong to the GPU context that made them, so a ``Pipeline`` is owned by one
engine instance (one viewport, or one final render) and is never shared.
"""

import time

import numpy as np

from ..core import cascades
from ..core.camera import world_positions
from ..core.shadow_plan import (CASCADE_LINE_COLORS, depth_blocks_from_reduction,
                                front_to_back, gbuffer_plan, instance_bounds,
                                layout_atlas, pack_frame, plan_shadows)
from ..core.frame_layout import FRAME_LAYOUT
from ..core.view_state import ShadowViewState
from ..core.material_layout import pack_material
from . import shaders
from .gpu_mesh import MaterialInfo
from .result import RenderResult



def _column_major(matrix):
    return np.asarray(matrix, dtype=np.float32).T.ravel().tolist()


def _column_major_stack(matrices):
    """(N, 4, 4) matrices -> N lists of 16 floats in GLSL's column-major order."""
    matrices = np.asarray(matrices, dtype=np.float32)
    return matrices.transpose(0, 2, 1).reshape(len(matrices), 16).tolist()


# Shadow tiles drawn and skipped in this process (a tile is skipped when its light matrix,
# casters and their geometry are those it already holds); read by tests and the benchmark.
SHADOW_TILES = {"drawn": 0, "skipped": 0}
# G-buffers drawn, and kept because the frame before drew the same (tests read this).
GBUFFERS = {"drawn": 0, "kept": 0}

_BYTES_PER_TEXEL = {'RGBA32F': 16, 'RGBA16F': 8, 'R32F': 4, 'DEPTH_COMPONENT32F': 4,
                    'RGBA8': 4, 'R8': 1}


# NOTE: a stabilized cascade's x/y (texel-snapped) do not move with a small camera move, but
# its depth range follows the camera by a little: a tile is kept when the depth row of its
# light matrix moved by at most this (clip units, ~1e-4 mm over a 100 m range), far below
# any depth bias, and compared with the matrix it was drawn with, so it cannot drift.
TILE_DEPTH_TOLERANCE = 1e-6


def _same_tile(held, signature):
    """Whether a tile drawn with ``held`` holds what ``signature`` would draw."""
    if held is None or held[:3] != signature[:3] or held[4:] != signature[4:]:
        return False
    a, b = held[3], signature[3]
    # Rows 0, 1 and 3 the same bytes (a -0.0 for a 0.0 only redraws the tile), row 2
    # within the tolerance; bytes of slices cost less than numpy's comparisons here.
    return a[:2].tobytes() == b[:2].tobytes() and a[3].tobytes() == b[3].tobytes() and \
        float(np.abs(a[2] - b[2]).max()) <= TILE_DEPTH_TOLERANCE


# What the G-buffer programs read of the frame block (gbuffer_vert/frag.glsl), and what
# the AO passes read besides the G-buffer (ao_frag.glsl).
_GBUFFER_FRAME_FIELDS = ("clip_from_world", "camera_position", "camera_forward",
                         "sample_index")
_AO_FRAME_FIELDS = ("ao_enabled", "ao_distance", "ao_strength", "ao_pixels_per_unit",
                    "ao_view_ray", "is_perspective", "viewport_size", "view_from_world")


def _programs_key():
    """Which compiled programs a frame draws with (F5 replaces them), compiled now if they
    were not yet, so a record made with it names the programs that drew it."""
    library = shaders.LIBRARY
    library.get("gbuffer")
    return id(library), library.generation


def _same_textures(cache, textures):
    """Whether the mesh cache still gives each image of ``textures`` ((image, GPU texture
    or False) pairs) the texture it gave when they were recorded."""
    try:
        return all(cache.textures.get(image.name) is texture for image, texture in textures)
    except ReferenceError:      # an image removed since
        return False


class _InstanceArrays:
    """Per-instance arrays of one frame, kept while the instances are the same (viewport
    redraws that only move the view): world matrices (N, 4, 4), the same as GLSL lists,
    which are mirrored, the world AABBs (``instance_bounds``) and, for the last sun
    rotation culled against, the boxes in its frame (``cascades.boxes_in_light_frame``)."""
    __slots__ = ("keys", "meshes", "matrix_bytes", "world_from_objects",
                 "world_from_objects_gl", "mirrored", "bounds_lo_hi", "bounds_checked",
                 "light_frame_boxes")

    def __init__(self, snap, cache, keys, meshes, world_from_objects):
        self.keys, self.meshes = keys, meshes
        self.world_from_objects = world_from_objects
        self.matrix_bytes = world_from_objects.tobytes()
        self.world_from_objects_gl = _column_major_stack(world_from_objects)
        # Negative scale turns a triangle's winding around: back-face culling of a mirrored
        # instance culls its front-wound faces.
        self.mirrored = np.linalg.det(world_from_objects[:, :3, :3]) < 0.0
        self.bounds_lo_hi = instance_bounds(snap.instances, cache.meshes)
        # Checked once here, not again for every cascade's culling (``_cull``).
        self.bounds_checked = self.bounds_lo_hi is not None and \
            cascades.boxes_are_valid(*self.bounds_lo_hi)
        self.light_frame_boxes = (None, None)     # (rotation bytes, boxes in its frame)

    def holds(self, keys, meshes, world_from_objects):
        """Whether these arrays are those of ``keys`` drawn with ``meshes`` (GPUMesh or
        None per instance: a re-upload is a new object, so new bounds) at these matrices."""
        return (keys == self.keys and len(meshes) == len(self.meshes)
                and all(a is b for a, b in zip(meshes, self.meshes))
                and world_from_objects.tobytes() == self.matrix_bytes)


# The G-buffer programs' material samplers, in _DrawMaterial.textures order.
_MATERIAL_SAMPLERS = ("base_color_texture", "normal_texture", "emission_texture",
                      "surface_texture")
# Slots without a material draw as Blender's default grey.
_DEFAULT_MATERIAL = MaterialInfo()


class _DrawMaterial:
    """One material slot ready to draw: its uniform buffer, its four textures (white where
    there is none, see _MATERIAL_SAMPLERS), alpha and shadow modes, culling, and the keys a
    shadow tile and a kept G-buffer record of it."""
    __slots__ = ("block", "textures", "textured", "writes_emission", "alpha_mode",
                 "shadow_mode", "backface_culling", "backface_culling_shadow", "shadow_key",
                 "gbuffer_key")

    def __init__(self, block, textures, textured, writes_emission, alpha_mode, shadow_mode,
                 backface_culling, backface_culling_shadow, shadow_key, gbuffer_key):
        self.block, self.textures, self.textured = block, textures, textured
        self.writes_emission = writes_emission
        self.alpha_mode, self.shadow_mode = alpha_mode, shadow_mode
        self.backface_culling = backface_culling
        self.backface_culling_shadow = backface_culling_shadow
        self.shadow_key = shadow_key
        self.gbuffer_key = gbuffer_key


# The G-buffer's draws in order: (program, slot of the _draw_items entry, whether the mesh
# has tangents, None: either, whether the program samples the material's textures).
# NOTE: llvmpipe samples a texture even where the shader's `if` skips it, so materials
# without images use a program that has no texture reads (about a third of the G-buffer's
# time here); it is given no textures either (four binds per material a frame).
_GBUFFER_PASSES = (("gbuffer_untextured", 5, None, False), ("gbuffer", 0, False, True),
                   ("gbuffer_tangent", 0, True, True), ("gbuffer_masked", 1, False, True),
                   ("gbuffer_masked_tangent", 1, True, True))

# The lighting program of each Shadow Filter setting (shaders.py builds one per filter).
LIGHTING_PROGRAMS = {"HARD": "lighting_hard", "PCF": "lighting", "SOFT": "lighting_soft"}


def lighting_program(snap):
    """The lighting program for this frame: its Shadow Filter's, with the point- and
    spot-light loops only when the scene has such lights and the debug views only when one
    is shown
    (shaders.py: llvmpipe pays for code a frame does not use)."""
    settings = snap.settings
    debug = getattr(settings, "debug_view", "NONE") != "NONE" or \
        bool(getattr(settings, "debug_inset", False))
    point_shadows = bool(snap.points) and snap.points[0].casts_shadow
    return (LIGHTING_PROGRAMS.get(getattr(settings, "shadow_filter", "PCF"), "lighting") +
            ("_points" if snap.points else "") +
            ("_point_shadows" if point_shadows else "") + ("_spots" if snap.spots else "") +
            ("_debug" if debug else ""))


def _writes_emission(items):
    """Whether any camera draw of ``items`` (see Pipeline._draw_items) has emission or
    metallic, i.e. needs the G-buffer's emission target. Instances of one mesh share their
    entry, so each entry is looked at once."""
    seen = set()
    for entry in items:
        if id(entry) in seen:
            continue
        seen.add(id(entry))
        for draws in (entry[0], entry[1], entry[5]):
            for _batch, material in draws:
                if material.writes_emission:
                    return True
    return False


class _DrawLists:
    """What the passes derive from one frame's draw items (``Pipeline._draw_items``), kept
    with them: the same items (``_kept_draw_items`` keeps them while meshes, materials and
    textures are the same) give the same answers. Per instance: whether each G-buffer
    pass of _GBUFFER_PASSES and each shadow program (opaque, alpha-masked) draws it."""
    __slots__ = ("items", "writes_emission", "gbuffer_masks", "shadow_masks", "partial_mask",
                 "signatures")

    def __init__(self, items):
        self.items = items
        self.writes_emission = _writes_emission(items)
        self.gbuffer_masks = tuple(
            np.array([bool(entry[slot]) and (tangents is None or entry[4] == tangents)
                      for entry in items], dtype=bool)
            for _program, slot, tangents, _textured in _GBUFFER_PASSES)
        self.shadow_masks = tuple(np.array([bool(entry[2 + masked]) for entry in items],
                                           dtype=bool) for masked in (0, 1))
        # Which instances have an alpha-hashed shadow material (the atlas's partial-caster
        # mask draws only those).
        self.partial_mask = np.array([any(material.shadow_mode == 'HASHED'
                                          for _batch, material in entry[3])
                                      for entry in items], dtype=bool)
        self.signatures = None      # Pipeline._caster_signatures, asked for once


class RenderTargetError(Exception):
    """A render target or shadow map could not be allocated; the message says which and
    how large."""


class Pipeline:
    """GPU resources and passes for one engine instance (one GPU context)."""

    def __init__(self, textures=None, view_state=None):
        # Textures may be shared between GPU contexts (framebuffers may not), so final
        # renders pass one long-lived dict and skip reallocating ~80 MB of targets per frame.
        self._textures = {} if textures is None else textures
        self._framebuffers = {}
        self._fullscreen = None
        self._white = None
        self.warnings = []
        self.timings = {}
        self.profile = False
        self.skip_gpu_calls = False   # benchmark only: a frame of Python without the GPU
        self.gbuffer_fb = None      # kept after draw() for the final render's read-back
        self._combined_fb = None    # what holds the final Combined image, when not "final"
        self.ao_fb = None           # the half-resolution AO of the last frame (None: AO off)
        self._zeroed_emission = None   # the emission texture last cleared to zero
        self.gbuffer_kept = False   # this frame's G-buffer is the frame before's (see draw)
        self.shadow_tiles = {"drawn": 0, "skipped": 0}   # of the last frame
        self._held_lists = None     # _DrawLists of the last frame's draw items
        self._held_instances = None   # _InstanceArrays of the last frame
        self._held_draws = None     # the last frame's draw items and what they came from
        self._held_signatures = {}  # instance key -> (draw-list entry, caster signature)
        self._depth_pairs = None    # the last Fit to Visible Depth read-back (benchmark)
        # What planning carries from frame to frame for this view (frozen cascades,
        # hysteresis); a final render passes its own long-lived one.
        self.view_state = ShadowViewState() if view_state is None else view_state

    # -- resources ---------------------------------------------------------------------
    def _texture(self, name, size, fmt):
        import gpu
        key = (name, size, fmt)
        texture = self._textures.get(name)
        if texture is None or texture[0] != key:
            self._framebuffers = {k: v for k, v in self._framebuffers.items()
                                  if name not in k}
            self._textures.pop(name, None)
            try:
                created = gpu.types.GPUTexture(size, format=fmt)
            except Exception as error:
                megabytes = size[0] * size[1] * _BYTES_PER_TEXEL.get(fmt, 4) / 2**20
                raise RenderTargetError(
                    f"could not allocate the {size[0]}x{size[1]} {name} target "
                    f"({megabytes:,.0f} MB): {' '.join(str(error).split())}") from None
            self._textures[name] = (key, created)
        return self._textures[name][1]

    def _framebuffer(self, name, depth=None, colors=()):
        import gpu
        key = (name, id(depth), tuple(id(c) for c in colors))
        fb = self._framebuffers.get(key)
        if fb is None:
            fb = gpu.types.GPUFrameBuffer(depth_slot=depth, color_slots=colors)
            self._framebuffers = {k: v for k, v in self._framebuffers.items() if k[0] != name}
            self._framebuffers[key] = fb
        return fb

    def gbuffer_depth_texture(self, width, height):
        """The G-buffer's depth buffer; attached to a lighting target too (see draw)."""
        return self._texture("depth", (width, height), 'DEPTH_COMPONENT32F')

    def _fullscreen_batch(self):
        import gpu
        if self._fullscreen is None:
            fmt = gpu.types.GPUVertFormat()
            fmt.attr_add(id="pos", comp_type='F32', len=2, fetch_mode='FLOAT')
            vbo = gpu.types.GPUVertBuf(fmt, 3)
            vbo.attr_fill("pos", np.array([[-1, -1], [3, -1], [-1, 3]], dtype=np.float32))
            self._fullscreen = gpu.types.GPUBatch(type='TRIS', buf=vbo)
        return self._fullscreen

    def _frame_ubo(self, frame_data):
        import gpu
        if getattr(self, "_ubo", None) is None:
            self._ubo = gpu.types.GPUUniformBuf(frame_data.tobytes())
        else:
            self._ubo.update(frame_data.tobytes())
        return self._ubo

    def _white_texture(self):
        import gpu
        if self._white is None:
            self._white = gpu.types.GPUTexture(
                (1, 1), format='RGBA8',
                data=gpu.types.Buffer('FLOAT', 4, [1.0, 1.0, 1.0, 1.0]))
        return self._white

    def _atlas(self, plan):
        """The shadow atlas (depth) and its partial-caster mask (1 where an alpha-hashed
        caster lies in front of what a texel holds: its shadow is the share of texels the
        filter finds, which PCF Sharpen must leave alone, see ``_draw_partial_mask``); on
        allocation failure, halve resolutions and say so."""
        while True:
            size = layout_atlas(plan.tiles)
            try:
                return (self._texture("atlas", size, 'DEPTH_COMPONENT32F'),
                        self._texture("atlas_partial", size, 'R8'))
            except Exception as error:
                if all(t.resolution <= 64 for t in plan.tiles):
                    raise
                message = (f"shadow atlas {size[0]}x{size[1]} could not be allocated "
                           f"({error}); halving shadow resolutions")
                if message not in self.warnings:
                    self.warnings.append(message)
                for tile in plan.tiles:
                    if tile.resolution > 64:
                        tile.texel_world *= 2.0
                        if tile.texel_world_xy is not None:
                            tile.texel_world_xy = tuple(2.0 * t for t in tile.texel_world_xy)
                    tile.resolution = max(tile.resolution // 2, 64)

    def _sync(self, fb, name, start):
        """When profiling, wait for the GPU (a 1-pixel read) and record the pass time."""
        if self.profile:
            with fb.bind():
                fb.read_color(0, 0, 1, 1, 4, 0, 'FLOAT')
            self.timings[name] = time.perf_counter() - start
        return time.perf_counter()

    # -- passes ------------------------------------------------------------------------
    def draw(self, snap, cache, target_fb=None, width=None, height=None, plan=None,
             overlays=True, depth_tested=False):
        """Render one frame into ``target_fb`` (None: the currently bound framebuffer).
        ``depth_tested``: ``target_fb`` has the G-buffer's depth texture attached
        (``gbuffer_depth_texture``), so lighting can skip the background.
        ``plan``: a shadow plan to reuse (the jittered samples of one final render share
        the plan of its unjittered camera, so their shadow maps are drawn once).
        ``overlays``: draw the frozen cascade boxes; anti-aliased frames draw them after
        the anti-aliasing instead (``draw_overlays``), so 1-pixel lines stay crisp."""
        import gpu
        # Programs replaced by F5 or dropped with a library are freed here, in the context
        # that draws, never where they were retired (see the NOTE in shaders.py).
        shaders.release_retired()
        library = shaders.LIBRARY
        width = width or snap.camera.width
        height = height or snap.camera.height
        start = time.perf_counter()
        self.timings = {}

        # World AABB per instance: caster culling per cascade, and the scene's bounds for the
        # automatic occluder margin.
        instances = self._instance_arrays(snap, cache)
        bounds_lo_hi = instances.bounds_lo_hi
        bounds = None if bounds_lo_hi is None else \
            (bounds_lo_hi[0].min(axis=0), bounds_lo_hi[1].max(axis=0))
        # Fit to Visible Depth needs the G-buffer's depths before it can plan; it draws the
        # G-buffer with a plan without cascades and a frame block without the plan's
        # fields (the G-buffer reads only the camera from it).
        fit_to_visible = plan is None and bool(getattr(snap.settings, "fit_to_visible", False))
        if plan is None:
            plan = gbuffer_plan(snap, bounds, self.view_state) if fit_to_visible else \
                plan_shadows(snap, bounds, view_state=self.view_state)
        self.warnings.extend(w for w in snap.warnings + plan.warnings if w not in self.warnings)
        atlas, partial = (None, None) if fit_to_visible else self._atlas(plan)
        frame_data = pack_frame(snap, None if fit_to_visible else plan)
        frame_ubo = self._frame_ubo(frame_data)
        self.timings["python_setup"] = time.perf_counter() - start

        # Once per frame: each instance's batches, opaque and alpha-masked apart, with
        # their material inputs, and its matrix; the passes below only index into these.
        white = self._white_texture()
        items = self._kept_draw_items(snap, cache, white)
        lists = self._held_lists
        if lists is None or lists.items is not items:
            lists = self._held_lists = _DrawLists(items)
        world_from_objects = instances.world_from_objects
        world_from_objects_gl = instances.world_from_objects_gl
        mirrored = instances.mirrored

        def shadow_pass(t):
            """1. Shadow atlas: only tiles whose contents would change are cleared and
            drawn."""
            t = time.perf_counter()
            atlas_fb = self._framebuffer("atlas", depth=atlas)
            held = self._atlas_contents(atlas)
            # Blender 3.4's gpu.state has no scissor: there the whole atlas is cleared and drawn.
            can_clear_tile = hasattr(gpu.state, "scissor_set")
            if lists.signatures is None:
                lists.signatures = self._caster_signatures(snap, cache, items)
            signatures = lists.signatures
            cull_front = bool(snap.settings.cull_front_faces)
            stale = []
            casts_shadow = np.fromiter((i.casts_shadow for i in snap.instances), dtype=bool,
                                       count=len(snap.instances))
            for tile in plan.tiles:
                visible = np.asarray(self._cull(snap.instances, bounds_lo_hi, tile), dtype=np.int64)
                visible = visible[casts_shadow[visible]]
                clip_from_world = np.asarray(tile.clip_from_world, dtype=np.float64)
                signature = (tuple(tile.origin), tile.resolution, cull_front,
                             clip_from_world, world_from_objects[visible].tobytes(),
                             tuple(map(signatures.__getitem__, visible.tolist())))
                key = (tuple(tile.origin), tile.resolution)
                if can_clear_tile and None not in signature[5] and \
                        _same_tile(held.get(key), signature):
                    continue
                stale.append((tile, visible, key, signature))
            if not self.skip_gpu_calls:
                SHADOW_TILES["skipped"] += len(plan.tiles) - len(stale)
                SHADOW_TILES["drawn"] += len(stale)
            self.shadow_tiles = {"drawn": len(stale), "skipped": len(plan.tiles) - len(stale)}
            with atlas_fb.bind():
                if not can_clear_tile:
                    self._gpu_call(atlas_fb.clear, depth=1.0)
                gpu.state.depth_test_set('LESS_EQUAL')
                gpu.state.depth_mask_set(True)
                gpu.state.face_culling_set('FRONT' if cull_front else 'NONE')
                for tile, visible, key, signature in stale:
                    self._begin_tile(atlas_fb, tile, dict(depth=1.0) if can_clear_tile else None)
                    if not self.skip_gpu_calls:
                        # Forget the tile's contents while it is redrawn: if drawing raises,
                        # the next frame draws it again.
                        held.pop(key, None)
                    if len(visible):
                        self._draw_casters(library, items, lists.shadow_masks,
                                           world_from_objects, tile, visible, mirrored,
                                           cull_front)
                    if not self.skip_gpu_calls:
                        held[key] = signature
                gpu.state.face_culling_set('NONE')
            self._draw_partial_mask(library, items, lists, atlas, partial, stale,
                                    world_from_objects, mirrored, cull_front, can_clear_tile)
            t = self._sync(atlas_fb, "shadow", t)
            return t

        def gbuffer_pass(t):
            """2. G-buffer."""
            albedo = self._texture("albedo", (width, height), 'RGBA16F')
            normal = self._texture("normal", (width, height), 'RGBA16F')
            view_depth = self._texture("view_depth", (width, height), 'R32F')
            depth = self.gbuffer_depth_texture(width, height)
            emission = self._texture("emission", (width, height), 'RGBA16F')
            facet = self._texture("facet", (width, height), 'RGBA16F')
            # Emission and metallic have a target only in frames that draw some: without
            # it each fragment writes a sixth less (llvmpipe: ~15 % of the G-buffer), and
            # the lighting pass reads an emission texture kept at zero.
            if lists.writes_emission:
                gbuffer_fb = self._framebuffer("gbuffer", depth=depth,
                                               colors=(albedo, normal, view_depth, facet,
                                                       emission))
                self._zeroed_emission = None
            else:
                gbuffer_fb = self._framebuffer("gbuffer_no_emission", depth=depth,
                                               colors=(albedo, normal, view_depth, facet))
                if self._zeroed_emission is not emission:
                    emission_fb = self._framebuffer("emission_only", colors=(emission,))
                    with emission_fb.bind():
                        self._gpu_call(emission_fb.clear, color=(0.0, 0.0, 0.0, 0.0))
                    self._zeroed_emission = emission
            # Near to far, so the early depth test skips the shading of hidden fragments.
            order = np.asarray(front_to_back(snap, bounds_lo_hi), dtype=np.int64)
            order = order[np.fromiter((i.visible_camera for i in snap.instances), dtype=bool,
                                      count=len(snap.instances))[order]]
            terminator_offsets = np.fromiter((i.terminator_offset for i in snap.instances),
                                             dtype=np.float64, count=len(snap.instances))
            # A G-buffer that would come out the same as the one the targets hold is not
            # drawn again (F12 after a shadow or light setting changed; an unchanged
            # re-render), nor is its AO (see _ambient_occlusion).
            targets = (albedo, normal, view_depth, emission, depth, facet)
            contents = self._gbuffer_contents(snap, cache, items, order, world_from_objects,
                                              terminator_offsets, frame_data,
                                              lists.writes_emission)
            held = self._textures.get("gbuffer_contents")
            self.gbuffer_kept = False
            if not self.skip_gpu_calls and contents is not None and held is not None and \
                    held[1] == contents and all(a is b for a, b in zip(held[0], targets)):
                GBUFFERS["kept"] += 1
                self.gbuffer_kept = True
                t = self._sync(gbuffer_fb, "gbuffer", t)
                return t, (albedo, normal, view_depth, emission, gbuffer_fb, facet)
            if not self.skip_gpu_calls:
                # Forget what the targets held while they are redrawn (if drawing raises,
                # the next frame draws again), and what was computed from them.
                for name in ("gbuffer_contents", "ao_contents", "depth_blocks"):
                    self._textures.pop(name, None)
                GBUFFERS["drawn"] += 1
            with gbuffer_fb.bind():
                gpu.state.viewport_set(0, 0, width, height)
                self._gpu_call(gbuffer_fb.clear, color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
                gpu.state.depth_test_set('LESS_EQUAL')
                gpu.state.depth_mask_set(True)
                culling = 'NONE'
                # Opaque before alpha-tested; untextured materials with the program that
                # samples no texture, meshes with tangents (normal maps) with the programs
                # that read them. (slot in the _draw_items entry, tangents or None: any)
                for (program, slot, _tangents, textured), drawn in zip(_GBUFFER_PASSES,
                                                                       lists.gbuffer_masks):
                    rows = order[drawn[order]]
                    if not len(rows):
                        continue
                    gbuffer = library.get(program)
                    gbuffer.bind()
                    gbuffer.uniform_block("frame", frame_ubo)
                    bound = None
                    offset = None
                    for index in rows.tolist():
                        draws = items[index][slot]
                        gbuffer.uniform_float("world_from_object", world_from_objects_gl[index])
                        # Most objects share Blender's default: set only when it changes.
                        if terminator_offsets[index] != offset:
                            offset = terminator_offsets[index]
                            gbuffer.uniform_float("terminator_offset", float(offset))
                        for batch, material in draws:
                            wanted = ('FRONT' if mirrored[index] else 'BACK') \
                                if material.backface_culling else 'NONE'
                            if wanted != culling:
                                gpu.state.face_culling_set(wanted)
                                culling = wanted
                            if material is not bound:
                                gbuffer.uniform_block("material", material.block)
                                if textured:
                                    for name, texture in zip(_MATERIAL_SAMPLERS,
                                                             material.textures):
                                        gbuffer.uniform_sampler(name, texture)
                                bound = material
                            self._gpu_call(batch.draw, gbuffer)
                gpu.state.face_culling_set('NONE')
                gpu.state.depth_test_set('NONE')
            if contents is not None and not self.skip_gpu_calls:
                self._textures["gbuffer_contents"] = (targets, contents)
            t = self._sync(gbuffer_fb, "gbuffer", t)
            return t, (albedo, normal, view_depth, emission, gbuffer_fb, facet)

        t = time.perf_counter()
        if fit_to_visible:
            # Sample-distribution shadow maps: the G-buffer first, its nearest and farthest
            # view depth, then cascades fitted to that range, then their shadow maps.
            t, gbuffer = gbuffer_pass(t)
            blocks = self._textures.get("depth_blocks") if self.gbuffer_kept else None
            if blocks is None:
                blocks = self._visible_depth_blocks(gbuffer[2], width, height)
                if blocks is not None:
                    self._textures["depth_blocks"] = blocks
            t = self._sync(gbuffer[4], "depth_range", t)
            plan = plan_shadows(snap, bounds, blocks, view_state=self.view_state)
            self.warnings.extend(w for w in plan.warnings if w not in self.warnings)
            atlas, partial = self._atlas(plan)
            frame_ubo = self._frame_ubo(pack_frame(snap, plan, like=frame_data))
            t = shadow_pass(t)
        else:
            t = shadow_pass(t)
            t, gbuffer = gbuffer_pass(t)
        albedo, normal, view_depth, emission, gbuffer_fb, facet = gbuffer

        # 2b. Ambient occlusion: skipped, with no texture allocated, when it is off.
        ambient_occlusion = self._ambient_occlusion(snap, frame_ubo, frame_data, view_depth,
                                                    normal, width, height)
        if ambient_occlusion is not None:
            t = self._sync(self.ao_fb, "ao", t)

        # 3. Lighting (+ debug views) into the target
        program = lighting_program(snap)
        lighting = library.get(program)
        # NOTE: with the G-buffer's depth attached to the target (``depth_tested``), the
        # lighting pass runs only where a surface is (its triangle lies on the far plane:
        # depth test GREATER), and a trivial program gives the background its colour (LESS
        # or EQUAL): llvmpipe skips the shading of pixel blocks that fail an early depth
        # test, so sky pixels stop paying for the whole lighting shader. The debug views
        # draw the shadow map over the background too, so they keep the plain pass.
        depth_tested = depth_tested and not program.endswith("_debug")

        def light_pass():
            gpu.state.viewport_set(0, 0, width, height)
            gpu.state.depth_mask_set(False)
            if depth_tested:
                background = library.get("background")
                gpu.state.depth_test_set('LESS_EQUAL')
                background.bind()
                background.uniform_block("frame", frame_ubo)
                self._gpu_call(self._fullscreen_batch().draw, background)
                gpu.state.depth_test_set('GREATER')
            else:
                gpu.state.depth_test_set('NONE')
            lighting.bind()
            lighting.uniform_block("frame", frame_ubo)
            lighting.uniform_sampler("gbuffer_albedo", albedo)
            lighting.uniform_sampler("gbuffer_normal", normal)
            lighting.uniform_sampler("gbuffer_depth", view_depth)
            lighting.uniform_sampler("shadow_atlas", atlas)
            lighting.uniform_sampler("shadow_partial", partial)
            lighting.uniform_sampler("ambient_occlusion",
                                     white if ambient_occlusion is None else ambient_occlusion)
            lighting.uniform_sampler("gbuffer_emission", emission)
            lighting.uniform_sampler("gbuffer_facet", facet)
            self._gpu_call(self._fullscreen_batch().draw, lighting)
            gpu.state.depth_test_set('NONE')
            if overlays and plan.frozen_camera is not None:
                self._draw_frozen(snap, plan)

        if target_fb is None:
            light_pass()
        else:
            with target_fb.bind():
                light_pass()
            t = self._sync(target_fb, "lighting", t)
        self.gbuffer_fb = gbuffer_fb
        self.timings["total"] = time.perf_counter() - start
        return plan

    def _ambient_occlusion(self, snap, frame_ubo, frame_data, view_depth, normal, width,
                           height):
        """The AO pass (ao_frag.glsl): the horizon search, then the depth-aware blur, both at
        half resolution. Returns the blurred texture (AO: 1 = open, 0 = occluded; and the
        view depth it stands for), which the lighting pass brings to full resolution; or
        None when AO is off or its strength is 0, in which case no AO texture is allocated
        and the lighting pass ignores its sampler. With the G-buffer kept from the frame
        before (``gbuffer_kept``) and the same AO settings, the AO drawn then is kept too."""
        import gpu
        self.ao_fb = None
        settings = snap.settings
        if not getattr(settings, "ambient_occlusion", False) or \
                getattr(settings, "ao_strength", 0.0) <= 0.0 or \
                getattr(settings, "ao_distance", 0.0) <= 0.0:
            return None
        half_size = ((width + 1) // 2, (height + 1) // 2)
        search = self._texture("ao_half", half_size, 'RG32F')
        blurred = self._texture("ao", half_size, 'RG32F')
        search_fb = self._framebuffer("ao_half", colors=(search,))
        blurred_fb = self._framebuffer("ao", colors=(blurred,))
        library = shaders.LIBRARY
        inputs = (_programs_key(), FRAME_LAYOUT.field_bytes(frame_data, _AO_FRAME_FIELDS))
        held = self._textures.get("ao_contents")
        if self.gbuffer_kept and held is not None and held[0] is blurred and \
                held[1] == inputs:
            self.ao_fb = blurred_fb
            return blurred
        self._textures.pop("ao_contents", None)
        for program, fb, extra in (("ao", search_fb, ()),
                                   ("ao_blur", blurred_fb, (("ao_half", search),))):
            shader = library.get(program)
            with fb.bind():
                gpu.state.viewport_set(0, 0, *half_size)
                gpu.state.depth_test_set('NONE')
                gpu.state.depth_mask_set(False)
                shader.bind()
                shader.uniform_block("frame", frame_ubo)
                if program == "ao":
                    shader.uniform_sampler("gbuffer_depth", view_depth)
                shader.uniform_sampler("gbuffer_normal", normal)
                for name, texture in extra:
                    shader.uniform_sampler(name, texture)
                self._gpu_call(self._fullscreen_batch().draw, shader)
        self.ao_fb = blurred_fb
        if not self.skip_gpu_calls:
            self._textures["ao_contents"] = (blurred, inputs)
        return blurred

    def _begin_tile(self, fb, tile, clear=None):
        """Draw into ``tile`` of the bound ``fb`` from now on; with ``clear`` (``fb.clear``'s
        arguments) clear that tile first, and only it."""
        import gpu
        gpu.state.viewport_set(tile.origin[0], tile.origin[1], tile.resolution,
                               tile.resolution)
        if clear:
            # NOTE: a clear honours the scissor box, not the viewport: without it the whole
            # atlas (the other tiles too) would be cleared.
            gpu.state.scissor_test_set(True)
            gpu.state.scissor_set(tile.origin[0], tile.origin[1], tile.resolution,
                                  tile.resolution)
            self._gpu_call(fb.clear, **clear)
            gpu.state.scissor_test_set(False)

    def _draw_partial_mask(self, library, items, lists, atlas, partial, stale,
                           world_from_objects, mirrored, cull_front, can_clear_tile):
        """The atlas's partial-caster mask for the redrawn tiles ``stale``: cleared, then
        marked by their alpha-hashed casters against the finished depth (depth writes
        off). A scene without hashed casters draws nothing here once the mask is clear."""
        import gpu
        held = self._textures.get("atlas_partial_marks")
        new = held is None or held[0] is not partial
        if new:
            # [texture, whether it may hold marks]: a new texture holds anything.
            held = self._textures["atlas_partial_marks"] = [partial, True]
        hashed = bool(lists.partial_mask.any())
        if not hashed and not held[1]:
            return
        clear = (0.0, 0.0, 0.0, 0.0)
        partial_fb = self._framebuffer("atlas_partial", depth=atlas, colors=(partial,))
        with partial_fb.bind():
            cleared = new or not hashed or not can_clear_tile
            if cleared:
                self._gpu_call(partial_fb.clear, color=clear)
            held[1] = hashed
            if not hashed:
                return
            gpu.state.depth_test_set('LESS_EQUAL')
            gpu.state.depth_mask_set(False)
            gpu.state.face_culling_set('FRONT' if cull_front else 'NONE')
            for tile, visible, _key, _signature in stale:
                self._begin_tile(partial_fb, tile, None if cleared else dict(color=clear))
                if len(visible) and lists.partial_mask[visible].any():
                    self._draw_casters(library, items, lists.shadow_masks,
                                       world_from_objects, tile, visible, mirrored,
                                       cull_front, partial_mask=lists.partial_mask)
            gpu.state.face_culling_set('NONE')
            gpu.state.depth_mask_set(True)

    def _draw_casters(self, library, items, shadow_masks, world_from_objects, tile, visible,
                      mirrored, cull_front, partial_mask=None):
        """Draw the shadow casters ``visible`` (instance indices) into ``tile``: opaque,
        then alpha-masked. With ``partial_mask`` (per instance: has an alpha-hashed shadow
        material) only the hashed materials, with the partial-caster mask's program."""
        import gpu
        clip_from_objects = _column_major_stack(tile.clip_from_world @
                                                world_from_objects[visible])
        default = 'FRONT' if cull_front else 'NONE'
        culling = default
        # (program, which instances it draws, their draw-list slot, whether it reads the
        # material): the partial-caster mask draws only the hashed materials of slot 3.
        passes = (("shadow_partial", partial_mask, 3, False),) if partial_mask is not None \
            else (("shadow", shadow_masks[0], 2, False),
                  ("shadow_masked", shadow_masks[1], 3, True))
        for program, drawn, slot, reads_material in passes:
            rows = np.flatnonzero(drawn[visible])
            if not len(rows):
                continue
            shadow = library.get(program)
            shadow.bind()
            bound = None
            for row, index in zip(rows.tolist(), visible[rows].tolist()):
                shadow.uniform_float("clip_from_object", clip_from_objects[row])
                for batch, material in items[index][slot]:
                    if partial_mask is not None and material.shadow_mode != 'HASHED':
                        continue
                    # 4.2+ "Backface Culling" of shadows: the faces turned away from the
                    # light (the winding turned around for a mirrored instance).
                    wanted = ('FRONT' if mirrored[index] else 'BACK') \
                        if material.backface_culling_shadow else default
                    if wanted != culling:
                        gpu.state.face_culling_set(wanted)
                        culling = wanted
                    if reads_material and material is not bound:
                        shadow.uniform_block("material", material.block)
                        shadow.uniform_sampler("base_color_texture", material.textures[0])
                        bound = material
                    self._gpu_call(batch.draw, shadow)
        if culling != default:
            gpu.state.face_culling_set(default)

    def _instance_arrays(self, snap, cache):
        """This frame's ``_InstanceArrays``: the last frame's when the instances, their
        meshes and matrices are the same, else new ones."""
        instances = snap.instances
        keys = tuple(i.key for i in instances)
        meshes = [cache.meshes.get(key) for key in keys]
        world_from_objects = np.array([i.world_from_object for i in instances],
                                      dtype=np.float64).reshape(-1, 4, 4)
        held = self._held_instances
        if held is None or not held.holds(keys, meshes, world_from_objects):
            held = self._held_instances = _InstanceArrays(snap, cache, keys, meshes,
                                                          world_from_objects)
        return held

    def _atlas_contents(self, atlas):
        """What each tile of ``atlas`` holds: (origin, resolution) -> the signature it was
        drawn with. Kept beside the atlas texture (final renders share it between
        renders), and forgotten when the texture is reallocated."""
        held = self._textures.get("atlas_contents")
        if held is None or held[0] is not atlas:
            held = (atlas, {})
            self._textures["atlas_contents"] = held
        return held[1]

    def _caster_signatures(self, snap, cache, items):
        """Per instance, what its shadow depends on besides its matrix: the geometry
        (``GPUMesh.serial``, never reused, unlike ``id()``) and the alpha-masked draws'
        cut-out inputs. A masked draw with an image texture gives None, which never equals
        a held signature: the image may have been edited in place."""
        per_key = {}
        signatures = []
        # A mesh's signature is kept with its draw lists (``_draw_items``): the same lists
        # (the same object) have the same signature.
        held = self._held_signatures
        kept = {}
        for instance, entry in zip(snap.instances, items):
            if instance.key not in per_key:
                known = held.get(instance.key)
                if known is not None and known[0] is entry:
                    signature = known[1]
                else:
                    mesh = cache.meshes.get(instance.key)
                    keys = tuple(material.shadow_key for _b, material in entry[2] + entry[3])
                    signature = (mesh.serial if mesh is not None else 0, keys)
                    if None in keys:
                        signature = None
                per_key[instance.key] = signature
                kept[instance.key] = (entry, signature)
            signatures.append(per_key[instance.key])
        self._held_signatures = kept
        return signatures

    def _gbuffer_contents(self, snap, cache, items, order, world_from_objects,
                          terminator_offsets, frame_data, writes_emission):
        """What a G-buffer drawn now would hold, as a value to compare with the one the
        targets hold: the programs, camera and sample, which instances in which order at
        which matrices, each one's geometry (``GPUMesh.serial``), material inputs and
        Shadow Terminator Geometry Offset. None
        when a draw reads an image (its pixels may have changed in place). In the viewport
        the camera is looked at first, so a redraw of a moving view pays for little else
        (its record holds only the camera, which the next redraw of that view completes)."""
        camera = (_programs_key(), writes_emission,
                  FRAME_LAYOUT.field_bytes(frame_data, _GBUFFER_FRAME_FIELDS))
        held = self._textures.get("gbuffer_contents")
        # NOTE: the benchmark's Python-only redraw (``skip_gpu_calls``) repeats the view of
        # the redraw before; it pays what a redraw of a moving view pays.
        if self.skip_gpu_calls or \
                (snap.is_viewport and (held is None or held[1][0] != camera)):
            return (camera,)
        per_entry = {}
        draws = []
        instances = snap.instances
        for index in order.tolist():
            entry = items[index]
            known = per_entry.get(id(entry))
            if known is None:
                mesh = cache.meshes.get(instances[index].key)
                keys = tuple(material.gbuffer_key
                             for _batch, material in entry[0] + entry[1] + entry[5])
                if None in keys:
                    return None
                known = per_entry[id(entry)] = (mesh.serial if mesh is not None else 0, keys)
            draws.append(known)
        # The facet target carries each object's Shadow Terminator Geometry Offset.
        return (camera, order.tobytes(), world_from_objects[order].tobytes(), tuple(draws),
                terminator_offsets[order].tobytes())

    def _gpu_call(self, call, *args, **kwargs):
        """Every draw and clear of a frame goes through here, so that the benchmark can
        time the frame's Python alone (``skip_gpu_calls``): on llvmpipe a draw call does
        the vertex work on the calling thread and its rasteriser threads compete with
        Python for the cores, so a normal frame cannot tell Python and GPU time apart."""
        if not self.skip_gpu_calls:
            call(*args, **kwargs)

    def _cull(self, instances, bounds_lo_hi, tile):
        if bounds_lo_hi is None:
            return range(0)
        if tile.point_face is not None:
            position, face, reach = tile.point_face
            return np.nonzero(cascades.aabbs_in_point_light_face(
                bounds_lo_hi[0], bounds_lo_hi[1], position, face, reach))[0]
        if tile.cascade is None:    # spot tiles: no caster culling (few, small frusta)
            return range(len(instances))
        held = self._held_instances
        checked = held is not None and held.bounds_lo_hi is bounds_lo_hi and held.bounds_checked
        rotated = None
        if checked:
            # The cascades of one sun share its rotation: the boxes are turned into its
            # frame once, and again only when the sun turns or the instances change.
            light_from_world = tile.cascade.light_from_world
            rotation = light_from_world[:3, :3].tobytes()
            if held.light_frame_boxes[0] != rotation:
                held.light_frame_boxes = (rotation, cascades.boxes_in_light_frame(
                    bounds_lo_hi[0], bounds_lo_hi[1], light_from_world))
            rotated = held.light_frame_boxes[1]
        mask = cascades.aabbs_in_cascade(bounds_lo_hi[0], bounds_lo_hi[1], tile.cascade,
                                         checked=checked, rotated=rotated)
        return np.nonzero(mask)[0]

    def _kept_draw_items(self, snap, cache, white):
        """``_draw_items``, kept from the last frame while it would come out the same: the
        same meshes (a re-upload is a new GPUMesh), the same MaterialInfo lists (a material
        edit makes new ones, see MeshCache.sync) and, for every image, the same GPU texture
        (an edited image's texture is dropped from the cache)."""
        keys = tuple(instance.key for instance in snap.instances)
        held = self._held_draws
        if held is not None and held[0] == keys and held[1] is white and \
                all(cache.meshes.get(key) is mesh and
                    (mesh is None or mesh.materials is materials)
                    for key, mesh, materials in held[2]) and _same_textures(cache, held[3]):
            return held[4]
        items = self._draw_items(snap, cache, white)
        meshes = [(key, cache.meshes.get(key)) for key in dict.fromkeys(keys)]
        textures = tuple((image, cache.textures.get(image.name))
                         for _key, mesh in meshes if mesh is not None
                         for info in mesh.materials
                         for image in (info.image, info.normal_image, info.emission_image,
                                       info.surface_image)
                         if image is not None)
        self._held_draws = (keys, white, [(key, mesh, mesh.materials if mesh is not None
                                           else None) for key, mesh in meshes],
                            textures, items)
        return items

    def _draw_items(self, snap, cache, white):
        """Per instance: (camera opaque textured draws, camera alpha-tested draws, shadow
        opaque draws, shadow alpha-tested draws, whether the mesh has tangents, camera
        opaque untextured draws); each draw is (batch, ``_DrawMaterial``). Instances of one
        mesh share the lists, and slots of one material share its ``_DrawMaterial`` (so the
        G-buffer binds a material shared by many objects once)."""
        per_mesh = {}
        per_material = {}
        items = []
        for instance in snap.instances:
            entry = per_mesh.get(instance.key)
            if entry is None:
                mesh = cache.meshes.get(instance.key)
                entry = ([], [], [], [], bool(mesh is not None and mesh.has_tangents), [])
                for batch, slot in (mesh.batches if mesh is not None else ()):
                    material = self._material(cache, mesh, slot, white, per_material)
                    camera = 1 if material.alpha_mode != 'OPAQUE' else \
                        (0 if material.textured else 5)
                    entry[camera].append((batch, material))
                    if material.shadow_mode != 'NONE':
                        entry[2 + (material.shadow_mode != 'OPAQUE')].append(
                            (batch, material))
                per_mesh[instance.key] = entry
            items.append(entry)
        return items

    def _material(self, cache, mesh, slot, white, memo=None):
        """One material slot as both the shadow and G-buffer passes draw it: its uniform
        block (made once per MaterialInfo and set of loadable textures, kept on it),
        textures (white where there is none) and settings."""
        import gpu
        material = mesh.materials[slot] if slot < len(mesh.materials) else None
        if material is None:
            material = _DEFAULT_MATERIAL
        if memo is not None:
            # Keyed by identity: MaterialInfo objects live in the meshes' lists meanwhile.
            held = memo.get(id(material))
            if held is None:
                held = memo[id(material)] = self._material(cache, mesh, slot, white)
            return held
        images = (material.image, material.normal_image, material.emission_image,
                  material.surface_image)
        textures = tuple(cache.texture(image) if image is not None else None
                         for image in images)
        loaded = tuple(texture is not None for texture in textures)
        held = material.gpu_block
        if held is None or held[0] != loaded:
            shadow_alpha = material.shadow_mode if material.shadow_mode in \
                ('CLIP', 'HASHED') else 'OPAQUE'
            block = pack_material({
                "base_color": material.base_color, "emission": material.emission,
                "metallic": material.metallic, "roughness": material.roughness,
                "specular_level": material.specular_level,
                "normal_strength": material.normal_strength,
                "alpha_cutoff": material.alpha_cutoff, "alpha_mode": material.alpha_mode,
                "shadow_alpha_mode": shadow_alpha,
                "has_base_texture": int(loaded[0]), "has_normal_texture": int(loaded[1]),
                "has_emission_texture": int(loaded[2]),
                "surface_convention": material.surface_convention,
                "roughness_channel": material.roughness_channel if loaded[3] else -1,
                "metallic_channel": material.metallic_channel if loaded[3] else -1})
            held = (loaded, gpu.types.GPUUniformBuf(block.tobytes()), shadow_alpha,
                    block.tobytes())
            material.gpu_block = held
        # What a shadow tile drawn with this material depends on; None when it reads an
        # image, which may have been edited in place.
        shadow_key = (held[2], material.base_color[3], material.alpha_cutoff,
                      material.backface_culling_shadow)
        if held[2] != 'OPAQUE' and loaded[0]:
            shadow_key = None
        writes_emission = bool(loaded[2] or max(material.emission) > 0.0 or
                               material.metallic > 0.0 or
                               (loaded[3] and material.metallic_channel >= 0))
        # What a G-buffer drawn with this material depends on; None when it reads an
        # image (painted or reloaded in place, it keeps its name and texture).
        gbuffer_key = None if any(loaded) else \
            (held[3], material.alpha_mode, material.backface_culling)
        return _DrawMaterial(held[1], tuple(t or white for t in textures), any(loaded),
                             writes_emission, material.alpha_mode, material.shadow_mode,
                             material.backface_culling, material.backface_culling_shadow,
                             shadow_key, gbuffer_key)

    def _draw_frozen(self, snap, plan):
        """Draw each frozen cascade's light-space box as coloured lines."""
        import gpu
        lines, colors = [], []
        for index, tile in enumerate(plan.tiles[:plan.cascade_count]):
            world_from_clip = np.linalg.inv(tile.clip_from_world)
            corners = np.array([[x, y, z, 1.0] for z in (-1, 1) for y in (-1, 1)
                                for x in (-1, 1)]) @ world_from_clip.T
            corners = corners[:, :3] / corners[:, 3:]
            for a, b in ((0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7),
                         (0, 4), (1, 5), (2, 6), (3, 7)):
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
        shader.uniform_float("clip_from_world", _column_major(snap.camera.clip_from_world))
        batch.draw(shader)

    # -- sample-distribution shadow maps ------------------------------------------------
    # The G-buffer is reduced to blocks of this many pixels on a side (two 4x4 steps) and
    # read back; the CPU fits the cascades to them (core/shadow_plan.py).
    DEPTH_BLOCK_PIXELS = 16

    def _visible_depth_blocks(self, view_depth, width, height):
        """What the G-buffer shows per 16x16 block: nearest and farthest view depth, by two
        4x4 min/max reductions on the GPU and one read-back of the small result
        (``shadow_plan.depth_blocks_from_reduction``); None without a GPU."""
        import gpu
        source, is_view_depth = view_depth, 1
        size = (width, height)
        shader = shaders.LIBRARY.get("depth_range")
        for level in range(2):
            size = (max((size[0] + 3) // 4, 1), max((size[1] + 3) // 4, 1))
            target = self._texture(f"depth_range_{level}", size, 'RGBA32F')
            fb = self._framebuffer(f"depth_range_{level}", colors=(target,))
            with fb.bind():
                gpu.state.viewport_set(0, 0, size[0], size[1])
                gpu.state.depth_test_set('NONE')
                gpu.state.blend_set('NONE')
                shader.bind()
                shader.uniform_int("source_is_view_depth", is_view_depth)
                shader.uniform_sampler("source", source)
                self._gpu_call(self._fullscreen_batch().draw, shader)
            source, is_view_depth = target, 0
        if self.skip_gpu_calls:
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

    # -- anti-aliasing -------------------------------------------------------------------
    def _fullscreen_pass(self, program, target_fb, width, height, samplers, floats=()):
        import gpu
        shader = shaders.LIBRARY.get(program)
        with target_fb.bind():
            gpu.state.viewport_set(0, 0, width, height)
            gpu.state.depth_test_set('NONE')
            gpu.state.blend_set('NONE')
            shader.bind()
            for name, texture in samplers:
                shader.uniform_sampler(name, texture)
            for name, value in floats:
                shader.uniform_float(name, value)
            self._gpu_call(self._fullscreen_batch().draw, shader)
            if self.profile:          # wait for the GPU, so the pass's time is its own
                target_fb.read_color(0, 0, 1, 1, 4, 0, 'FLOAT')

    def draw_viewport(self, snap, cache, width, height, fxaa=True):
        """A viewport frame into the bound framebuffer, through FXAA when ``fxaa``: the
        lit image goes to an offscreen target first, and FXAA writes it to the screen."""
        import gpu
        if not fxaa:
            return self.draw(snap, cache, None, width, height)
        blend = gpu.state.blend_get() if hasattr(gpu.state, "blend_get") else 'NONE'
        lit = self._texture("lit", (width, height), 'RGBA16F')
        lit_fb = self._framebuffer("lit", depth=self.gbuffer_depth_texture(width, height),
                                   colors=(lit,))
        gpu.state.blend_set('NONE')
        plan = self.draw(snap, cache, lit_fb, width, height, overlays=False,
                         depth_tested=True)
        t = time.perf_counter()
        shader = shaders.LIBRARY.get("fxaa")
        gpu.state.viewport_set(0, 0, width, height)
        gpu.state.depth_test_set('NONE')
        gpu.state.blend_set(blend)
        shader.bind()
        shader.uniform_sampler("source", lit)
        self._gpu_call(self._fullscreen_batch().draw, shader)
        self.timings["fxaa"] = time.perf_counter() - t
        if plan.frozen_camera is not None:
            self._draw_frozen(snap, plan)
        return plan

    def _draw_antialiased(self, snap, cache, samples, use_fxaa, color, aux):
        """Final-render anti-aliasing: FXAA on one sample, or ``samples`` jittered frames
        (core/antialiasing.py) averaged into a running mean. Sample 0 is unjittered and
        writes the auxiliary target; later samples reuse its shadow plan, so the shadow maps
        are drawn once. Leaves the framebuffer holding the Combined image in
        ``self._combined_fb``."""
        from ..core.antialiasing import jittered, sample_offsets
        width, height = snap.camera.width, snap.camera.height
        lit = self._texture("lit_final", (width, height), 'RGBA32F')
        depth = self.gbuffer_depth_texture(width, height)
        first_fb = self._framebuffer("lit_first", depth=depth, colors=(lit, aux))
        started = time.perf_counter()
        plan = self.draw(snap, cache, first_fb, width, height, overlays=False,
                         depth_tested=True)
        timings = dict(self.timings)
        color_fb = self._framebuffer("final_color_only", colors=(color,))
        t = time.perf_counter()
        if use_fxaa:
            self._fullscreen_pass("fxaa", color_fb, width, height, (("source", lit),))
            self._draw_overlays(snap, plan, color_fb, width, height)
            self._combined_fb = color_fb
            timings["fxaa"] = time.perf_counter() - t
            timings["total"] = timings.get("total", 0.0) + timings["fxaa"]
            self.timings = timings
            return plan
        # A running mean ping-pongs between the final colour target and a second one.
        offsets, weights = sample_offsets(samples, snap.pixel_filter_width)
        spare = self._texture("accumulate", (width, height), 'RGBA32F')
        spare_fb = self._framebuffer("accumulate", colors=(spare,))
        scratch_aux = self._texture("lit_aux_scratch", (width, height), 'RGBA32F')
        sample_fb = self._framebuffer("lit_sample", depth=depth, colors=(lit, scratch_aux))
        self._fullscreen_pass("accumulate", color_fb, width, height,
                              (("previous", lit), ("current", lit)), (("sample_share", 1.0),))
        accumulating = time.perf_counter() - t
        mean, mean_fb, other, other_fb = color, color_fb, spare, spare_fb
        total = weights[0]
        camera = snap.camera
        try:
            for index, (offset, weight) in enumerate(zip(offsets[1:], weights[1:]), start=1):
                snap.camera = jittered(camera, offset)
                snap.sample_index = index
                self.draw(snap, cache, sample_fb, width, height, plan=plan, overlays=False,
                          depth_tested=True)
                for name, value in self.timings.items():
                    if name != "total":
                        timings[name] = timings.get(name, 0.0) + value
                total += weight
                t = time.perf_counter()
                self._fullscreen_pass("accumulate", other_fb, width, height,
                                      (("previous", mean), ("current", lit)),
                                      (("sample_share", float(weight / total)),))
                accumulating += time.perf_counter() - t
                mean, mean_fb, other, other_fb = other, other_fb, mean, mean_fb
        finally:
            snap.camera = camera
            snap.sample_index = 0
        # The samples' own passes are added into shadow/gbuffer/lighting above; this step
        # is the averaging alone.
        timings["antialiasing"] = accumulating
        timings["total"] = time.perf_counter() - started
        self.timings = timings
        self._draw_overlays(snap, plan, mean_fb, width, height)
        self._combined_fb = mean_fb
        return plan

    def _draw_overlays(self, snap, plan, target_fb, width, height):
        import gpu
        if plan.frozen_camera is None:
            return
        with target_fb.bind():
            gpu.state.viewport_set(0, 0, width, height)
            self._draw_frozen(snap, plan)

    # -- read-back for final renders -----------------------------------------------------
    # What each image is read from: (target, colour slot); the G-buffer's normal target is
    # the pipeline's own, the other two the final target's.
    READS = {"combined": ("final", 0), "aux": ("final", 1), "normal": ("gbuffer", 1)}

    def render_offscreen(self, snap, cache, reads=None, with_positions=False):
        """Draw into offscreen float targets and read back only what ``reads`` names:
        image name ("combined", "aux", "normal") -> channels (1..4, from the first;
        default: combined and aux, RGBA). Each image is one read into a new buffer that the
        returned (H, W, channels) float32 array views, without another copy. With
        ``with_positions`` the G-buffer's world positions are added as "position" (tests
        ray-cast from them; needs "aux" with 4 channels)."""
        import gpu
        width, height = snap.camera.width, snap.camera.height
        if reads is None:
            reads = {"combined": 4, "aux": 4}
        if with_positions:
            reads = dict(reads, aux=4)
        color = self._texture("final_color", (width, height), 'RGBA32F')
        aux = self._texture("final_aux", (width, height), 'RGBA32F')
        target = self._framebuffer("final", depth=self.gbuffer_depth_texture(width, height),
                                   colors=(color, aux))
        self._combined_fb = None
        # No clear: every path writes every pixel of both targets (background and lighting
        # programs between them, or a debug view, or FXAA / the sample average).
        samples = max(int(getattr(snap.settings, "render_samples", 1)), 1)
        use_fxaa = samples == 1 and bool(getattr(snap.settings, "fxaa", False))
        if samples == 1 and not use_fxaa:
            plan = self.draw(snap, cache, target, width, height, depth_tested=True)
        else:
            plan = self._draw_antialiased(snap, cache, samples, use_fxaa, color, aux)
        combined_fb = self._combined_fb
        t = time.perf_counter()
        out = {}
        for name, channels in reads.items():        t = time.perf_counter()
        out = {}
        for name, channels in reads.items():
            source, slot = self.READS[name]
            fb = {"final": target, "gbuffer": self.gbuffer_fb}[source]
            if name == "combined":
                fb, slot = combined_fb or target, 0
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
        self.timings["readback"] = time.perf_counter() - t
        return RenderResult(images=out, plan=plan, timings=dict(self.timings),
                            warnings=list(self.warnings))
