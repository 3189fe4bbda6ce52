"""The deferred pipeline: shadow atlas, G-buffer, lighting and debug views, for any target.

Owns every GPU pass and the textures they render into. Input is a ``FrameSnapshot``
(plain data) plus a ``MeshCache``; output is pixels in a target framebuffer: the viewport's
own (``view_draw``) or an offscreen one that ``render()`` reads back. Both go through
``Pipeline.draw``, so the viewport and a final render of the same camera agree.

Passes per frame:
1. shadow: one depth-only tile per cascade (and per shadowed spot light) in one atlas;
2. G-buffer: albedo+specular, normal+shininess, view depth (0 = background), depth; world
   positions are rebuilt from view depth in the lighting pass (``world_positions`` here);
3. lighting: a full-screen pass reading the G-buffer and the atlas (``lighting_frag.glsl``);
4. overlays: frozen cascade boxes.

Framebuffers belong to the GPU context that made them, so a ``Pipeline`` is owned by one
engine instance (one viewport, or one final render) and is never shared.
"""

import time
from dataclasses import dataclass

import numpy as np

from . import cascades, shaders
from .shaders import FRAME_LAYOUT, MAX_CASCADES, MAX_POINT_LIGHTS, MAX_SPOT_LIGHTS

DEBUG_VIEW_INDEX = {"NONE": 0, "CASCADES": 1, "SHADOW_FACTOR": 2, "SHADOW_MAP": 3,
                    "TEXEL_DENSITY": 4, "ALBEDO": 5, "NORMAL": 6, "POSITION": 7,
                    "DEPTH": 8, "SPECULAR": 9}
PCF_PATTERN_INDEX = {"GRID": 0, "CROSS5": 1, "NINE_TAP": 2}
CASCADE_LINE_COLORS = ((1, .2, .2, 1), (.2, 1, .2, 1), (.3, .4, 1, 1), (1, 1, .2, 1))

# Maps OpenGL clip space (-1..1 on every axis) to window/texture space (0..1).
WINDOW_FROM_CLIP = np.array([[.5, 0, 0, .5], [0, .5, 0, .5], [0, 0, .5, .5], [0, 0, 0, 1.]])
MAX_ATLAS_WIDTH = 8192
SPOT_SHADOW_RESOLUTION = 1024

# Cascades kept while "Freeze Cascades" is on, per scene. Plain numpy data, no GPU objects.
_FROZEN = {}


@dataclass
class ShadowTile:
    clip_from_world: np.ndarray
    resolution: int
    texel_world: float         # orthographic: scene units per texel; perspective: per unit dist
    near: float
    far: float
    is_perspective: bool
    origin: tuple = (0, 0)     # atlas texels
    cascade: object = None     # cascades.CascadeFit for sun tiles
    display_near: float = 0.0  # where the scene starts in this light's depth (debug view)


@dataclass
class ShadowPlan:
    tiles: list
    cascade_count: int
    splits: np.ndarray         # count+1 view depths
    bands: np.ndarray          # blend band before each far split
    shadow_distance: float
    spot_tiles: dict           # spot index -> tile index
    frozen_camera: object = None
    warnings: list = None      # settings that could not be honoured, in the user's words


def instance_bounds(instances, meshes):
    """(N,3) world-space min and max of each instance's mesh bounds."""
    rows = [(i.world_from_object, meshes[i.key]) for i in instances if i.key in meshes]
    if not rows:
        return None
    matrices = np.stack([m for m, _ in rows])                          # (N,4,4)
    lo = np.stack([g.aabb_min for _, g in rows])
    hi = np.stack([g.aabb_max for _, g in rows])
    # 8 corners per box, via a bit pattern choosing lo or hi on each axis.
    pick = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=bool)
    corners = np.where(pick[None], hi[:, None, :], lo[:, None, :])      # (N,8,3)
    world = np.einsum("nij,nkj->nki", matrices[:, :3, :3], corners) + matrices[:, None, :3, 3]
    return world.min(axis=1), world.max(axis=1)


def plan_shadows(snap, bounds):
    """Cascade splits and light matrices for this frame (pure math, see cascades.py)."""
    s = snap.settings
    camera = snap.camera
    tiles = []
    spot_tiles = {}
    count = int(s.cascade_count)
    distance = s.shadow_distance if s.shadow_distance > 0 else camera.clip_end
    distance = float(min(max(distance, camera.clip_start * 1.001), camera.clip_end))
    splits = np.array([camera.clip_start, distance])
    bands = np.zeros(MAX_CASCADES)
    frozen_camera = None
    warnings = []
    if snap.sun is not None and snap.sun.casts_shadow:
        margin = None if s.occluder_margin_auto else float(s.occluder_margin)
        manual = cascades.manual_splits_from_fractions(distance, s.manual_splits, count)
        key = snap.scene_name
        if s.freeze_cascades and key in _FROZEN:
            result, frozen_camera = _FROZEN[key]
        else:
            arguments = dict(
                count=count, scheme=s.split_scheme, lam=float(s.split_lambda),
                manual=manual if s.split_scheme == 'MANUAL' else None,
                shadow_distance=distance, base_resolution=int(s.resolution),
                equal_resolution=bool(s.equal_resolution), stabilize=bool(s.stabilize),
                occluder_margin=margin, blend_band=float(s.blend_band),
                # Auto: the near plane reaches the scene's bounds, so no caster is clipped.
                # Manual: exactly the margin the user typed, nothing added.
                scene_bounds=bounds if s.occluder_margin_auto else None)
            try:
                result = cascades.compute_cascades(
                    camera.world_from_view, camera.clip_from_view, -snap.sun.to_light,
                    **arguments)
            except ValueError as error:
                # An impossible setting (e.g. manual splits that do not increase): say which
                # and draw with hybrid splits rather than fail the frame.
                warnings.append(f"{error}; using hybrid splits instead")
                arguments.update(scheme="HYBRID", manual=None)
                result = cascades.compute_cascades(
                    camera.world_from_view, camera.clip_from_view, -snap.sun.to_light,
                    **arguments)
            warnings.extend(result.notes)
            if s.freeze_cascades:
                _FROZEN[key] = (result, camera)
                frozen_camera = camera
            else:
                _FROZEN.pop(key, None)
        splits = result.splits
        bands = np.zeros(MAX_CASCADES)
        bands[:count] = cascades.blend_band_widths(splits, float(s.blend_band))
        for fit in result.cascades:
            tiles.append(ShadowTile(fit.clip_from_world, fit.resolution, fit.texel_size_world,
                                    fit.near, fit.far, False, cascade=fit))
    else:
        count = 0
    for index, spot in enumerate(snap.spots[:MAX_SPOT_LIGHTS]):
        if not spot.casts_shadow or len(tiles) >= shaders.MAX_SHADOW_TILES:
            continue
        resolution = min(SPOT_SHADOW_RESOLUTION, int(s.resolution))
        near = max(spot.clip_start, 1e-3)
        far = max(spot.radius, near * 2.0)
        light_from_world, clip_from_light = cascades.spot_light_matrices(
            spot.world_from_light, min(spot.spot_size, np.radians(179.0)), near, far)
        # A 180 degree cone has no perspective projection; 179 is the widest we draw.
        half = 0.5 * min(spot.spot_size, np.radians(179.0))
        spot_tiles[index] = len(tiles)
        tiles.append(ShadowTile(clip_from_light @ light_from_world, resolution,
                                2.0 * np.tan(half) / resolution, near, far, True))
    if bounds is not None:
        # The shadow-map view stretches depth over the part the scene occupies; the occluder
        # margin alone would squeeze all content into the last few percent of grey.
        corners = np.array([[bounds[i & 1][0], bounds[(i >> 1) & 1][1], bounds[(i >> 2) & 1][2],
                             1.0] for i in range(8)])
        for tile in tiles:
            clip = corners @ tile.clip_from_world.T
            window = np.clip(clip[:, 2] / clip[:, 3] * 0.5 + 0.5, 0.0, 1.0).min()
            if tile.is_perspective:
                ndc = window * 2.0 - 1.0
                tile.display_near = 2.0 * tile.near * tile.far / (
                    tile.far + tile.near - ndc * (tile.far - tile.near))
            else:
                tile.display_near = tile.near + window * (tile.far - tile.near)
    return ShadowPlan(tiles, count, np.asarray(splits, dtype=np.float64),
                      np.asarray(bands, dtype=np.float64), distance, spot_tiles, frozen_camera,
                      warnings)


def layout_atlas(tiles):
    """Shelf-pack square tiles into one atlas; returns (width, height) in texels."""
    x = y = row_height = width = 0
    for tile in tiles:
        if x + tile.resolution > MAX_ATLAS_WIDTH and x > 0:
            x, y = 0, y + row_height
            row_height = 0
        tile.origin = (x, y)
        x += tile.resolution
        row_height = max(row_height, tile.resolution)
        width = max(width, x)
    return max(width, 1), max(y + row_height, 1)


def pack_frame(snap, plan):
    """The lighting pass's uniform block for this frame (std140 float32 array)."""
    s = snap.settings
    camera = snap.camera
    data = FRAME_LAYOUT.new_data()
    put = FRAME_LAYOUT.set
    put(data, "clip_from_world", camera.clip_from_world)
    put(data, "view_from_world", np.linalg.inv(camera.world_from_view))
    put(data, "world_from_clip", np.linalg.inv(camera.clip_from_world))
    put(data, "camera_position", [*camera.position, 1.0 if camera.is_perspective else 0.0])
    put(data, "camera_forward", [*camera.forward, 0.0])
    put(data, "viewport", [camera.width, camera.height, 1.0 / camera.width, 1.0 / camera.height])
    put(data, "ambient", [*snap.ambient, 0.0 if snap.film_transparent else 1.0])
    put(data, "background", [*snap.background, 1.0])
    if snap.sun is not None:
        put(data, "sun_direction", [*snap.sun.to_light, 1.0])
        put(data, "sun_color", [*snap.sun.color, 1.0 if plan.cascade_count else 0.0])
    fade_start = plan.shadow_distance * (1.0 - s.fade_fraction) if s.fade_out \
        else plan.shadow_distance * 2.0
    put(data, "shadow_params", [plan.cascade_count, plan.shadow_distance, fade_start, 0.0])
    put(data, "filter_params", [s.pcf_radius, PCF_PATTERN_INDEX[s.pcf_pattern],
                                s.depth_bias, s.slope_bias])
    points = snap.points[:MAX_POINT_LIGHTS]
    spots = snap.spots[:MAX_SPOT_LIGHTS]
    put(data, "bias_params", [s.normal_offset, len(spots), len(points), 0.0])
    put(data, "debug_params", [DEBUG_VIEW_INDEX[s.debug_view], s.debug_shadow_map,
                               1.0 if s.debug_inset else 0.0, 0.0])
    far = np.full(MAX_CASCADES, 1e30)
    near = np.zeros(MAX_CASCADES)
    far[:plan.cascade_count] = plan.splits[1:plan.cascade_count + 1]
    near[:plan.cascade_count] = plan.splits[:plan.cascade_count]
    put(data, "cascade_splits", far)
    put(data, "cascade_near", near)
    put(data, "cascade_band", plan.bands[:MAX_CASCADES])
    for t, tile in enumerate(plan.tiles):
        put(data, "shadow_from_world", WINDOW_FROM_CLIP @ tile.clip_from_world, t)
        put(data, "shadow_tiles", [tile.origin[0], tile.origin[1], tile.resolution,
                                   tile.texel_world], t)
        put(data, "shadow_depth", [tile.near, tile.far, 1.0 if tile.is_perspective else 0.0,
                                   tile.display_near], t)
    for i, light in enumerate(points):
        put(data, "point_lights", [*light.position, light.radius], 2 * i)
        put(data, "point_lights", [*light.color, 0.0], 2 * i + 1)
    from .snapshot import spot_cone_cosines
    for i, spot in enumerate(spots):
        cos_outer, cos_inner = spot_cone_cosines(spot)
        put(data, "spot_lights", [*spot.position, spot.radius], 4 * i)
        put(data, "spot_lights", [*spot.color, plan.spot_tiles.get(i, -1)], 4 * i + 1)
        put(data, "spot_lights", [*spot.direction, cos_outer], 4 * i + 2)
        put(data, "spot_lights", [cos_inner, 0.0, 0.0, 0.0], 4 * i + 3)
    return data


def _front_to_back(snap, bounds_lo_hi):
    """Instance indices sorted by the view depth of their bounds' centres."""
    if bounds_lo_hi is None:
        return range(len(snap.instances))
    centres = 0.5 * (bounds_lo_hi[0] + bounds_lo_hi[1])
    return np.argsort(centres @ np.asarray(snap.camera.forward, dtype=np.float64))


def world_positions(camera, view_depth):
    """(H, W, 3) world positions of pixel centres at the given view depths: the same
    reconstruction as ``world_position_at`` in lighting_frag.glsl, in float64."""
    height, width = view_depth.shape
    x = (np.arange(width) + 0.5) / width * 2.0 - 1.0
    y = (np.arange(height) + 0.5) / height * 2.0 - 1.0
    ndc = np.stack(np.broadcast_arrays(x[None, :], y[:, None]), axis=-1)     # (H, W, 2)
    world_from_clip = np.linalg.inv(camera.clip_from_world)
    points = []
    for z in (-1.0, 1.0):
        clip = np.concatenate([ndc, np.full(ndc.shape[:2] + (1,), z),
                               np.ones(ndc.shape[:2] + (1,))], axis=-1)
        world = clip @ world_from_clip.T
        points.append(world[..., :3] / world[..., 3:])
    position = np.asarray(camera.position, dtype=np.float64)
    forward = np.asarray(camera.forward, dtype=np.float64)
    near_depth = (points[0] - position) @ forward
    far_depth = (points[1] - position) @ forward
    t = (view_depth - near_depth) / (far_depth - near_depth)
    return points[0] + (points[1] - points[0]) * t[..., None]


def _column_major(matrix):
    return np.asarray(matrix, dtype=np.float32).T.ravel().tolist()


def _column_major_stack(matrices):
    """(N, 4, 4) matrices -> N lists of 16 floats in GLSL's column-major order."""
    matrices = np.asarray(matrices, dtype=np.float32)
    return matrices.transpose(0, 2, 1).reshape(len(matrices), 16).tolist()


class Pipeline:
    """GPU resources and passes for one engine instance (one GPU context)."""

    def __init__(self, textures=None):
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

    # -- resources ---------------------------------------------------------------------
    def _texture(self, name, size, fmt):
        import gpu
        key = (name, size, fmt)
        texture = self._textures.get(name)
        if texture is None or texture[0] != key:
            self._framebuffers = {k: v for k, v in self._framebuffers.items()
                                  if name not in k}
            self._textures[name] = (key, gpu.types.GPUTexture(size, format=fmt))
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
        """The shadow atlas; on allocation failure, halve resolutions and say so."""
        while True:
            size = layout_atlas(plan.tiles)
            try:
                return self._texture("atlas", size, 'DEPTH_COMPONENT32F')
            except Exception as error:
                if all(t.resolution <= 64 for t in plan.tiles):
                    raise
                message = (f"shadow atlas {size[0]}x{size[1]} could not be allocated "
                           f"({error}); halving shadow resolutions")
                if message not in self.warnings:
                    self.warnings.append(message)
                for tile in plan.tiles:
                    tile.texel_world *= 2.0 if tile.resolution > 64 else 1.0
                    tile.resolution = max(tile.resolution // 2, 64)

    def _sync(self, fb, name, start):
        """When profiling, wait for the GPU (a 1-pixel read) and record the pass time."""
        if self.profile:
            with fb.bind():
                fb.read_color(0, 0, 1, 1, 4, 0, 'FLOAT')
            self.timings[name] = time.perf_counter() - start
        return time.perf_counter()

    # -- passes ------------------------------------------------------------------------
    def draw(self, snap, cache, target_fb=None, width=None, height=None):
        """Render one frame into ``target_fb`` (None: the currently bound framebuffer)."""
        import gpu
        library = shaders.LIBRARY
        width = width or snap.camera.width
        height = height or snap.camera.height
        start = time.perf_counter()
        self.timings = {}

        # World AABB per instance: caster culling per cascade, and the scene's bounds for the
        # automatic occluder margin.
        bounds_lo_hi = instance_bounds(snap.instances, cache.meshes)
        bounds = None if bounds_lo_hi is None else \
            (bounds_lo_hi[0].min(axis=0), bounds_lo_hi[1].max(axis=0))
        plan = plan_shadows(snap, bounds)
        self.warnings.extend(w for w in plan.warnings if w not in self.warnings)
        atlas = self._atlas(plan)
        frame_data = pack_frame(snap, plan)
        frame_ubo = self._frame_ubo(frame_data)
        self.timings["python_setup"] = time.perf_counter() - start

        # Once per frame: each instance's batches, opaque and alpha-masked apart, with
        # their material inputs, and its matrix; the passes below only index into these.
        white = self._white_texture()
        items = self._draw_items(snap, cache, white)
        world_from_objects = np.array([i.world_from_object for i in snap.instances],
                                      dtype=np.float64).reshape(-1, 4, 4)
        world_from_objects_gl = _column_major_stack(world_from_objects)

        # 1. Shadow atlas
        t = time.perf_counter()
        atlas_fb = self._framebuffer("atlas", depth=atlas)
        with atlas_fb.bind():
            self._gpu_call(atlas_fb.clear, depth=1.0)
            gpu.state.depth_test_set('LESS_EQUAL')
            gpu.state.depth_mask_set(True)
            gpu.state.face_culling_set('FRONT' if snap.settings.cull_front_faces else 'NONE')
            for tile in plan.tiles:
                gpu.state.viewport_set(tile.origin[0], tile.origin[1],
                                       tile.resolution, tile.resolution)
                visible = self._cull(snap.instances, bounds_lo_hi, tile)
                if len(visible) == 0:
                    continue
                clip_from_objects = _column_major_stack(
                    tile.clip_from_world @ world_from_objects[visible])
                for masked in (False, True):
                    shadow = library.get("shadow_masked" if masked else "shadow")
                    shadow.bind()
                    for row, index in enumerate(visible):
                        draws = items[index][masked]
                        if not draws:
                            continue
                        shadow.uniform_float("clip_from_object", clip_from_objects[row])
                        for batch, texture, color, params in draws:
                            if masked:   # the opaque program has no material inputs
                                shadow.uniform_float("material_params",
                                                     (0.0, color[3], params[2], params[3]))
                                shadow.uniform_sampler("base_color_texture", texture)
                            self._gpu_call(batch.draw, shadow)
            gpu.state.face_culling_set('NONE')
        t = self._sync(atlas_fb, "shadow", t)

        # 2. G-buffer
        albedo = self._texture("albedo", (width, height), 'RGBA16F')
        normal = self._texture("normal", (width, height), 'RGBA16F')
        view_depth = self._texture("view_depth", (width, height), 'R32F')
        depth = self._texture("depth", (width, height), 'DEPTH_COMPONENT32F')
        gbuffer_fb = self._framebuffer("gbuffer", depth=depth,
                                       colors=(albedo, normal, view_depth))
        # Near to far, so the early depth test skips the shading of hidden fragments.
        order = _front_to_back(snap, bounds_lo_hi)
        with gbuffer_fb.bind():
            gpu.state.viewport_set(0, 0, width, height)
            self._gpu_call(gbuffer_fb.clear, color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
            gpu.state.depth_test_set('LESS_EQUAL')
            gpu.state.depth_mask_set(True)
            for masked in (False, True):
                gbuffer = library.get("gbuffer_masked" if masked else "gbuffer")
                gbuffer.bind()
                gbuffer.uniform_block("frame", frame_ubo)
                for index in order:
                    draws = items[index][masked]
                    if not draws:
                        continue
                    gbuffer.uniform_float("world_from_object", world_from_objects_gl[index])
                    for batch, texture, color, params in draws:
                        gbuffer.uniform_float("base_color", color)
                        gbuffer.uniform_float("material_params", params)
                        gbuffer.uniform_sampler("base_color_texture", texture)
                        self._gpu_call(batch.draw, gbuffer)
            gpu.state.depth_test_set('NONE')
        t = self._sync(gbuffer_fb, "gbuffer", t)

        # 3. Lighting (+ debug views) into the target
        lighting = library.get("lighting")

        def light_pass():
            gpu.state.viewport_set(0, 0, width, height)
            gpu.state.depth_test_set('NONE')
            gpu.state.depth_mask_set(False)
            lighting.bind()
            lighting.uniform_block("frame", frame_ubo)
            lighting.uniform_sampler("gbuffer_albedo", albedo)
            lighting.uniform_sampler("gbuffer_normal", normal)
            lighting.uniform_sampler("gbuffer_depth", view_depth)
            lighting.uniform_sampler("shadow_atlas", atlas)
            self._gpu_call(self._fullscreen_batch().draw, lighting)
            if plan.frozen_camera is not None:
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
        if tile.cascade is None:    # spot tiles: no caster culling (few, small frusta)
            return range(len(instances))
        mask = cascades.aabbs_in_cascade(bounds_lo_hi[0], bounds_lo_hi[1], tile.cascade)
        return np.nonzero(mask)[0]

    def _draw_items(self, snap, cache, white):
        """Per instance: (opaque draws, alpha-masked draws), each a list of (batch, texture,
        base colour, material parameters); instances of one mesh share the lists."""
        per_mesh = {}
        items = []
        for instance in snap.instances:
            entry = per_mesh.get(instance.key)
            if entry is None:
                mesh = cache.meshes.get(instance.key)
                entry = ([], [])
                for batch, slot in (mesh.batches if mesh is not None else ()):
                    texture, color, params = self._material(cache, mesh, slot, white)
                    entry[params[2] > 0.0].append((batch, texture, color, params))
                per_mesh[instance.key] = entry
            items.append(entry)
        return items

    def _material(self, cache, mesh, slot, white):
        """Texture, base colour and packed parameters (shininess, specular, alpha cutoff,
        has texture) of one material slot; both the shadow and G-buffer passes use them."""
        material = mesh.materials[slot] if slot < len(mesh.materials) else None
        if material is None:
            return white, (0.8, 0.8, 0.8, 1.0), (32.0, 0.5, 0.0, 0.0)
        texture = cache.texture(material.image) if material.image is not None else None
        return (texture or white, tuple(material.base_color),
                (material.shininess, material.specular, material.alpha_cutoff,
                 1.0 if texture else 0.0))

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

    # -- read-back for final renders -----------------------------------------------------
    def render_offscreen(self, snap, cache, with_positions=False, with_normals=True):
        """Draw into offscreen float targets and read back (combined, aux, normal, and the
        G-buffer's world positions when asked: tests ray-cast from them)."""
        import gpu
        width, height = snap.camera.width, snap.camera.height
        color = self._texture("final_color", (width, height), 'RGBA32F')
        aux = self._texture("final_aux", (width, height), 'RGBA32F')
        target = self._framebuffer("final", colors=(color, aux))
        with target.bind():
            target.clear(color=(0.0, 0.0, 0.0, 0.0))
        plan = self.draw(snap, cache, target, width, height)
        t = time.perf_counter()
        out = {}
        count = width * height * 4
        reads = [("combined", target, 0), ("aux", target, 1)]
        if with_normals or with_positions:
            reads.append(("normal", self.gbuffer_fb, 1))
        for name, fb, slot in reads:
            buffer = gpu.types.Buffer('FLOAT', count)
            with fb.bind():
                fb.read_color(0, 0, width, height, 4, slot, 'FLOAT', data=buffer)
            out[name] = np.frombuffer(buffer, dtype=np.float32).reshape(height, width, 4).copy()
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
        return out, plan
