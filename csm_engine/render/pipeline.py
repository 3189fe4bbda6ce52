"""The deferred pipeline: one frame's passes in order, for any target.

Owns ``Pipeline``: for one engine instance (one viewport, or one final render), the order
of the passes, the shadow planning call, the per-pass timings and what the last frame drew
and kept (``last_frame``). Input is a ``FrameSnapshot`` (plain data) plus a ``MeshCache``;
output is pixels in a target framebuffer: the viewport's own (``draw_viewport``) or an
offscreen one that ``render_offscreen`` reads back into a ``RenderResult``. Both go through
``Pipeline.draw``, so the viewport and a final render of the same camera agree.

The passes, one module each:
- ``shadow_atlas``: the shadow maps and their partial-caster mask;
- ``blocker_search``: the soft filter's reach, the atlas's nearest depth per block;
- ``gbuffer``: what the camera sees, per pixel;
- ``visible_depth``: the G-buffer's depth range per block, for Fit to Visible Depth;
- ``ambient_occlusion``: half-resolution AO from the G-buffer;
- ``shadow_volumes``: the sun's shadow volumes counted per pixel (Filter Exact, and the
  Shadow error view);
- ``lighting``: shading (and debug views) into the target;
- ``overlays``: the frozen cascades' boxes;
- ``antialiasing``: viewport FXAA, final-render FXAA or jittered samples;
- ``readback``: a final render's images into numpy;
- ``passes``: the render passes a final render asked for (light and colour passes from the
  lighting pass, Cryptomatte IDs from the G-buffer, the rest derived from the read-back).
What they draw from is in ``draw_lists``; textures, framebuffers and the record of what the
textures hold in ``resources``.

Framebuffers belong to the GPU context that made them, so a ``Pipeline`` is owned by one
engine instance and is never shared; its textures may be (``RenderResources``).
"""

import time

from ..core.shadow_plan import gbuffer_plan, pack_frame, plan_shadows
from ..core.view_state import ShadowViewState
from . import antialiasing, passes as render_passes, shaders
from .ambient_occlusion import draw_ambient_occlusion
from .blocker_search import nearest_blocks
from .draw_lists import HeldDrawLists
from .gbuffer import draw_gbuffer
from .lighting import draw_lighting
from .readback import read_images, read_target, unpack_normals
# RenderTargetError: what the engine tells the user when a target cannot be allocated.
from .resources import RenderTargetError, Targets  # noqa: F401
from .result import PassCounts, RenderResult
from .shadow_atlas import allocate_atlas, draw_shadow_atlas
from .shadow_volumes import ShadowVolumes, draw_shadow_volumes, shadow_error, volume_lights
from .visible_depth import VisibleDepth


class Pipeline:
    """GPU resources and passes for one engine instance (one GPU context).

    ``resources``: textures and what they hold, shared between instances that render one
    after another (final renders pass one long-lived ``RenderResources`` and skip
    reallocating ~80 MB of targets, and redrawing unchanged passes, per frame).
    ``view_state``: what this view's shadow planning carries from frame to frame (frozen
    cascades, the fitted depth range's hysteresis); each view has its own, and a final
    render keeps one across renders (``engine.py``)."""

    def __init__(self, resources=None, view_state=None):
        self.targets = Targets(resources)
        self.view_state = ShadowViewState() if view_state is None else view_state
        self.draw_lists = HeldDrawLists()
        self.visible_depth = VisibleDepth()
        self.warnings = []
        self.timings = {}
        self.last_frame = PassCounts()  # what the last ``draw`` drew and kept
        self.last_plan = None           # the shadow plan the last ``draw`` used
        self.gbuffer = None             # kept after draw() for the final render's read-back
        # Cryptomatte: each drawn sample's ID image, and the materials named in them.
        self.cryptomatte_samples = render_passes.CryptomatteSamples()
        self.cryptomatte_materials = set()
        # The Normal pass of an anti-aliased render: the first (unjittered) sample's.
        self.first_sample_normals = None
        self.shadow_error = None        # the last Shadow error view's ShadowError
        # The last frame's shadow-volume counts (RGBA32F: the sun, then up to three local
        # lights; above zero in shadow), None when it counted none: for a render pass.
        self.volume_count = None

    @property
    def shadow_volumes(self):
        """The Exact filter's volume geometry, kept with the resources (``ShadowVolumes``)."""
        resources = self.targets.resources
        if resources.shadow_volumes is None:
            resources.shadow_volumes = ShadowVolumes()
        return resources.shadow_volumes

    @property
    def profile(self):
        """Wait for the GPU after each pass, so that its time (``timings``) is its own."""
        return self.targets.profile

    @profile.setter
    def profile(self, value):
        self.targets.profile = value

    @property
    def benchmark_skip_gpu_calls(self):
        """Benchmark only: draw nothing (every draw and clear skipped), to time a frame's
        Python alone; such frames keep no record of what they would have drawn."""
        return self.targets.benchmark_skip_gpu_calls

    @benchmark_skip_gpu_calls.setter
    def benchmark_skip_gpu_calls(self, value):
        self.targets.benchmark_skip_gpu_calls = value

    def _plan(self, snap, bounds, depth_blocks=None, gbuffer_only=False):
        """This view's shadow planning, the one place the pipeline calls the planner: the
        frame's plan (``depth_blocks``: the visible depths Fit to Visible Depth fits to),
        or with ``gbuffer_only`` the plan a Fit to Visible Depth frame draws its G-buffer
        with before those depths are known."""
        if gbuffer_only:
            return gbuffer_plan(snap, bounds, view_state=self.view_state)
        return plan_shadows(snap, bounds, depth_blocks, view_state=self.view_state)

    def _warn(self, messages):
        self.warnings.extend(w for w in messages if w not in self.warnings)

    def _sync(self, fb, name, start, depth_only=False):
        """When profiling, wait for the GPU (``Targets.wait_when_profiling``) and record
        the pass time under ``name``; returns the time the next pass starts from."""
        if self.profile:
            self.targets.wait_when_profiling(fb, depth_only)
            self.timings[name] = time.perf_counter() - start
        return time.perf_counter()

    def draw(self, snap, cache, target_fb=None, width=None, height=None, plan=None,
             overlays=True, depth_tested=False, passes=None, lighting_passes=False,
             sample_weight=1.0):
        """Render one frame into ``target_fb`` (None: the currently bound framebuffer);
        returns the shadow plan (also ``last_plan``); ``last_frame`` says what it drew
        and kept.
        ``depth_tested``: ``target_fb`` has the G-buffer's depth
        texture attached (``Targets.gbuffer_depth``), so lighting can skip the background.
        ``plan``: a shadow plan to reuse (the jittered samples of one final render share
        the plan of its unjittered camera, so their shadow maps are drawn once).
        ``overlays``: draw the frozen cascade boxes; anti-aliased frames draw them after
        the anti-aliasing instead, so 1-pixel lines stay crisp.
        ``passes`` (``passes.PassRequest``): with Cryptomatte layers, the G-buffer writes
        IDs too and this sample's (of pixel-filter weight ``sample_weight``) are read into
        ``cryptomatte_samples``. ``lighting_passes``: ``target_fb`` has the light and
        colour passes' targets in colour slots 2.. and lighting writes them."""
        # Programs replaced by F5 or dropped with a library are freed here, in the context
        # that draws, never where they were retired (see the NOTE in shaders.py).
        shaders.release_retired()
        targets = self.targets
        width = width or snap.camera.width
        height = height or snap.camera.height
        start = time.perf_counter()
        self.timings = {}

        # World AABB per instance: caster culling per cascade, and the scene's bounds for the
        # automatic occluder margin.
        instances = self.draw_lists.instances(snap, cache)
        bounds = instances.scene_bounds
        # Fit to Visible Depth needs the G-buffer's depths before it can plan; it draws the
        # G-buffer with a plan without cascades and a frame block without the plan's
        # fields (the G-buffer reads only the camera from it).
        fit_to_visible = plan is None and bool(snap.settings.fit_to_visible)
        if plan is None:
            plan = self._plan(snap, bounds, gbuffer_only=fit_to_visible)
        self._warn(snap.warnings + plan.warnings)
        # Allocated before the frame block is packed: a failed allocation halves the
        # plan's resolutions, which the block carries.
        atlas = None if fit_to_visible else allocate_atlas(targets, plan, self.warnings)
        frame_data = pack_frame(snap, None if fit_to_visible else plan)
        frame_ubo = targets.frame_ubo(frame_data)
        self.timings["python_setup"] = time.perf_counter() - start

        # Once per frame: each instance's draws, by program, with their material inputs,
        # and its matrix; the passes below only index into these.
        lists = self.draw_lists.lists(snap, cache, targets.white())

        def shadow_pass(atlas, t):
            """The shadow maps; for the soft filter also its reach (``blocker_search``)."""
            signatures = self.draw_lists.caster_signatures(snap, cache, lists)
            tiles = draw_shadow_atlas(targets, snap, plan, atlas, lists, instances,
                                      signatures)
            if snap.settings.shadow_filter == "SOFT":
                atlas = atlas._replace(
                    nearest_blocks=nearest_blocks(targets, atlas, tiles.drawn))
            return tiles, atlas, self._sync(atlas.framebuffer, "shadow", t,
                                               depth_only=True)

        ids = render_passes.cryptomatte_draw_ids(snap) \
            if passes is not None and passes.cryptomatte else None

        def gbuffer_pass(t):
            gbuffer, kept = draw_gbuffer(
                targets, snap, cache, lists, instances, frame_ubo, frame_data, width, height,
                ids)
            # Its colour targets hold packed bits (gbuffer_layout.glsl): its depth is read.
            return gbuffer, kept, self._sync(gbuffer.framebuffer, "gbuffer", t, True)

        t = time.perf_counter()
        if fit_to_visible:
            # Sample-distribution shadow maps: the G-buffer first, its nearest and farthest
            # view depth, then cascades fitted to that range, then their shadow maps.
            gbuffer, gbuffer_kept, t = gbuffer_pass(t)
            blocks = self.visible_depth.blocks(targets, gbuffer, gbuffer_kept, width, height)
            t = self._sync(gbuffer.framebuffer, "depth_range", t, True)
            plan = self._plan(snap, bounds, blocks)
            self._warn(plan.warnings)
            atlas = allocate_atlas(targets, plan, self.warnings)
            frame_ubo = targets.frame_ubo(pack_frame(snap, plan, like=frame_data))
            tiles, atlas, t = shadow_pass(atlas, t)
        else:
            tiles, atlas, t = shadow_pass(atlas, t)
            gbuffer, gbuffer_kept, t = gbuffer_pass(t)

        if ids is not None and targets.records:
            ids_fb = targets.framebuffer("cryptomatte_ids_read", colors=(gbuffer.ids,))
            self.cryptomatte_samples.add(read_target(ids_fb, 0, width, height, 3),
                                         sample_weight)
            self.cryptomatte_materials.update(ids.per_material)
        ambient_occlusion = draw_ambient_occlusion(targets, snap, frame_ubo, frame_data,
                                                   gbuffer, gbuffer_kept, width, height)
        if ambient_occlusion is not None:
            t = self._sync(ambient_occlusion.framebuffer, "ao", t)

        volume_count = None
        lights = volume_lights(snap, plan)
        if lights:
            volume_count, volume_fb = draw_shadow_volumes(
                targets, self.shadow_volumes, snap, cache, bounds, lights, frame_ubo,
                gbuffer, width, height, gbuffer_kept)
            t = self._sync(volume_fb, "shadow_volumes", t)

        draw_lighting(targets, snap, plan, frame_ubo, gbuffer, atlas, ambient_occlusion,
                      target_fb, width, height, depth_tested, overlays, lighting_passes,
                      volume_count, lists.writes_emission, lists.writes_coat,
                      bool(lists.partial_mask.any()))
        if target_fb is not None:
            t = self._sync(target_fb, "lighting", t)
        self.shadow_error = None
        if volume_count is not None and snap.settings.debug_view == "SHADOW_ERROR" and \
                targets.records:
            self.shadow_error = shadow_error(target_fb, width, height)

        self.gbuffer = gbuffer
        self.volume_count = volume_count
        self.last_frame = _counts(targets, tiles, gbuffer_kept, ambient_occlusion)
        self.last_plan = plan
        self.timings["total"] = time.perf_counter() - start
        return plan

    def draw_viewport(self, snap, cache, width, height, fxaa=True):
        """A viewport frame into the bound framebuffer, through FXAA when ``fxaa``."""
        if not fxaa:
            return self.draw(snap, cache, None, width, height)
        return antialiasing.draw_viewport_fxaa(self, snap, cache, width, height)

    def render_offscreen(self, snap, cache, reads=None, with_positions=False,
                         passes=render_passes.NO_PASSES, memory=None):
        """Draw into offscreen float targets and read back only what ``reads`` names:
        image name ("combined", "aux", "normal") -> channels (1..4, from the first;
        default: combined and aux, RGBA); see ``readback.read_images``. With
        ``with_positions`` the G-buffer's world positions are added as "position" (tests
        ray-cast from them). ``passes`` (``passes.PassRequest``): the render passes to
        draw and return too, under their (Blender 5.0) names, with the Cryptomatte
        metadata. ``memory`` (``readback.ReadbackMemory``): read into memory kept between
        renders (the images are then valid until the next render into it). Returns a
        ``RenderResult`` with what the passes drew."""
        targets = self.targets
        width, height = snap.camera.width, snap.camera.height
        if reads is None:
            reads = {"combined": 4, "aux": 4}
        if with_positions:
            reads = dict(reads, aux=4)
        if passes.names & render_passes.DERIVED_PASSES:
            reads = dict(reads, combined=4, aux=4)
        color = targets.texture("final_color", (width, height), 'RGBA32F')
        aux = targets.texture("final_aux", (width, height), 'RGBA32F')
        lighting_passes = passes.lighting
        pass_textures = render_passes.lighting_pass_textures(targets, width, height) \
            if lighting_passes else ()
        final_fb = targets.framebuffer("final_passes" if lighting_passes else "final",
                                       depth=targets.gbuffer_depth(width, height),
                                       colors=(color, aux) + pass_textures)
        self.cryptomatte_samples = render_passes.CryptomatteSamples()
        self.cryptomatte_materials = set()
        self.first_sample_normals = None
        # No clear: every path writes every pixel of both targets (background and lighting
        # programs between them, or a debug view, or FXAA / the sample average).
        samples = max(int(snap.settings.render_samples), 1)
        use_fxaa = samples == 1 and bool(snap.settings.fxaa)
        if samples == 1 and not use_fxaa:
            plan = self.draw(snap, cache, final_fb, width, height, depth_tested=True,
                             passes=passes, lighting_passes=lighting_passes)
            combined_fb, counts = final_fb, self.last_frame
        else:
            plan, combined_fb, self.timings, counts = antialiasing.draw_antialiased(
                self, snap, cache, samples, use_fxaa, color, aux, passes, pass_textures)
        t = time.perf_counter()
        if lighting_passes:
            reads = dict(reads, **{name: 4 for name in render_passes.LIGHTING_PASS_TARGETS})
        normals_fb = unpack_normals(targets, self.gbuffer) if "normal" in reads else None
        images = read_images(snap, reads, final_fb, combined_fb, normals_fb,
                             with_positions, memory)
        if self.first_sample_normals is not None:
            images["normal"] = self.first_sample_normals
        metadata = {}
        if passes.any:
            images.update(render_passes.collect(snap, passes, images, self.cryptomatte_samples))
            metadata = render_passes.cryptomatte_metadata(snap, passes,
                                                          self.cryptomatte_materials)
        self.timings["readback"] = time.perf_counter() - t
        return RenderResult(images=images, plan=plan, timings=dict(self.timings),
                            passes=counts, warnings=list(self.warnings), metadata=metadata,
                            shadow_error=self.shadow_error)


def _counts(targets, tiles, gbuffer_kept, ambient_occlusion):
    """The ``PassCounts`` of one frame (a benchmark's Python-only frame draws nothing)."""
    if not targets.records:
        return PassCounts()
    ao_kept = ambient_occlusion is not None and ambient_occlusion.kept
    return PassCounts(shadow_tiles_drawn=tiles.drawn, shadow_tiles_kept=tiles.kept,
                      gbuffers_drawn=int(not gbuffer_kept), gbuffers_kept=int(gbuffer_kept),
                      ao_drawn=int(ambient_occlusion is not None and not ao_kept),
                      ao_kept=int(ao_kept))
